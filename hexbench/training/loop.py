"""The training loop of `hexbench train`: check the settings, open (or resume) the run, build the
learner and let it learn until the env-step budget, with a progress bar, and a checkpoint on
SIGINT / SIGTERM before exiting.

Off-policy methods (SAC, TD3) resume with an empty replay buffer: buffers are large and pickled, so
they are not saved.
"""

from __future__ import annotations

import signal
import threading
from pathlib import Path

from hexbench.agents.policy import action_noise, algo_class, config_dict, policy_kwargs, sb3_kwargs
from hexbench.artifacts.manifest import CheckpointError, verify_checkpoint
from hexbench.training.envs import (
    make_run_vec_env,
    restore_curriculum,
    restore_reward_normalizer,
    reward_normalizer_state,
)
from hexbench.training.runs import check_resume, new_run, read_run, save_checkpoint, start_session
from hexbench.training.settings import TrainError, TrainSettings, check_settings, load_run_config
from hexbench.training.warm_start import make_value_warmup, read_init_weights, set_initial_action


def train(settings: TrainSettings) -> dict:
    """Train (or resume) a run; returns the final run.json content."""
    import torch

    torch.set_num_threads(1)
    check_settings(settings)
    config = load_run_config(settings)
    run_dir = settings.run_dir
    previous = read_run(run_dir)
    cfg_dict = config_dict(config)
    if previous is not None:
        check_resume(run_dir, previous, settings, cfg_dict)
    init_state, init_info = None, None
    if settings.init_from is not None and previous is None:  # read (and verify) before any file is written
        init_state, init_info = read_init_weights(settings.init_from, config)
    run = start_session(run_dir, previous or new_run(settings, cfg_dict, init_info), settings)
    venv = make_run_vec_env(settings, config)
    if run["checkpoints"]:
        model = resume_model(run_dir, run, venv, config, settings)
    else:
        model = new_model(venv, config, settings, init_state)
    if settings.total_steps - model.num_timesteps <= 0:
        venv.close()
        return run
    return learn(settings, run, model, venv)


def resume_model(run_dir: Path, run: dict, venv, config, settings: TrainSettings):
    """The run's last checkpoint (sha256 checked), with the reward normaliser and curricula restored."""
    last = run["checkpoints"][-1]
    path = run_dir / last["file"]
    try:
        verify_checkpoint(path, last["sha256"])
    except CheckpointError as e:
        venv.close()
        raise TrainError(str(e)) from None
    extra = {"action_noise": action_noise(config)} if action_noise(config) is not None else {}
    model = algo_class(config.algo).load(path, env=venv, device=settings.device, **extra)
    restore_reward_normalizer(venv, last.get("reward_normalizer"))
    restore_curriculum(venv, run["curriculum"])
    return model


def new_model(venv, config, settings: TrainSettings, init_weights: dict | None):
    """A fresh learner of the config's algorithm, started at its initial action or from warm-start weights."""
    extra = {"action_noise": action_noise(config)} if action_noise(config) is not None else {}
    model = algo_class(config.algo)("MlpPolicy", venv, seed=settings.seed, device=settings.device, verbose=0,
                                    policy_kwargs=policy_kwargs(config), **sb3_kwargs(config), **extra)
    if getattr(config, "initial_action", None) is not None:
        set_initial_action(model, config.initial_action)
    if init_weights is not None:
        model.policy.load_state_dict(init_weights, strict=False)  # fit checked by read_init_weights
    return model


def progress_bar(settings: TrainSettings, completed_steps: int):
    """(rich Progress, its task, the stderr console) for the run's env steps."""
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    console = Console(stderr=True)
    progress = Progress(TextColumn(f"[bold]{settings.method} {settings.terrain} seed {settings.seed}"), BarColumn(),
                        MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn(), TextColumn("{task.fields[info]}"),
                        console=console, disable=not settings.show_progress, transient=False)
    task = progress.add_task("train", total=settings.total_steps, completed=completed_steps, info="starting")
    return progress, task, console


def learn(settings: TrainSettings, run: dict, model, venv) -> dict:
    """Learn up to the budget; a checkpoint at the end, also when interrupted (then a TrainError)."""
    from hexbench.training.callbacks import TrainingMonitor

    run_dir = settings.run_dir

    def save(model, env_steps: int, wall_time_s: float, curriculum: list[dict], summary: dict) -> None:
        save_checkpoint(run_dir, run, model, env_steps, wall_time_s, curriculum, summary,
                        reward_normalizer_state(venv))

    progress, task, console = progress_bar(settings, model.num_timesteps)
    log_to = console if settings.log_lines and not console.is_terminal else None  # a log file: lines, not a bar
    callback = TrainingMonitor(settings, run, save, progress, task, log_to)
    callbacks = [callback, make_value_warmup(settings.value_warmup_steps)] if settings.value_warmup_steps else callback
    interrupted = False
    # SIGTERM checkpoints too; signals reach the main thread only (a run in a worker thread keeps its default)
    in_main_thread = threading.current_thread() is threading.main_thread()
    old_handler = signal.signal(signal.SIGTERM, _raise_keyboard_interrupt) if in_main_thread else None
    try:
        with progress:
            model.learn(total_timesteps=settings.total_steps - model.num_timesteps, reset_num_timesteps=False,
                        callback=callbacks)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if in_main_thread:
            signal.signal(signal.SIGTERM, old_handler)
    if callback.model is not None and callback.model.num_timesteps > (run["env_steps"] or 0):
        callback.num_timesteps = callback.model.num_timesteps
        try:
            callback.checkpoint()
        except (EOFError, BrokenPipeError, ConnectionError) as e:  # worker processes already gone
            console.print(f"final checkpoint not saved ({type(e).__name__}); last one is at {run['env_steps']} steps")
    venv.close()
    if interrupted:
        raise TrainError(f"interrupted at {run['env_steps']} env steps; checkpoint saved in {run_dir} "
                         f"(run the same command to resume)")
    return run


def _raise_keyboard_interrupt(signum, frame):
    raise KeyboardInterrupt
