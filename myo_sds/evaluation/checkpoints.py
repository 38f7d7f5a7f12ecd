"""Which policy a command-line target names, and loading it with its frozen statistics."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from myo_sds.curricula.schema import load_curriculum
from myo_sds.envs.knobs import TaskKnobs
from myo_sds.envs.task_specs import TASK_SPECS
from myo_sds.published import archive_spaces, load_statistics, published_files
from myo_sds.run_folder import RunFolder, statistics_beside

_OFFICIAL_DIRECTIONS = ("hold", "cw", "ccw")  # myosuite's Task enum values 0, 1, 2


class EvaluationError(ValueError):
    """A checkpoint or env that cannot be evaluated; the message says why and what to do."""


@dataclass(frozen=True)
class CheckpointRef:
    """A saved policy and the normalization statistics of the same step."""

    model: Path
    vecnormalize: Path
    run_dir: Path | None

    @property
    def label(self) -> str:
        return str(self.run_dir.name + "/" + self.model.name if self.run_dir else self.model)


@dataclass(frozen=True)
class EnvChoice:
    """Which env to evaluate on: a preset or a curriculum stage, ours or the official one."""

    task: str
    name: str  # "p1", "p2" or "stage:NAME"
    distribution: TaskKnobs  # our env's knobs (a preset's, or the stage's)
    official: bool = False
    start_noise: float = 0.0  # rad: each hand joint moved by U(-start_noise, start_noise) at reset

    @property
    def label(self) -> str:
        noise = f" noise {self.start_noise:g}" if self.start_noise else ""
        return f"{'official' if self.official else 'ours'}:{self.name}{noise}"



def resolve_checkpoint(target: str | Path, checkpoint_steps: int | None = None,
                       last_checkpoint: bool = False) -> CheckpointRef:
    """The policy a command-line target names.

    A run folder means its final model (or, with ``last_checkpoint``, its newest checkpoint;
    with ``checkpoint_steps``, that checkpoint); a ``.zip`` means that file, with the
    statistics saved beside it under SB3's naming.
    """
    path = Path(target)
    if not path.exists():
        raise EvaluationError(f"{path}: no such run folder or checkpoint")
    if path.is_dir():
        run = RunFolder.containing(path)
        if run is None:  # a policy as its authors published it: one .zip and one .pkl
            try:
                model, statistics = published_files(path)
            except FileNotFoundError as error:
                raise EvaluationError(str(error)) from None
            return CheckpointRef(model, statistics, None)
        if checkpoint_steps is not None:
            files = run.checkpoint(checkpoint_steps)
            if not files.model.is_file():
                raise EvaluationError(f"{files.model}: no checkpoint at {checkpoint_steps} steps")
            return CheckpointRef(files.model, files.vecnormalize, run.path)
        try:
            model, statistics = run.newest_policy(prefer_final=not last_checkpoint)
        except FileNotFoundError as error:
            raise EvaluationError(str(error)) from None
        return CheckpointRef(model, statistics, run.path)
    if path.suffix != ".zip":
        raise EvaluationError(f"{path}: expected a run folder or a model .zip")
    run = RunFolder.containing(path.parent)
    return CheckpointRef(path, statistics_beside(path), run.path if run else None)


@dataclass
class LoadedPolicy:
    model: Any
    normalizer: Any  # VecNormalize with frozen statistics, or None

    def act(self, obs: np.ndarray, state, episode_start: bool):
        action, state = self.act_together(obs[None], state, np.array([episode_start]))
        return action[0], state

    def act_together(self, batch: np.ndarray, state, episode_starts: np.ndarray):
        """Deterministic actions for a batch of observations (one row per episode), one forward pass."""
        full = self.model.observation_space.shape[0]
        if batch.shape[1] < full:  # a privileged critic's extra inputs: the actor never reads them
            batch = np.concatenate([batch, np.zeros((len(batch), full - batch.shape[1]), batch.dtype)], axis=1)
        if self.normalizer is not None:
            batch = self.normalizer.normalize_obs(batch)
        return self.model.predict(batch, state=state, episode_start=episode_starts, deterministic=True)


def load_policy(ref: CheckpointRef, task: str) -> LoadedPolicy:
    """Load a model and its statistics (frozen), checking they fit the task's observation."""
    from myo_sds.policy import load_model

    if not ref.model.is_file():
        raise EvaluationError(f"{ref.model}: checkpoint not found")
    try:
        model = load_model(ref.model, device="cpu")
    except Exception as error:  # zipfile, pickle and torch errors alike
        raise EvaluationError(f"{ref.model}: cannot load this checkpoint ({type(error).__name__}: {error}); "
                              "it is not a complete RecurrentPPO model archive") from None
    expected = TASK_SPECS[task].env_class().OBS_SIZE
    shape = model.observation_space.shape
    # A policy trained with a privileged critic takes more, but its actor reads the official part.
    actor_size = getattr(model.policy, "actor_observation_size", None) or shape[0]
    if actor_size != expected:
        raise EvaluationError(f"{ref.model}: the policy takes observations of shape {shape}, but the "
                              f"{task} env gives ({expected},): it was trained on another task")
    normalizer = None
    if ref.vecnormalize.is_file():
        try:
            normalizer = load_statistics(ref.vecnormalize)
        except Exception as error:
            raise EvaluationError(f"{ref.vecnormalize}: cannot read normalization statistics ({error})") from None
        normalizer.training = False  # evaluation never updates the statistics
        normalizer.norm_reward = False
    else:
        raise EvaluationError(f"{ref.vecnormalize}: normalization statistics of this checkpoint not found "
                              "(they are saved beside the model under SB3's names)")
    return LoadedPolicy(model, normalizer)


