"""A checkpoint's files and their names (SB3's for the model and statistics, ours for the
curriculum state and the random streams); :mod:`myo_sds.run_folder` places them in a run."""

from __future__ import annotations

import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from myo_sds.curricula.state import CurriculumState


@dataclass(frozen=True)
class CheckpointFiles:
    """A checkpoint's files. The random state is optional: checkpoints written before it
    existed resume with streams seeded from the run's seed and step count."""

    steps: int
    model: Path
    vecnormalize: Path
    state: Path
    random_state: Path

    def __iter__(self):
        return iter((self.model, self.vecnormalize, self.state, self.random_state))

    def complete(self) -> bool:
        return all(path.is_file() for path in (self.model, self.vecnormalize, self.state))

    def read_state(self) -> CurriculumState:
        return CurriculumState.from_json(self.state.read_text())

    def read_random_state(self) -> dict[str, Any] | None:
        return pickle.loads(self.random_state.read_bytes()) if self.random_state.is_file() else None


def checkpoint_files(folder: Path, steps: int) -> CheckpointFiles:
    """SB3's names for a checkpoint's model and statistics, plus our curriculum state and the
    random generators' states."""
    return CheckpointFiles(steps, folder / f"rl_model_{steps}_steps.zip",
                           folder / f"rl_model_vecnormalize_{steps}_steps.pkl",
                           folder / f"curriculum_state_{steps}_steps.json",
                           folder / f"random_state_{steps}_steps.pkl")


def statistics_beside(model: Path) -> Path:
    """The normalization statistics saved beside a model file, under SB3's names."""
    name = model.name
    if name.startswith("rl_model_") and name.endswith("_steps.zip"):
        return model.with_name(name.replace("rl_model_", "rl_model_vecnormalize_").replace(".zip", ".pkl"))
    if "model" in name:  # final_model.zip, best_model_<steps>_steps.zip
        return model.with_name(name.replace("model", "vecnormalize").replace(".zip", ".pkl"))
    return model.with_name(f"{model.stem}_vecnormalize.pkl")  # a stage's hand-off: stages/<NN>_<stage>.zip
