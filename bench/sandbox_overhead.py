"""Wall-time cost of the controller sandbox, and the size of the action logs.

    python bench/sandbox_overhead.py                       # PPO-CPG, 6 levels x 4 episodes, 2 workers, 3 rounds
    python bench/sandbox_overhead.py --controller baselines/cpg.py --episodes 2 --rounds 1
    python bench/sandbox_overhead.py --per-step                 # one pinned worker: act(), the action check,
    #                                                             the env step (its physics) and the rest of the loop,
    #                                                             and each process's CPU, switches and faults per step
    python bench/sandbox_overhead.py --per-step --cores 2       # the same on two cores at once, as `hexbench run` loads them
    python bench/sandbox_overhead.py --act-loop                 # act() of the controller in one process, caches warm
    python bench/sandbox_overhead.py --at-once --rounds 2       # the full protocol sandboxed and in-process at the
    #                                                             same time, one core each, swapped every round

The same episodes are evaluated with the controller sandboxed (the default isolation: bubblewrap,
else process) and in-process (`--isolation none`), alternating A/B/B/A in one run, after an untimed
warm-up of each, so that load drifts hit both alike; the ratio is sandboxed / in-process wall time,
per round, overall and as the median of rounds, and
the same for the machine's busy CPU time (every process: meaningful on a quiet machine only).
Each timed run starts its worker processes and their controller processes afresh, so at the
default 24 episodes the one-time start-up (imports; a sandboxed worker also starts a controller
process that imports the controller's libraries) is a part of the ratio that a full protocol run
of 860 episodes spreads thin; `--per-step` measures the steady state alone.
Both runs must give identical episode rows (the sandbox changes where the controller runs, never
what it does). Then the action-log bytes per episode (always written) and per control step.
`--at-once` is for VMs whose speed drifts between back-to-back runs by more than the effect: each
round runs `hexbench run CONTROLLER --workers 1` twice at the same time, sandboxed on one core and
`--isolation none` on the other (cores swapped in the next round), recording on, the full protocol
(or `--episodes N` per level of every level); when one run ends, in-process episodes of rough 3 cm
keep its core busy until the other ends, so neither finishes on a quieter machine. Both runs'
episodes digests must be equal. The ratio is of the runs' own wall times (`wall_time_s`), per
round and over all rounds.
Also the evaluator <-> controller round trip for one act() call, with the two processes on one
core (what `hexbench run` does) and free to run on different cores. Writes
bench/out/sandbox_overhead.json.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from hexbench.evaluation import sandbox
from hexbench.evaluation.evaluate import evaluate
from hexbench.evaluation.workers import pin_to_core
from hexbench.suite.numerics import use_controller_math
from hexbench.suite.tasks import load_suite

REPO = Path(__file__).resolve().parent.parent
LEVELS = (("rough", 3.0), ("rough", 11.0), ("slopes", 6.0), ("slopes", 20.0), ("stairs", 2.0), ("stairs", 8.0))


def cpu_seconds() -> float:
    """Busy CPU time of the whole machine [s] (/proc/stat: every state but idle and iowait). The
    sandboxed controller processes are reaped inside bubblewrap's PID namespace, so this process's
    rusage never sees their time; the machine's counters do, and so does everything else running:
    the CPU figures mean something on a quiet machine only."""
    fields = Path("/proc/stat").read_text().splitlines()[0].split()[1:]
    ticks = [int(v) for v in fields]
    busy = sum(ticks[:8]) - ticks[3] - ticks[4]  # user nice system idle iowait irq softirq steal
    return busy / os.sysconf("SC_CLK_TCK")


def timed_run(controller: str, tasks, episodes: int, workers: int, isolation: str) -> tuple[float, float, dict, list[int]]:
    with tempfile.TemporaryDirectory() as d:
        c0 = cpu_seconds()
        t0 = time.perf_counter()
        res = evaluate(controller, tasks, Path(d) / "run", episodes=episodes, workers=workers, record=False,
                       progress=False, command="bench/sandbox_overhead.py", isolation=isolation)
        wall = time.perf_counter() - t0
        cpu = cpu_seconds() - c0
        if res.error:
            raise SystemExit(res.error)
        sizes = [(Path(d) / "run" / "episodes" / r["action_log_path"]).stat().st_size
                 for r in res.record["episodes"] if r.get("action_log_path")]
    return wall, cpu, res.record, sizes


def round_trip_us(isolation: str, pinned: bool, calls: int = 3000) -> float:
    """Median time of one act() round trip to the open-loop CPG (no work in act) [us]."""
    task = load_suite("v1").task("rough", 3.0)
    previous = pin_to_core() if pinned else None
    try:
        ctrl = sandbox.controller_for(str(REPO / "baselines" / "cpg.py"), task, isolation)
        obs = np.zeros(62, dtype=np.float32)
        ctrl.reset(0)
        times = []
        for step in range(calls):
            t0 = time.perf_counter()
            ctrl.act(obs, step)
            times.append(time.perf_counter() - t0)
        sandbox.close_all()
    finally:
        if previous is not None:
            os.sched_setaffinity(0, previous)
    return statistics.median(times) * 1e6


class StepTimer:
    """Sums the wall time [s] of the parts of a control step it wraps, by name."""

    def __init__(self):
        self.sums: dict[str, float] = {}

    def wrap(self, name: str, function):
        sums, clock = self.sums, time.perf_counter

        def timed(*args, **kwargs):
            t0 = clock()
            try:
                return function(*args, **kwargs)
            finally:
                sums[name] = sums.get(name, 0.0) + clock() - t0

        return timed


class TimedActor:
    """Wraps an episode's controller and times its act() calls (the `timer`'s "act")."""

    def __init__(self, ctrl, timer: StepTimer):
        self.ctrl, self._act = ctrl, timer.wrap("act", ctrl.act)
        self.action_mode, self.camera = ctrl.action_mode, getattr(ctrl, "camera", None)

    def reset(self, seed: int) -> None:
        self.ctrl.reset(seed)

    def act(self, obs, step: int):
        return self._act(obs, step)


def process_tree_counters(pid: int) -> dict[str, float]:
    """CPU time [s], context switches (voluntary: it blocked; involuntary: it was preempted) and
    minor page faults of a process and everything below it, from /proc."""
    totals = {"cpu_s": 0.0, "voluntary_switches": 0, "involuntary_switches": 0, "minor_faults": 0}
    pending, ticks = [pid], os.sysconf("SC_CLK_TCK")
    while pending:
        current = pending.pop()
        try:
            fields = Path(f"/proc/{current}/stat").read_text().rsplit(")", 1)[1].split()
            status = dict(line.split(":", 1) for line in Path(f"/proc/{current}/status").read_text().splitlines())
            for tid in os.listdir(f"/proc/{current}/task"):
                pending += [int(c) for c in Path(f"/proc/{current}/task/{tid}/children").read_text().split()]
        except (OSError, ValueError):
            continue
        totals["cpu_s"] += (int(fields[11]) + int(fields[12])) / ticks
        totals["minor_faults"] += int(fields[7])
        totals["voluntary_switches"] += int(status["voluntary_ctxt_switches"])
        totals["involuntary_switches"] += int(status["nonvoluntary_ctxt_switches"])
    return totals


def _own_counters() -> dict[str, float]:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return {"cpu_s": usage.ru_utime + usage.ru_stime, "voluntary_switches": usage.ru_nvcsw,
            "involuntary_switches": usage.ru_nivcsw, "minor_faults": usage.ru_minflt}


def per_step_us(controller: str, isolation: str, seeds: tuple[int, ...] = (1000, 1001)) -> list[dict]:
    """One worker pinned to one core, episodes of rough 3 cm: per control step, the act() round trip,
    the action check, the env step (and the physics inside it) and the rest of the loop [us], after
    one untimed episode; and per control step the evaluator's and (sandboxed) the controller
    process's CPU time [us], context switches and minor page faults."""
    from hexbench.suite import rollout

    task = load_suite("v1").task("rough", 3.0)
    previous = pin_to_core()
    check_action = rollout.check_action
    try:
        ctrl = sandbox.controller_for(controller, task, isolation)
        env = rollout.make_env(task, ctrl.action_mode)
        timer = StepTimer()
        rollout.check_action = timer.wrap("check", check_action)  # as the loop calls it
        env.step = timer.wrap("env_step", env.step)
        env.sim.step_physics = timer.wrap("physics", env.sim.step_physics)
        rollout.play(task, seeds[0], TimedActor(ctrl, timer), controller_seed=5, env=env)
        out = []
        child = getattr(getattr(ctrl, "process", None), "proc", None)
        for seed in seeds:
            timer.sums.clear()
            actor = TimedActor(ctrl, timer)
            before = [_own_counters()] + ([process_tree_counters(child.pid)] if child else [])
            t0 = time.perf_counter()
            steps = rollout.play(task, seed, actor, controller_seed=5, env=env).row["steps"]
            total = time.perf_counter() - t0
            after = [_own_counters()] + ([process_tree_counters(child.pid)] if child else [])
            counts = [{k: (b[k] - a[k]) / steps * (1e6 if k == "cpu_s" else 1) for k in a} for a, b in zip(before, after)]
            part_us = {name: value / steps * 1e6 for name, value in timer.sums.items()}
            out.append({"seed": seed, "steps": steps, "step_us": total / steps * 1e6, "act_us": part_us["act"],
                        "check_us": part_us["check"], "env_step_us": part_us["env_step"],
                        "physics_us": part_us["physics"],
                        "loop_rest_us": total / steps * 1e6 - part_us["act"] - part_us["check"] - part_us["env_step"],
                        "rest_us": total / steps * 1e6 - part_us["act"], "evaluator_per_step": counts[0],
                        "controller_process_per_step": counts[1] if child else None})
        env.close()
        sandbox.close_all()
    finally:
        rollout.check_action = check_action
        if previous is not None:
            os.sched_setaffinity(0, previous)
    return out


