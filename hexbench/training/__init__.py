"""Training the baselines with Stable-Baselines3 (`hexbench train`), and what comes after it.

    hexbench train baselines/ppo_cpg.py --terrain rough --steps 1000000 --seed 0 --workers 2

The baseline file's CONFIG (see hexbench.agents.policy) picks the algorithm, action mode and
hyper-parameters.

    settings    TrainSettings, the baseline CONFIG, `--set` / `--curriculum` parsing
    wrappers    the training curricula and the early-end penalty, as env wrappers
    envs        the curriculum envs (one per worker), VecEnv, reward normaliser state
    warm_start  `--init-from`, `--value-warmup`, a config's initial action
    runs        the run directory and run.json (resume, checkpoints)
    callbacks   progress.csv rows, progress bar and periodic checkpoints
    loop        the training loop (`train`)
    selection   `hexbench checkpoints select`: checkpoints scored on held-out episodes
    publish     `hexbench checkpoints publish`
    curves      learning curves (paper Fig. 4)
    sweep       the epsilon search (paper 3.2)
    batch       a batch of runs, one per (terrain, seed), locally or on Ray (`hexbench train --seeds`)
"""
