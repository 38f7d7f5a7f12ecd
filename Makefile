# Two entry points: `make demo` (set up, train the quickstart curriculum, evaluate it) and
# `make test` (set up, run the test suite). Both create .venv on first use.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
RUN_DIR := runs/quickstart

.PHONY: setup demo test test-fast wheel-check bench clean

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	# CPU torch first, so no dependency can pull a multi-GB CUDA build.
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $@

setup: $(VENV)/.installed

# The quickstart run beside two trained policies: the 2022 winner's published phase-1 policy and
# ours from scratch, on the 2022 start without and with start noise; the video shows the winner's
# best and worst episode with noise (one turns the balls, one drops them).
demo: setup
	$(PY) train.py --config configs/quickstart.yaml --run-dir $(RUN_DIR) --overwrite
	$(PY) evaluate.py models/reference/stiff_fingers_2022_p1 models/baoding_p1_2022 $(RUN_DIR) --env p1_2022 --start-noise 0,0.02 --episodes 8 --official --json $(RUN_DIR)/evaluation.json --plots $(RUN_DIR)/plots --video $(RUN_DIR)/episodes.mp4

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