def per_step_rounds(controller: str, mode: str, slot: int | None = None) -> list[tuple[str, dict]]:
    """The per-step split A/B/A/B (sandboxed in `mode`, in-process) in this process, pinned to core
    `slot` (None: the one it runs on)."""
    if slot is not None:
        pin_to_core(slot)
    return [(isolation, r) for isolation in (mode, "none", mode, "none") for r in per_step_us(controller, isolation)]


def report_act_loop(controller: str, calls: int = 3000, loops: int = 3) -> None:
    """The controller's own act() for rough 3 cm in this process (no limits around it), on one
    observation of a real episode, `loops` loops of `calls` calls: what a call costs with warm
    caches (a control step's act() runs with the caches the physics has just evicted: `--per-step`)."""
    from hexbench.suite import rollout

    task = load_suite("v1").task("rough", 3.0)
    pin_to_core()
    ctrl = sandbox.controller_for(controller, task, "none").ctrl
    env = rollout.make_env(task, ctrl.action_mode)
    obs, _ = env.reset(seed=1000)
    env.close()
    ctrl.reset(5)
    per_call_us = []
    for _ in range(loops):
        t0 = time.perf_counter()
        for _call in range(calls):
            ctrl.act(obs)
        per_call_us.append((time.perf_counter() - t0) / calls * 1e6)
    sandbox.close_all()
    print(f"act() in one process, caches warm, {loops} x {calls:,} calls: "
          + ", ".join(f"{us:.1f}" for us in per_call_us) + f" us per call (min {min(per_call_us):.1f})")


