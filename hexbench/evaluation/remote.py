"""The evaluator's handle on a sandboxed controller: `RemoteController`, and the camera it declared.

Nothing a controller process says is trusted: its camera spec is rebuilt from plain data and
bounded, its weights files must lie in its own folder, and its actions are checked as plain arrays.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexbench.evaluation import wire
from hexbench.suite.controller import CAMERA_EVERY_STEPS, ControllerError
from hexbench.world.env import ACTION_MODES

MAX_CAMERA_PIXELS = 640 * 480  # largest camera image a controller may ask the evaluator to render
# Camera spec bounds: rendering happens in the evaluator, outside every deadline, and TinyRenderer
# hangs on a degenerate projection (a field of view of 1e-6 deg), so a spec must be a sane camera.
CAMERA_BOUNDS: dict[str, tuple[float, float]] = {
    "fov_deg": (10.0, 170.0), "mount_forward_m": (-1.0, 1.0), "mount_up_m": (-1.0, 1.0),
    "pitch_down_deg": (-90.0, 90.0), "near_m": (0.005, 1.0), "far_m": (0.1, 50.0)}



def one_line(text: str, limit: int = 300) -> str:
    text = " ".join(text.split())
    return text if len(text) <= limit else text[:limit] + "..."


def _camera_from(info: dict, where: str):
    """The CameraSpec a controller declared, rebuilt from plain data and bounded."""
    from hexbench.world.camera import CameraSpec, Lighting

    if info.get("camera_type") is None or not info.get("has_see"):
        return None
    if info["camera_type"] != "hexbench.world.camera.CameraSpec" or not isinstance(info.get("camera"), dict):
        shown = str(info["camera_type"]).rsplit(".", 1)[-1][:60]
        raise ControllerError(f"{where}: camera is a {shown}; expected hexbench.world.camera.CameraSpec")
    fields = dict(info["camera"])
    try:
        if fields.get("lighting") is not None:
            fields["lighting"] = Lighting(**{k: tuple(v) if isinstance(v, list) else v
                                             for k, v in fields["lighting"].items()})
        camera = CameraSpec(**fields)
        numbers = [v for k, v in fields.items() if k != "lighting"]
        ok = all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in numbers)
        ok = ok and isinstance(camera.width_px, int) and isinstance(camera.height_px, int) \
            and camera.width_px * camera.height_px <= MAX_CAMERA_PIXELS and min(camera.width_px, camera.height_px) >= 8
        ok = ok and all(low <= getattr(camera, name) <= high for name, (low, high) in CAMERA_BOUNDS.items()) \
            and camera.far_m > camera.near_m
        if ok and camera.lighting is not None:
            light = camera.lighting
            ok = len(light.direction) == 3 and all(isinstance(v, (int, float)) and math.isfinite(v) and abs(v) <= 10
                                                   for v in (*light.direction, light.ambient, light.diffuse, light.specular))
    except (TypeError, ValueError, AttributeError, RecursionError):
        ok = False
    if not ok:
        bounds = ", ".join(f"{k} {lo:g}..{hi:g}" for k, (lo, hi) in CAMERA_BOUNDS.items())
        raise ControllerError(f"{where}: camera spec is invalid (at least 8 x 8 and at most {MAX_CAMERA_PIXELS} pixels; "
                              f"{bounds}; far_m > near_m)")
    return camera


class RemoteController:
    """The evaluator's handle on a controller built in a sandboxed process (`hexbench.suite.rollout` plays it)."""

    def __init__(self, process, task, info: dict):  # process: a hexbench.evaluation.sandbox.ControllerProcess
        where = process.file
        self.process, self.task_name = process, task.name
        if not info.get("has_reset") or not info.get("has_act"):
            missing = "reset" if not info.get("has_reset") else "act"
            raise process._fail(f"controller has no {missing}() method", "")
        self.action_mode = info.get("action_mode")
        if self.action_mode not in ACTION_MODES:
            raise process._fail(f"controller action_mode is {self.action_mode!r}; valid modes: {', '.join(ACTION_MODES)}", "")
        self.camera = _camera_from(info, where)
        every = info.get("camera_every_steps")
        every = CAMERA_EVERY_STEPS if every is None else every
        if self.camera is not None and (not isinstance(every, int) or isinstance(every, bool) or every < 1):
            raise process._fail(f"camera_every_steps must be a positive int, got {every!r}", "")
        self.camera_every_steps = every
        declared = info.get("checkpoint_paths") or []
        if not isinstance(declared, list) or not all(isinstance(p, str) for p in declared):
            raise process._fail("checkpoint_paths must be a list of file names", "")
        self.checkpoint_paths = [self._weights_file(p) for p in declared]

    def _weights_file(self, declared: str) -> Path:
        folder = self.process.path.parent
        try:
            path = Path(declared) if Path(declared).is_absolute() else folder / declared
            path = path.resolve()
            ok = folder in path.parents and path.is_file()
            size_bytes = path.stat().st_size if ok else 0
        except (ValueError, OSError, TypeError):  # a NUL byte, a name too long, not a string
            ok = False
        if not ok:
            raise self.process._fail(f"checkpoint path {declared!r} is not a file in the controller's folder", "")
        limit = self.process.limits.address_space_bytes
        if size_bytes > limit:  # the evaluator hashes every weights file: a huge (sparse) one would never end
            raise self.process._fail(f"checkpoint path {declared!r} is {size_bytes:,} bytes, more than the "
                                     f"controller process's address space ({limit:,} bytes) could load", "")
        return path

    def reset(self, seed: int) -> None:
        self.process.call(wire.RESET, wire.json_payload({"task": self.task_name, "seed": int(seed)}),
                          self.process.limits.call_timeout_s, "reset()", "")

    def see(self, image: np.ndarray, step: int) -> None:
        payload = wire.array_payload({"shape": list(image.shape)}, np.ascontiguousarray(image, np.uint8).tobytes())
        self.process.call(wire.SEE, payload, self.process.limits.call_timeout_s, "see()", f"at step {step}")

    def act(self, obs: np.ndarray, step: int):
        """The controller's action as a plain float ndarray, or a description of what it returned
        instead (a str), for `check_action` to turn into the one-line error."""
        context = f"at step {step}"
        _, body = self.process.call(wire.ACT, np.ascontiguousarray(obs, "<f4").tobytes(),
                                    self.process.limits.call_timeout_s, "act()", context)
        try:
            line, raw = wire.split_header_line(body)
            layout = action_layout(line)
            if not isinstance(layout, tuple):
                return layout
            dtype, shape, size_bytes = layout
            if len(raw) != size_bytes:
                raise ValueError("array size does not match its shape")
            return np.frombuffer(raw, dtype=dtype).reshape(shape).astype(np.float64 if dtype == "<f8" else np.float32)
        except (ValueError, KeyError, TypeError, AttributeError, RecursionError):
            raise self.process._fail("sent a malformed action message", context) from None


