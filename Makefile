# Two commands do all set-up on a fresh clone:  `make run` (the main job)  and  `make test`.
VENV ?= .venv
PY := $(VENV)/bin/python
# torch 2.13.0: on the hexbench CI machines pip takes a CPU build from local disk. Elsewhere,
# for a CPU-only build pass PyTorch's CPU wheel index, e.g. TORCH_PIP_ARGS="--index-url <cpu index>".
TORCH_SPEC ?= torch==2.13.0
TORCH_PIP_ARGS ?=

.PHONY: setup run test test-all browser sandbox
setup: $(VENV)/.installed sandbox

$(VENV)/.installed: pyproject.toml
	test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install -q --disable-pip-version-check $(TORCH_PIP_ARGS) "$(TORCH_SPEC)"
	$(PY) -m pip install -q --disable-pip-version-check -e ".[test]"
	touch $@

run: setup
	$(VENV)/bin/hexbench run baselines/ppo_cpg.py

# bubblewrap isolates each submitted controller (hexbench/evaluation/sandbox.py); libseccomp2 backs its seccomp
# filter. Without them hexbench falls back to --isolation process and says so.
sandbox:
	@(test -x /usr/bin/bwrap && /sbin/ldconfig -p | grep -q libseccomp.so.2) \
		|| (apt-get update && apt-get install -y bubblewrap libseccomp2) \
		|| echo "bubblewrap could not be installed; controllers will run with --isolation process"

# Headless Chromium for the leaderboard's browser test (Debian's chromium); the test skips if it cannot be had.
browser:
	@test -x /usr/bin/chromium || (apt-get update && apt-get install -y chromium) \
		|| echo "chromium could not be installed; the leaderboard browser test will skip"

# One test process per core (pytest-xdist; at most 4, each holds torch and PyBullet), each test file
# in one of them: the red-team attacks look for leftovers machine-wide and must not run side by side,
# and a module's fixtures (the Ray cluster) are made once. Plain `pytest` runs in one process.
PYTEST_PARALLEL ?= -n auto --maxprocesses 4 --dist loadfile

test: setup browser
	$(PY) -m pytest -q $(PYTEST_PARALLEL)

test-all: setup
	$(PY) -m pip install -q --disable-pip-version-check -e ".[ray]"
	$(PY) -m pytest -q $(PYTEST_PARALLEL) -m "slow or not slow"