def report_per_step(controller: str, cores: int) -> None:
    mode = sandbox.resolve_isolation("auto")
    if cores <= 1:
        results = [per_step_rounds(controller, mode)]
    else:  # one process per core, all at once: both cores busy, as in `hexbench run`; each spawned
        # process inherits the controller-math environment main() set
        from concurrent.futures import ProcessPoolExecutor
        from multiprocessing import get_context

        with ProcessPoolExecutor(max_workers=cores, mp_context=get_context("spawn")) as pool:
            results = list(pool.map(per_step_rounds, [controller] * cores, [mode] * cores, range(cores)))
    steps: dict[str, list[float]] = {}
    for core, rounds in enumerate(results):
        for isolation, r in rounds:
            steps.setdefault(isolation, []).append(r["step_us"])
            print(f"core slot {core} {isolation:<10} seed {r['seed']}: {r['steps']} steps, {r['step_us']:.0f} us per step: "
                  f"act() {r['act_us']:.0f} us, the rest {r['rest_us']:.0f} us (check {r['check_us']:.0f}, "
                  f"env step {r['env_step_us']:.0f} of which physics {r['physics_us']:.0f}, "
                  f"loop {r['loop_rest_us']:.0f}); "
                  + "; ".join(f"{who} CPU {c['cpu_s']:.0f} us, switches {c['voluntary_switches']:.2f} voluntary "
                              f"{c['involuntary_switches']:.2f} involuntary, {c['minor_faults']:.2f} faults"
                              for who, c in (("evaluator", r["evaluator_per_step"]),
                                             ("controller", r["controller_process_per_step"])) if c), flush=True)
    sandboxed, in_process = statistics.median(steps[mode]), statistics.median(steps["none"])
    print(f"median per control step: {mode} {sandboxed:.0f} us, in-process {in_process:.0f} us, "
          f"ratio {sandboxed / in_process:.3f} ({cores} core{'s' if cores > 1 else ''} busy)")


