"""The episode recorder the evaluator drives: on_reset, on_step, on_end (or abort).

Nothing is written while the episode runs. `on_end` encodes the whole episode, writes
`.<id>.mcap.<pid>.tmp` and `.<id>.rrd.<pid>.tmp` in the output folder and only then renames
them to `<id>.mcap` and `<id>.rrd`: a crash or kill at any point leaves no file under a final
name that is incomplete (at worst a hidden temporary, which `abort()` removes when it gets the
chance). Temporary files are not fsync'ed: the guarantee covers a crashed or killed process,
not a power cut. A write that fails (a full disk, a read-only folder) removes the temporaries and
is one OutputError line naming the file.
"""

from __future__ import annotations

import io
import os
import re
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from hexbench.artifacts.files import make_folder, sha256_bytes
from hexbench.errors import OutputError, os_reason
from hexbench.recording.capture import EpisodeCapture
from hexbench.recording.kinematics import joint_frames
from hexbench.recording.mcap_episode import McapPrecision, write_episode_mcap
from hexbench.recording.rerun_episode import RerunSettings, episode_rrd_bytes
from hexbench.recording.terrain_mesh import terrain_mesh

_SAFE_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._+-]*$")


@dataclass(frozen=True)
class RecordingConfig:
    mcap: McapPrecision = field(default_factory=McapPrecision)
    rerun: RerunSettings = field(default_factory=RerunSettings)
    write_rrd: bool = True


@lru_cache(maxsize=4)
def _frames(urdf: str):
    return joint_frames(urdf)


def _json_value(v):
    if hasattr(v, "item"):  # numpy scalar
        v = v.item()
    return v


def _library_id() -> str:
    import mcap

    from hexbench.artifacts.provenance import HEXBENCH_VERSION

    return f"hexbench/{HEXBENCH_VERSION} mcap-python/{getattr(mcap, '__version__', '?')}"


class EpisodeRecorder:
    def __init__(self, out_dir: Path, episode_id: str, meta: dict, config: RecordingConfig = RecordingConfig()):
        if not _SAFE_ID.match(episode_id):
            raise ValueError(f"episode id {episode_id!r} is not a safe file name; use letters, digits and . _ + -")
        self.out_dir = Path(out_dir)
        self.episode_id = episode_id
        self.meta = {**meta, "episode_id": episode_id}
        self.config = config
        self._capture = EpisodeCapture(config.mcap.metrics_every_n_steps)
        self._static: dict | None = None
        self._tmp_paths: list[Path] = []

    # ------------------------------------------------------------------ paths
    @property
    def mcap_path(self) -> Path:
        return self.out_dir / f"{self.episode_id}.mcap"

    @property
    def rrd_path(self) -> Path:
        return self.out_dir / f"{self.episode_id}.rrd"

    def _tmp(self, final: Path) -> Path:
        return final.with_name(f".{final.name}.{os.getpid()}.tmp")

    # -------------------------------------------------------------- callbacks
    def on_reset(self, env) -> None:
        from hexbench.world.robot import urdf_text

        urdf = urdf_text(env.sim.robot_spec)
        self._static = {"urdf": urdf, "joints": _frames(urdf), "mesh": terrain_mesh(env.sim.terrain),
                        "goal_distance_m": env.config.goal_distance_m}
        cfg = env.config
        # what verify needs beyond the task to rebuild the episode's environment
        self.meta.setdefault("max_steps", cfg.max_steps)
        self.meta.setdefault("residual_scale", cfg.eps)
        self.meta.setdefault("control_dt_s", cfg.physics.control_dt_s)
        self.meta.setdefault("goal_distance_m", cfg.goal_distance_m)
        self._capture.reset(env)

    def on_step(self, env, obs, action, reward, info) -> None:
        self._capture.step(env, action, reward, info)

    def on_end(self, row: dict) -> dict:
        if self._static is None:
            raise RuntimeError("on_end() before on_reset()")
        ep = self._capture.arrays()
        st = self._static
        make_folder(self.out_dir)
        writing = self.mcap_path
        try:
            buf = io.BytesIO()
            write_episode_mcap(buf, ep, urdf=st["urdf"], joints=st["joints"], mesh=st["mesh"], episode_meta=self.meta,
                               outcome={k: _json_value(v) for k, v in row.items()}, precision=self.config.mcap,
                               library=_library_id())
            mcap_bytes = buf.getvalue()
            tmp_mcap = self._tmp(self.mcap_path)
            self._tmp_paths.append(tmp_mcap)
            tmp_mcap.write_bytes(mcap_bytes)
            files = {"mcap_path": self.mcap_path.name, "mcap_sha256": sha256_bytes(mcap_bytes)}
            if self.config.write_rrd:
                writing = self.rrd_path
                rrd_bytes = episode_rrd_bytes(ep, recording_id=self.episode_id, urdf=st["urdf"], joints=st["joints"],
                                              mesh=st["mesh"], goal_x_m=st["goal_distance_m"], settings=self.config.rerun)
                tmp_rrd = self._tmp(self.rrd_path)
                self._tmp_paths.append(tmp_rrd)
                tmp_rrd.write_bytes(rrd_bytes)
                files.update({"rrd_path": self.rrd_path.name, "rrd_sha256": sha256_bytes(rrd_bytes)})
                os.replace(tmp_rrd, self.rrd_path)
            os.replace(tmp_mcap, self.mcap_path)
            self._tmp_paths.clear()
            return files
        except OSError as e:
            self.abort()
            raise OutputError(f"{writing}: cannot be written ({os_reason(e)})") from None
        except BaseException:
            self.abort()
            raise

    def abort(self) -> None:
        """Remove this episode's temporary files; never touches a final name."""
        for p in self._tmp_paths:
            try:
                p.unlink()
            except FileNotFoundError:
                pass
        self._tmp_paths.clear()
        self._capture = EpisodeCapture(self.config.mcap.metrics_every_n_steps)


def make_episode_recorder(out_dir: Path, episode_id: str, meta: dict,
                          config: RecordingConfig | None = None) -> EpisodeRecorder:
    """The recorder for one episode, writing `<out_dir>/<episode_id>.mcap` and `.rrd` on success."""
    return EpisodeRecorder(Path(out_dir), episode_id, dict(meta), config or RecordingConfig())


