"""Shared fixtures: one tiny two-stage training for every test that only reads a finished run."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest
from tiny_run import write_config

from myo_sds.curricula.state import CurriculumState
from myo_sds.training import CurriculumTrainer


@dataclass(frozen=True)
class FinishedRun:
    """A tiny run trained to its 2,048-step budget: stage 1 passed, stage 2 in progress.
    Tests must not change its folder (copy it first)."""

    path: Path
    trainer: CurriculumTrainer
    state: CurriculumState


@pytest.fixture(scope="session")
def tiny_run(tmp_path_factory) -> FinishedRun:
    folder = tmp_path_factory.mktemp("tiny_run")
    trainer = CurriculumTrainer.start(write_config(folder, total=2048), run_dir=folder / "run", progress=False)
    state = trainer.run()
    return FinishedRun(folder / "run", trainer, state)