def _hexbench_run(core: int, argv: list[str], log) -> subprocess.Popen:
    """`hexbench run ARGV` as the leader of a new process group (setsid), pinned to `core` (its workers and
    controller processes inherit the pin)."""
    return subprocess.Popen([sys.executable, "-m", "hexbench", "run", *argv], cwd=REPO, stdout=log,
                            stderr=subprocess.STDOUT, start_new_session=True,
                            preexec_fn=lambda: os.sched_setaffinity(0, {core}))


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, 9)
    proc.wait()


def at_once_round(controller: str, episodes: int | None, cores: dict[str, int], folder: Path) -> dict[str, dict]:
    """One round of `--at-once`: the two isolations' runs at once, each on its core in `cores`;
    (isolation -> its record's provenance and episodes digest)."""
    limit = [] if episodes is None else ["--episodes", str(episodes)]
    runs, logs, filler = {}, {}, None
    try:
        for isolation, core in cores.items():
            logs[isolation] = open(folder / f"{isolation}.log", "w")
            runs[isolation] = _hexbench_run(core, [controller, "--workers", "1", "--isolation", isolation, *limit,
                                                   "--out", str(folder / isolation)], logs[isolation])

        def running() -> list[str]:
            return [isolation for isolation, run in runs.items() if run.poll() is None]

        while len(running()) == len(runs):
            time.sleep(0.5)
        idle_core = next((cores[isolation] for isolation in runs if isolation not in running()), None)
        fillers = 0
        while running():  # the other run goes on: keep the finished run's core busy until it ends
            filler = _hexbench_run(idle_core, [controller, "--terrain", "rough", "--levels", "3", "--episodes", "4",
                                               "--workers", "1", "--isolation", "none", "--no-record", "--out",
                                               str(folder / f"filler-{fillers}")], subprocess.DEVNULL)
            fillers += 1
            while filler.poll() is None and running():
                time.sleep(0.5)
            _stop(filler)
    finally:  # interrupted: the runs (setsid: Ctrl-C does not reach them) must not outlive this script
        for run in [*runs.values(), *([filler] if filler else [])]:
            _stop(run)
        for log in logs.values():
            log.close()
    out = {}
    for isolation, run in runs.items():
        if run.returncode != 0:
            last_line = ((folder / f"{isolation}.log").read_text().strip().splitlines() or [""])[-1]
            raise SystemExit(f"the {isolation} run failed (exit {run.returncode}): {last_line}")
        record = json.loads((folder / isolation / "result.json").read_text())
        out[isolation] = {"wall_time_s": record["provenance"]["wall_time_s"], "core": cores[isolation],
                          "episodes_digest": record["episodes_digest"], "git_commit": record["provenance"]["git_commit"]}
    return out


