"""What a bare process boundary costs per control step, apart from hexbench's sandbox machinery.

    python bench/process_boundary.py                               # PPO-CPG, rough 3 cm, 6 rounds
    python bench/process_boundary.py --batch 1 4 --rounds 4        # also 4 episodes in lockstep per message
    python bench/process_boundary.py --controller baselines/cpg.py --steps 3000

The controller plays the task in one of three ways, with the evaluator's side kept to the minimum
(observations out and actions in over a pipe with a 4-byte length prefix; no deadlines, no checks,
no seccomp, no namespaces):

  in-process   the evaluator calls act() itself (what `--isolation none` does);
  fork         a child forked from the evaluator before it builds its environments plays the
               controller (it shares the evaluator's memory pages until either writes them);
  exec         a fresh Python interpreter plays it (what every sandbox does: bubblewrap and
               `--isolation process` both exec the controller's process).

`--batch K` plays K episodes in lockstep on one worker: K observations go out in one message and
K actions come back, so the round trip is paid once per K control steps. Episodes that end start
again from a fresh seed. Two workers run at once, pinned to cores 0 and 1 (each with its
controller process on its own core), as `hexbench run` loads a 2-core machine; each prints its
wall time per control step after a warm-up, and the modes alternate round by round so that load
drifts hit every mode alike. The medians and their ratios to in-process at the same batch size are
printed and written to bench/out/process_boundary.json.

Comparing `exec` with the sandbox's per-step figure (`python bench/sandbox_overhead.py --per-step
--cores 2`) separates what the sandbox machinery costs from what any second address space costs.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
MODES = ("in-process", "fork", "exec")
TERRAIN, LEVEL = "rough", 3.0
WARMUP_STEPS_PER_EPISODE = 40  # control steps each lockstep episode plays before the clock starts
FIRST_SEED, NEXT_SEED = 1000, 2000  # episode seeds: FIRST_SEED + slot, then NEXT_SEED + steps + slot
LENGTH = struct.Struct("<I")


def _task():
    from hexbench.suite.tasks import load_suite

    return load_suite("v1").task(TERRAIN, LEVEL)


def _controllers(controller_file: str, task, batch: int) -> list:
    from hexbench.suite.controller import make_controller

    controllers = [make_controller(controller_file, task) for _ in range(batch)]
    for slot, ctrl in enumerate(controllers):
        ctrl.reset(FIRST_SEED + slot)
    return controllers


def _read_message(fd: int) -> bytes | None:
    data, need = b"", None
    while need is None or len(data) < need:
        chunk = os.read(fd, 1 << 16)
        if not chunk:
            return None
        data += chunk
        if need is None and len(data) >= LENGTH.size:
            need = LENGTH.size + LENGTH.unpack_from(data)[0]
    return data[LENGTH.size:]


def _send_message(fd: int, payload: bytes) -> None:
    view = memoryview(LENGTH.pack(len(payload)) + payload)
    while view:
        view = view[os.write(fd, view):]


def serve(controller_file: str, batch: int, core: int, in_fd: int, out_fd: int) -> None:
    """The controller's side: K observations in, K float32 actions out, until the pipe closes."""
    os.sched_setaffinity(0, {core})
    controllers = _controllers(controller_file, _task(), batch)
    while (payload := _read_message(in_fd)) is not None:
        observations = np.frombuffer(payload, "<f4").reshape(batch, -1)
        _send_message(out_fd, b"".join(np.asarray(ctrl.act(obs.copy()), "<f4").tobytes()
                                       for ctrl, obs in zip(controllers, observations)))
    os._exit(0)


