# Two entry points: `make demo` (set up, train the quickstart curriculum, evaluate it) and
# `make test` (set up, run the test suite). Both create .venv on first use.
PYTHON ?= python3
# Where pip looks for PyTorch first (empty: its own indexes). On plain PyPI torch 2.13.0 is the
# CUDA build (2.7 GB with its nvidia packages); TORCH_INDEX=https://download.pytorch.org/whl/cpu
# takes the CPU build (192 MB).
TORCH_INDEX ?=
VENV := .venv
PY := $(VENV)/bin/python
RUN_DIR := runs/quickstart

.PHONY: setup setup-run demo test test-fast wheel-check bench clean

# The demo installs what it runs; the tests add their tools (pytest, ruff, Ray).
$(VENV)/.installed-run: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	# torch first, pinned: no dependency then pulls another build of it.
	$(PY) -m pip install --quiet torch==2.13.0 $(if $(TORCH_INDEX),--index-url $(TORCH_INDEX))
	$(PY) -m pip install --quiet -e .
	touch $@

$(VENV)/.installed: $(VENV)/.installed-run
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $@

setup-run: $(VENV)/.installed-run

setup: $(VENV)/.installed

# The quickstart (about a minute and a half of training on from our shipped from-scratch policy:
# configs/quickstart.yaml), then the trained policy beside the one it started from, on MyoSuite
# 3.0.0's P1 start with each hand joint moved by up to 0.02 rad at reset, 30 episodes each on our
# env and MyoSuite's; the video shows the trained policy's best and worst episode. Each phase's
# time is printed.
demo:
	@t0=$$(date +%s); $(MAKE) --no-print-directory setup-run; t1=$$(date +%s); \
	$(PY) train.py --config configs/quickstart.yaml --run-dir $(RUN_DIR) --overwrite && t2=$$(date +%s) && \
	$(PY) evaluate.py $(RUN_DIR) models/baoding_p1_2022 --env p1 --start-noise 0.02 --episodes 30 --official --workers 2 --json $(RUN_DIR)/evaluation.json --plots $(RUN_DIR)/plots --video $(RUN_DIR)/episodes.mp4 && t3=$$(date +%s) && \
	echo "demo: set-up $$((t1 - t0)) s, training $$((t2 - t1)) s, evaluation and video $$((t3 - t2)) s, in all $$((t3 - t0)) s"

test: setup
	$(PY) -m ruff check .
	$(PY) -m pytest -q

test-fast: setup
	$(PY) -m pytest -q -m "not slow"

# The wheel in a fresh venv, its commands run from another folder (CI runs this too).
wheel-check:
	.ci/wheel_check

bench: setup
	$(PY) benchmarks/env_speed.py

clean:
	rm -rf $(VENV) runs
