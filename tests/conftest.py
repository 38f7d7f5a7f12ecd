"""Shared fixtures: one tiny two-stage training for every test that only reads a finished run."""

from __future__ import annotations

from myo_sds import set_process_environment

set_process_environment()  # as the command lines do, before NumPy, torch and MuJoCo load

from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import pytest  # noqa: E402
from tiny_run import write_config  # noqa: E402

from myo_sds.curricula.state import CurriculumState  # noqa: E402
from myo_sds.training import CurriculumTrainer  # noqa: E402


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