@functools.lru_cache(maxsize=64)
def action_layout(header_line: bytes):
    """What an ACTION payload's header line declares: (dtype, shape, size [bytes]) of a float array,
    or the NotAnArray / WrongDtype / WrongShape that describes anything else. ValueError, KeyError or
    TypeError (the message is malformed) if it is not such a line. A controller sends the same line
    step after step, so each is parsed and checked once."""
    header = json.loads(header_line)
    if not isinstance(header, dict):
        raise ValueError("array message header is not an object")
    kind = header.get("type")
    if kind != "ndarray":
        return NotAnArray(str(kind)[:80])
    dtype, shape = str(header["dtype"]), tuple(int(n) for n in header["shape"])
    if dtype not in ("<f4", "<f8"):
        return WrongDtype(dtype[:40], shape)
    if header.get("truncated"):
        return WrongShape(shape)
    return dtype, shape, math.prod(shape) * int(dtype[-1])


@dataclass(frozen=True)
class NotAnArray:
    """act() returned something that is not an ndarray (its type name)."""

    type_name: str


@dataclass(frozen=True)
class WrongShape:
    """act() returned a float array too large to send (its shape only)."""

    shape_only: tuple


@dataclass(frozen=True)
class WrongDtype:
    """act() returned an ndarray of a dtype other than float32/float64."""

    dtype: str
    shape: tuple