def run_task(ref: CheckpointRef) -> str:
    """The task a checkpoint was trained on: from its run folder, else from its observation size."""
    if ref.run_dir is not None:
        return load_curriculum(RunFolder(ref.run_dir).curriculum_file).task
    try:
        shape = archive_spaces(ref.model)[0].shape
    except Exception as error:
        raise EvaluationError(f"{ref.model}: cannot load this checkpoint ({type(error).__name__}: {error}); "
                              "it is not a complete RecurrentPPO model archive") from None
    for name, spec in TASK_SPECS.items():
        if shape == (spec.env_class().OBS_SIZE,):
            return name
    raise EvaluationError(f"{ref.model}: the policy takes observations of shape {shape}: it was trained on another "
                          f"task than these ({', '.join(f'{n}: ({s.env_class().OBS_SIZE},)' for n, s in TASK_SPECS.items())})")


def choose_env(ref: CheckpointRef, name: str, official: bool = False, start_noise: float = 0.0) -> EnvChoice:
    """Parse a preset (``p1``, ``p1_2022``, ``p2``) or ``stage:NAME`` (a stage of the checkpoint's
    own curriculum); ``start_noise`` (rad) moves each hand joint at reset."""
    task = run_task(ref)
    if not (start_noise >= 0 and math.isfinite(start_noise)):
        raise EvaluationError(f"--start-noise {start_noise}: expected radians >= 0, e.g. 0.02")
    if start_noise and not TASK_SPECS[task].hand_joints:
        raise EvaluationError(f"--start-noise: the {task} task declares no hand joints to move")
    presets = TASK_SPECS[task].knobs.PRESETS
    if name in presets:
        choice = EnvChoice(task, name, TASK_SPECS[task].knobs.parse(name), official, start_noise)
    elif name.startswith("stage:"):
        if official:
            raise EvaluationError(f"--env {name}: the official env has only the presets' tasks "
                                  f"({', '.join(presets)})")
        if ref.run_dir is None:
            raise EvaluationError(f"--env {name}: {ref.model} is not inside a run folder, so it has no curriculum")
        curriculum = load_curriculum(RunFolder(ref.run_dir).curriculum_file)
        try:
            stage = curriculum.stages[curriculum.stage_index(name[len("stage:"):])]
        except KeyError as error:
            raise EvaluationError(f"--env {name}: {error.args[0]}") from None
        choice = EnvChoice(task, name, stage.distribution, official, start_noise)
    else:
        raise EvaluationError(f"--env {name!r}: expected one of {', '.join(presets)} or stage:NAME")
    if official and name not in TASK_SPECS[task].official_ids:
        raise EvaluationError(f"no official env for {task} {name}")
    return choice