def report_at_once(controller: str, episodes: int | None, rounds: int) -> None:
    mode = sandbox.resolve_isolation("auto")
    if len(os.sched_getaffinity(0)) < 2:
        raise SystemExit("--at-once needs two cores")
    first, second = sorted(os.sched_getaffinity(0))[:2]
    signal.signal(signal.SIGTERM, lambda *_: sys.exit("stopped (SIGTERM)"))  # as Ctrl-C: the runs are stopped too
    results = []
    with tempfile.TemporaryDirectory(prefix="hexbench-at-once-") as d:
        for k in range(rounds):
            cores = {mode: first, "none": second} if k % 2 == 0 else {mode: second, "none": first}
            folder = Path(d) / f"round-{k + 1}"
            folder.mkdir()
            r = at_once_round(controller, episodes, cores, folder)
            shutil.rmtree(folder)
            ratio = r[mode]["wall_time_s"] / r["none"]["wall_time_s"]
            results.append({"ratio": ratio, **r})
            print(f"round {k + 1}: {mode} on core {r[mode]['core']} {r[mode]['wall_time_s']:.1f} s, in-process on core "
                  f"{r['none']['core']} {r['none']['wall_time_s']:.1f} s: {ratio:.3f}; episodes digests equal: "
                  f"{r[mode]['episodes_digest'] == r['none']['episodes_digest']}", flush=True)
    digests = {r[iso]["episodes_digest"] for r in results for iso in (mode, "none")}
    overall = sum(r[mode]["wall_time_s"] for r in results) / sum(r["none"]["wall_time_s"] for r in results)
    committed = REPO / "leaderboard" / f"{Path(controller).stem}.json"
    as_committed = (f"; the same as {committed.name}: {digests == {json.loads(committed.read_text())['episodes_digest']}}"
                    if episodes is None and committed.is_file() else "")
    print(f"sandboxed ({mode}) / in-process wall time, run at the same time: {overall:.3f} over {rounds} round(s); "
          f"one episodes digest for all runs: {len(digests) == 1}{as_committed}")
    out = REPO / "bench" / "out"
    out.mkdir(parents=True, exist_ok=True)
    (out / "sandbox_overhead_at_once.json").write_text(json.dumps({
        "controller": controller, "isolation": mode, "episodes_per_level": episodes, "rounds": results,
        "ratio": overall, "digests_equal": len(digests) == 1}, indent=1))
    if len(digests) != 1:
        raise SystemExit("the runs played different episodes")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--controller", default=str(REPO / "baselines" / "ppo_cpg.py"))
    ap.add_argument("--episodes", type=int, default=None,
                    help="episodes per level (default 4; with --at-once the protocol's 20)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=3, help="A/B pairs")
    ap.add_argument("--per-step", action="store_true", help="only the per-step split of a pinned worker, A/B/A/B")
    ap.add_argument("--cores", type=int, default=1, help="with --per-step: that many pinned workers at once")
    ap.add_argument("--act-loop", action="store_true", help="only act() in one process, caches warm")
    ap.add_argument("--at-once", action="store_true",
                    help="both isolations' `hexbench run` at the same time, one core each, swapped every round "
                         "(full protocol unless --episodes is given)")
    args = ap.parse_args()
    if args.at_once:
        report_at_once(args.controller, args.episodes, args.rounds)
        return
    args.episodes = 4 if args.episodes is None else args.episodes
    use_controller_math()  # in-process controllers here multiply as in an evaluation worker
    if args.act_loop:
        report_act_loop(args.controller)
        return
    if args.per_step:
        report_per_step(args.controller, args.cores)
        return
    suite = load_suite("v1")
    tasks = [suite.task(t, lv) for t, lv in LEVELS]
    mode = sandbox.resolve_isolation("auto")
    walls: dict[str, list[float]] = {mode: [], "none": []}
    cpus: dict[str, list[float]] = {mode: [], "none": []}
    rows: dict[str, list] = {}
    sizes: list[int] = []
    steps: list[int] = []
    for isolation in (mode, "none"):  # untimed: the first run of each pays for file caches and imports
        timed_run(args.controller, tasks[:1], 1, 1, isolation)
    for k in range(args.rounds):
        for isolation in ((mode, "none") if k % 2 == 0 else ("none", mode)):
            wall, cpu, record, log_sizes = timed_run(args.controller, tasks, args.episodes, args.workers, isolation)
            walls[isolation].append(wall)
            cpus[isolation].append(cpu)
            outcome = [{k2: v for k2, v in r.items() if not k2.startswith("action_log")} for r in record["episodes"]]
            rows.setdefault(isolation, outcome)
            if isolation == mode:
                sizes, steps = log_sizes, [r["steps"] for r in record["episodes"]]
            print(f"round {k + 1}: {isolation:<10} {wall:7.1f} s wall, {cpu:7.1f} s CPU", flush=True)
    identical = rows[mode] == rows["none"]
    ratio = sum(walls[mode]) / sum(walls["none"])
    per_round = [a / b for a, b in zip(walls[mode], walls["none"])]
    median_ratio = statistics.median(per_round)
    cpu_ratio = sum(cpus[mode]) / sum(cpus["none"])
    print(f"sandboxed ({mode}) / in-process wall time: {ratio:.3f} overall, median of rounds "
          f"{median_ratio:.3f}; per round " + ", ".join(f"{r:.3f}" for r in per_round)
          + f"; rows identical: {identical}")
    print(f"sandboxed / in-process CPU time (machine-wide busy time: all processes): {cpu_ratio:.3f}")
    per_step = [s / n for s, n in zip(sizes, steps)]
    print(f"action log per episode: mean {statistics.mean(sizes) / 1e3:.1f} kB, median "
          f"{statistics.median(sizes) / 1e3:.1f} kB, max {max(sizes) / 1e3:.1f} kB "
          f"({statistics.mean(per_step):.1f} bytes per control step; {len(sizes)} episodes)")
    trips = {f"{iso}, {'one core' if pinned else 'free'}": round_trip_us(iso, pinned)
             for iso in (mode, "none") for pinned in (True, False)}
    for name, us in trips.items():
        print(f"act() round trip ({name}): {us:.1f} us")
    out = REPO / "bench" / "out"
    out.mkdir(parents=True, exist_ok=True)
    (out / "sandbox_overhead.json").write_text(json.dumps({
        "controller": args.controller, "isolation": mode, "episodes_per_level": args.episodes, "levels": LEVELS,
        "workers": args.workers, "wall_time_s": walls, "cpu_time_s": cpus, "cpu_ratio": cpu_ratio, "ratio": ratio, "ratio_per_round": per_round,
        "ratio_median_of_rounds": median_ratio,
        "rows_identical": identical, "action_log_bytes": sizes, "episode_steps": steps,
        "act_round_trip_us": trips, "load_average_at_end": os.getloadavg()}, indent=1))


if __name__ == "__main__":
    main()