def measure(controller_file: str, mode: str, batch: int, core: int, steps: int) -> float:
    """One worker: K environments in lockstep, the controller played as `mode`; wall time per control step [us]."""
    from hexbench.suite.numerics import use_controller_math
    from hexbench.suite.rollout import make_env

    use_controller_math()
    os.sched_setaffinity(0, {core})
    task = _task()
    child = None
    if mode == "in-process":
        controllers = _controllers(controller_file, task, batch)
    else:
        to_child_r, to_child_w = os.pipe()
        from_child_r, from_child_w = os.pipe()
        if mode == "fork":
            pid = os.fork()
            if pid == 0:
                os.close(to_child_w)
                os.close(from_child_r)
                serve(controller_file, batch, core, to_child_r, from_child_w)
        else:
            child = subprocess.Popen([sys.executable, __file__, "--serve", controller_file, str(batch), str(core),
                                      str(to_child_r), str(from_child_w)], pass_fds=(to_child_r, from_child_w))
        os.close(to_child_r)
        os.close(from_child_w)
        controllers = None
    from hexbench.suite.controller import make_controller

    action_mode = make_controller(controller_file, task).action_mode  # the parent's own copy, for the env's action mode
    envs = [make_env(task, action_mode) for _ in range(batch)]
    observations = [env.reset(seed=FIRST_SEED + slot)[0] for slot, env in enumerate(envs)]
    played, start, timed_from = 0, 0.0, None
    while timed_from is None or played - timed_from < steps:
        if controllers is not None:
            actions = [np.asarray(ctrl.act(obs), np.float32) for ctrl, obs in zip(controllers, observations)]
        else:
            _send_message(to_child_w, b"".join(np.ascontiguousarray(obs, "<f4").tobytes() for obs in observations))
            actions = np.frombuffer(_read_message(from_child_r), "<f4").reshape(batch, -1)
        for slot, env in enumerate(envs):
            obs, _, terminated, truncated, _ = env.step(actions[slot])
            if terminated or truncated:
                obs, _ = env.reset(seed=NEXT_SEED + played + slot)
            observations[slot] = obs
        played += batch
        if timed_from is None and played >= WARMUP_STEPS_PER_EPISODE * batch:
            start, timed_from = time.perf_counter(), played
    per_step_us = (time.perf_counter() - start) / (played - timed_from) * 1e6
    if controllers is None:
        os.close(to_child_w)
        if child is not None:
            child.wait()
        else:
            os.waitpid(pid, 0)
    return per_step_us


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--controller", default=str(REPO / "baselines" / "ppo_cpg.py"))
    parser.add_argument("--batch", type=int, nargs="+", default=[1], help="episodes in lockstep per worker")
    parser.add_argument("--rounds", type=int, default=6)
    parser.add_argument("--steps", type=int, default=6000, help="timed control steps per worker and run")
    args = parser.parse_args()
    here = [sys.executable, __file__]
    per_step: dict[str, list[float]] = {}
    for round_index in range(args.rounds):
        for batch in args.batch:
            for mode in MODES:
                workers = [subprocess.Popen([*here, "--measure", args.controller, mode, str(batch), str(core),
                                             str(args.steps)], stdout=subprocess.PIPE, text=True) for core in (0, 1)]
                figures = [float(w.communicate()[0].split()[-1]) for w in workers]
                per_step.setdefault(f"{mode} K={batch}", []).extend(figures)
                print(f"round {round_index + 1}: {mode:10s} K={batch}: "
                      + ", ".join(f"{f:.0f}" for f in figures) + " us per control step", flush=True)
    summary = {}
    for batch in args.batch:
        base = statistics.median(per_step[f"in-process K={batch}"])
        for mode in MODES:
            key = f"{mode} K={batch}"
            median = statistics.median(per_step[key])
            summary[key] = {"median_us_per_step": round(median, 1), "ratio_to_in_process": round(median / base, 3),
                            "runs_us_per_step": [round(v, 1) for v in per_step[key]]}
            print(f"{key:16s} median {median:7.1f} us per control step, {median / base:.3f} of in-process")
    out = REPO / "bench" / "out" / "process_boundary.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"controller": args.controller, "task": f"{TERRAIN} {LEVEL:g}", "rounds": args.rounds,
                               "steps_per_run": args.steps, "workers": 2, "results": summary}, indent=1) + "\n")
    print(f"wrote {out.relative_to(REPO)}")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--serve":
        serve(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]), int(sys.argv[6]))
    elif len(sys.argv) > 1 and sys.argv[1] == "--measure":
        print(f"{measure(sys.argv[2], sys.argv[3], int(sys.argv[4]), int(sys.argv[5]), int(sys.argv[6])):.1f}")
    else:
        main()
