"""The submission interface: a controller file and the `Controller` protocol.

A controller file is a Python file that defines

    def make_controller(task: hexbench.suite.tasks.TaskSpec) -> Controller

where a Controller is any object with

    action_mode: str                 # one of hexbench.world.env.ACTION_MODES: "joint", "cpg_residual", "cpg_params", ...
    def reset(self, seed: int) -> None
    def act(self, obs: np.ndarray) -> np.ndarray   # (62,) float32 in, action in [-1, 1] out

The evaluator only passes observations in and takes actions out. Every action is checked
(`check_action`) before it reaches the simulator.

Optional camera (a `SeeingController`, e.g. baselines/hlta.py): a controller that also has

    camera: hexbench.world.camera.CameraSpec   # the body-mounted camera it wants
    camera_every_steps: int              # optional, default CAMERA_EVERY_STEPS (every 0.5 s)
    def see(self, image: np.ndarray) -> object   # (H, W, 3) uint8 RGB

gets `see(image)` before `act` on step 0 and then every `camera_every_steps` control steps. The
image is rendered by PyBullet's CPU renderer with every terrain body painted `CAMERA_GROUND_RGB`
(the lighting and painting of the terrain-image dataset, hexbench.perception.views).
"""

from __future__ import annotations

import importlib.util
import sys
import uuid
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from hexbench.artifacts.files import file_kind, sha256_file
from hexbench.errors import HexbenchError, os_reason
from hexbench.world.env import ACTION_MODES
from hexbench.world.sim import clip_ufunc

_max_reduce = np.maximum.reduce
_ACTION_BOUND = 1.0 + 1e-6  # |a| above this is refused; up to it, clipped to [-1, 1]


@runtime_checkable
class Controller(Protocol):
    action_mode: str

    def reset(self, seed: int) -> None: ...

    def act(self, obs: np.ndarray) -> np.ndarray: ...


CAMERA_EVERY_STEPS = 30  # control steps between camera images (0.5 s at 60 Hz)
CAMERA_GROUND_RGB = (0.62, 0.6, 0.55)  # terrain colour in camera images (a plain grey-beige)


@runtime_checkable
class SeeingController(Controller, Protocol):
    camera: object  # hexbench.world.camera.CameraSpec

    def see(self, image: np.ndarray) -> object: ...


class ControllerError(HexbenchError):
    """A submitted controller misbehaved; the message is one line naming file and problem."""


# A controller file is source code (weights go in files of their own, `checkpoint_paths`); the
# evaluator hashes it before anything runs, so a larger one (a huge sparse file) is refused unread.
MAX_CONTROLLER_FILE_BYTES = 16 << 20


def controller_file_problem(path: str | Path) -> str | None:
    """Why `path` cannot be a controller file (one line naming it), or None: it must be a plain
    file of at most MAX_CONTROLLER_FILE_BYTES, not a folder, a pipe or a device."""
    path = Path(path)
    try:
        status = path.stat()
    except FileNotFoundError:
        return f"{path}: no such controller file"
    except OSError as e:
        return f"{path}: cannot be read ({os_reason(e)})"
    kind = file_kind(status.st_mode)
    if kind != "a plain file":
        return f"{path}: is {kind}; expected a controller file (.py) defining make_controller(task)"
    if status.st_size > MAX_CONTROLLER_FILE_BYTES:
        return (f"{path}: {status.st_size:,} bytes; a controller file has at most {MAX_CONTROLLER_FILE_BYTES:,} "
                "(weights go in files of their own, named in checkpoint_paths)")
    return None


def file_sha256(path: str | Path) -> str:
    return sha256_file(path)


def load_controller_module(path: str | Path):
    """Import a controller file as a fresh module; ControllerError on any failure."""
    path = Path(path)
    if not path.is_file():
        raise ControllerError(f"{path}: no such controller file")
    name = f"hexbench_submission_{path.stem}_{uuid.uuid4().hex[:8]}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ControllerError(f"{path}: cannot be imported as a Python file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except SyntaxError as e:
        raise ControllerError(f"{path}: syntax error at line {e.lineno}: {e.msg}") from None
    except BaseException as e:  # noqa: BLE001 - any failure of foreign code is reported, not raised
        raise ControllerError(f"{path}: import failed: {type(e).__name__}: {e}") from None
    if not callable(getattr(module, "make_controller", None)):
        raise ControllerError(f"{path}: defines no make_controller(task) function")
    return module


def make_controller(path: str | Path, task) -> Controller:
    """Load the file and build its controller for `task`, checking the protocol."""
    module = load_controller_module(path)
    try:
        ctrl = module.make_controller(task)
    except BaseException as e:  # noqa: BLE001
        raise ControllerError(f"{path}: make_controller raised {type(e).__name__}: {e}") from None
    for attr in ("reset", "act"):
        if not callable(getattr(ctrl, attr, None)):
            raise ControllerError(f"{path}: controller has no {attr}() method")
    mode = getattr(ctrl, "action_mode", None)
    if mode not in ACTION_MODES:
        raise ControllerError(f"{path}: controller action_mode is {mode!r}; valid modes: {', '.join(ACTION_MODES)}")
    return ctrl


def check_action(action, expected_dim: int, where: str) -> np.ndarray:
    """Validate one action (type, shape, dtype, finite, within [-1, 1]); ControllerError if bad.

    Returns it as float32, the action space's dtype: the evaluator applies and logs exactly that.
    `action` may also be a stand-in from the sandbox (hexbench.evaluation.sandbox.NotAnArray / WrongDtype)
    saying what the controller returned instead of a float array.
    """
    type_name = getattr(action, "type_name", None)
    if action is None or type_name == "NoneType":
        raise ControllerError(f"{where}: act() returned None; expected a float array of shape ({expected_dim},)")
    if type_name is not None or not isinstance(action, np.ndarray) and not hasattr(action, "dtype") \
            and not hasattr(action, "shape_only"):
        name = type_name or type(action).__name__
        raise ControllerError(f"{where}: act() returned {name}; expected a numpy float array of shape ({expected_dim},)")
    shape_only = getattr(action, "shape_only", None)
    if shape_only is not None:  # WrongShape stand-in: a float array too large to send
        raise ControllerError(f"{where}: action shape is {shape_only}; expected ({expected_dim},)")
    dtype = getattr(action, "dtype", None)
    if not isinstance(action, np.ndarray):  # WrongDtype stand-in
        raise ControllerError(f"{where}: action dtype is {dtype}; expected float32 or float64")
    if action.dtype.kind != "f":
        raise ControllerError(f"{where}: action dtype is {action.dtype}; expected float32 or float64")
    if action.shape != (expected_dim,):
        raise ControllerError(f"{where}: action shape is {action.shape}; expected ({expected_dim},)")
    # A plain array of the same values (a subclass's overrides play no part in the checks); one
    # reduction decides the common case, every |a| within bounds (a NaN makes the largest NaN, which
    # compares false): this runs at every control step of every episode.
    action = np.asarray(action)
    if not _max_reduce(abs(action)) <= _ACTION_BOUND:
        if not np.all(np.isfinite(action)):
            raise ControllerError(f"{where}: action contains NaN or infinite values")
        raise ControllerError(f"{where}: action outside [-1, 1] (max |a| = {float(np.max(np.abs(action))):.3g})")
    return clip_ufunc(np.asarray(action, dtype=np.float32), -1.0, 1.0)
