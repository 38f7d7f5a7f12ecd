"""The run folder: the one place that knows its files, their names and their formats.

::

    RUN/
      config.yaml, curriculum.yaml      the resolved run config and its own copy of the curriculum
      command.txt, versions.json        each session's command line, time and machine; package versions
      curriculum_state.json             the curriculum state of the latest checkpoint
      episodes.csv                      one row per training episode
      evaluations.csv                   one row per stage evaluation and stage-end probe
      stages/                           the policy each finished stage handed on: <NN>_<stage>.zip, _vecnormalize.pkl
      checkpoints/                      rl_model_<steps>_steps.zip, rl_model_vecnormalize_<steps>_steps.pkl,
                                        curriculum_state_<steps>_steps.json, random_state_<steps>_steps.pkl
      final_model.zip, final_vecnormalize.pkl
      tb/                               TensorBoard events

An exported model folder (:meth:`RunFolder.export_model`) holds the model, its statistics and
curriculum state, the config, curriculum and provenance files, and a model card (README.md).

Every file is replaced in one rename (written under a temporary name first), so a crash or a
``kill -9`` leaves the previous version readable.
"""

from __future__ import annotations

import json
import os
import pickle
import sys
import time
from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path
from typing import Any

from myo_sds import numerics
from myo_sds.checkpoint_files import CheckpointFiles, checkpoint_files, statistics_beside
from myo_sds.curricula.state import CurriculumState
from myo_sds.episode_log import (
    EPISODE_COLUMNS,
    EpisodeRecord,
    EvaluationRecord,
    append_episodes,
    append_evaluations,
    read_episodes,
    read_evaluations,
    truncate_episodes,
)

__all__ = ["EPISODE_COLUMNS", "CheckpointFiles", "EpisodeRecord", "EvaluationRecord", "RunFolder", "checkpoint_files",
           "statistics_beside"]

CONFIG_FILE = "config.yaml"
CURRICULUM_FILE = "curriculum.yaml"
STATE_FILE = "curriculum_state.json"
EPISODES_FILE = "episodes.csv"
EVALUATIONS_FILE = "evaluations.csv"
STAGES_DIR = "stages"
CHECKPOINT_DIR = "checkpoints"
FINAL_MODEL = "final_model.zip"
FINAL_VECNORMALIZE = "final_vecnormalize.pkl"
COMMAND_FILE = "command.txt"
VERSIONS_FILE = "versions.json"
MODEL_CARD = "README.md"


def atomic_write_text(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def _atomic_save(path: Path, save) -> None:
    """Run ``save(tmp_path)`` and rename the result into place."""
    tmp = path.with_name(f".tmp_{path.name}")
    save(tmp)
    os.replace(tmp, path)


class _InRun:
    """A file or folder of the run by name: ``RunFolder(p).config_file`` is ``p / "config.yaml"``."""

    def __init__(self, name: str) -> None:
        self.name = name

    def __get__(self, folder: RunFolder | None, owner: type | None = None):
        return self if folder is None else folder.path / self.name


class RunFolder:
    """A run folder on disk (see the module docstring for its layout)."""

    config_file = _InRun(CONFIG_FILE)
    curriculum_file = _InRun(CURRICULUM_FILE)
    state_file = _InRun(STATE_FILE)
    episodes_file = _InRun(EPISODES_FILE)
    evaluations_file = _InRun(EVALUATIONS_FILE)
    checkpoint_dir = _InRun(CHECKPOINT_DIR)
    final_model = _InRun(FINAL_MODEL)
    final_vecnormalize = _InRun(FINAL_VECNORMALIZE)
    tensorboard_dir = _InRun("tb")
    command_file = _InRun(COMMAND_FILE)
    versions_file = _InRun(VERSIONS_FILE)
    model_card = _InRun(MODEL_CARD)

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    def __repr__(self) -> str:
        return f"RunFolder({str(self.path)!r})"

    # creation and provenance -----------------------------------------------------------

    @classmethod
    def create(cls, output_dir: Path, config_name: str, seed: int) -> RunFolder:
        """A fresh, race-free folder ``<output_dir>/<config>-<date>-<time>-s<seed>[-n]``."""
        stamp = time.strftime("%Y%m%d-%H%M%S")
        base = Path(output_dir) / f"{config_name}-{stamp}-s{seed}"
        for attempt in range(1000):
            candidate = base if attempt == 0 else base.with_name(f"{base.name}-{attempt}")
            try:
                candidate.mkdir(parents=True, exist_ok=False)
                return cls(candidate)
            except FileExistsError:
                continue
        raise RuntimeError(f"could not create a run folder next to {base}")

    @classmethod
    def claim(cls, path: Path, overwrite: bool = False) -> RunFolder:
        """``path`` as a new run's folder: created, or emptied with ``overwrite``; a folder that
        holds anything is otherwise refused (a ``ConfigError`` saying what to do instead)."""
        import shutil

        from myo_sds.curricula.yaml_reader import ConfigError

        if path.exists() and any(path.iterdir()):
            if not overwrite:
                raise ConfigError(f"{path}: run folder exists and is not empty; use --resume "
                                  "to continue it or --overwrite to replace it")
            shutil.rmtree(path)
        path.mkdir(parents=True, exist_ok=True)
        return cls(path)

    def remove(self) -> None:
        """Delete the folder and everything in it (a run that failed before training)."""
        import shutil

        shutil.rmtree(self.path)

    def write_provenance(self, config_yaml: str, curriculum_yaml: str) -> None:
        """The resolved config (pointing at the folder's own copy of the curriculum), that
        copy, the command line and the package versions."""
        (self.path / CURRICULUM_FILE).write_text(curriculum_yaml)
        (self.path / CONFIG_FILE).write_text(config_yaml)
        self.command_file.unlink(missing_ok=True)
        self.record_session(0)
        self.versions_file.write_text(json.dumps(numerics.package_versions(), indent=2))

    def record_session(self, from_step: int) -> None:
        """Append this session's command line to ``command.txt``, after a comment line with
        the time, the step it starts from and the machine: a run resumed many times keeps
        how each part of it was trained."""
        from myo_sds.numerics import cpu_name
        from myo_sds.threads import available_cpus

        when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
        with self.command_file.open("a") as file:
            file.write(f"# {when}, from env step {from_step:,}, {available_cpus()} CPUs ({cpu_name()})\n"
                       f"{' '.join(sys.argv)}\n")

    def looks_like_run(self) -> bool:
        """A run folder, or a model folder exported from one (:meth:`export_model`)."""
        return self.config_file.is_file() and (self.checkpoint_dir.is_dir() or self.final_model.is_file())

    def export_model(self, destination: Path, checkpoint: CheckpointFiles | None = None) -> RunFolder:
        """A light folder for sharing a policy: the model of ``checkpoint`` (default: the final
        model, else the latest checkpoint) with its optimizer state, its normalization statistics
        and curriculum state, and the run's config, curriculum and provenance (command lines,
        versions); no checkpoints and no logs. The model card is the caller's to write.
        ``evaluate.py`` and ``train.py --status`` read it like a run folder."""
        import shutil

        if checkpoint is None and not self.final_model.is_file():
            checkpoint = self.latest_checkpoint()
        if checkpoint is None and not self.final_model.is_file():
            raise FileNotFoundError(f"{self.path}: no final model and no complete checkpoint to export")
        target = RunFolder(destination)
        target.path.mkdir(parents=True, exist_ok=True)
        model, stats, state_file = ((self.final_model, self.final_vecnormalize, self.state_file) if checkpoint is None
                                    else (checkpoint.model, checkpoint.vecnormalize, checkpoint.state))
        for source, copy in ((model, target.final_model), (stats, target.final_vecnormalize),
                             (self.config_file, target.config_file), (self.curriculum_file, target.curriculum_file)):
            shutil.copyfile(source, copy)
        for source, copy in ((self.command_file, target.command_file), (self.versions_file, target.versions_file)):
            if source.is_file():
                shutil.copyfile(source, copy)
        # The export has no episode log: keep each stage's start time in the state itself.
        state = CurriculumState.from_json(state_file.read_text())
        episodes = self.read_episodes()
        if checkpoint is not None and checkpoint.steps < state.num_timesteps:  # a stage's best (best_of_stage)
            state.rewind_current_stage(checkpoint.steps, episodes)
        walls = state.stage_start_walls(episodes)[1:]
        state.history = [replace(t, wall_s=wall_s) for t, wall_s in zip(state.history, walls)]
        target.state_file.write_text(state.to_json())
        self._copy_evaluations(target, state.num_timesteps)
        return target

    def _copy_evaluations(self, target: RunFolder, max_step: int) -> None:
        """The evaluation log up to ``max_step`` (small; the stage curves are drawn from it)."""
        target.evaluations_file.unlink(missing_ok=True)
        records = [r for r in self.read_evaluations() if r.step <= max_step]
        if records:
            target.append_evaluations(records)

    def best_of_stage(self, checkpoint: CheckpointFiles | None = None) -> CheckpointFiles:
        """The best evaluated policy of the stage ``checkpoint`` (default: the newest complete
        one) is in, as checkpoint files: its model and statistics, with that checkpoint's
        curriculum and random state (:meth:`export_model` rewinds the state to the policy's step)."""
        checkpoint = checkpoint or self.latest_checkpoint()
        if checkpoint is None:
            raise FileNotFoundError(f"{self.path}: no complete checkpoint")
        state = checkpoint.read_state()
        step = state.best_evaluated_step
        if step is None:
            raise FileNotFoundError(f"{self.path}: the checkpoint at {checkpoint.steps:,} steps has no evaluated "
                                    f"policy in its stage (stage {state.stage_index + 1}: no `evaluate` in the "
                                    "curriculum, or none run yet)")
        model, statistics = self.best_files(step)
        if not (model.is_file() and statistics.is_file()):
            raise FileNotFoundError(f"{self.path}: the stage's best policy ({model.name}, {statistics.name}) is missing")
        return CheckpointFiles(step, model, statistics, checkpoint.state, checkpoint.random_state)

    def export_resumable(self, destination: Path, checkpoint: CheckpointFiles | None = None) -> RunFolder:
        """What ``--resume`` needs of the run, for another machine: config, curriculum,
        provenance, and one checkpoint (default: the newest complete one) with its model,
        optimizer, statistics, curriculum and random state, and the evaluation log; no episode log
        and no TensorBoard events. An earlier export at ``destination`` is replaced (its checkpoints removed)."""
        import shutil

        checkpoint = checkpoint or self.latest_checkpoint()
        if checkpoint is None:
            raise FileNotFoundError(f"{self.path}: no complete checkpoint to export")
        target = RunFolder(destination)
        if target.checkpoint_dir.is_dir():
            shutil.rmtree(target.checkpoint_dir)
        target.checkpoint_dir.mkdir(parents=True)
        for source, copy in ((self.config_file, target.config_file), (self.curriculum_file, target.curriculum_file),
                             (self.command_file, target.command_file), (self.versions_file, target.versions_file),
                             (checkpoint.state, target.state_file)):
            if source.is_file():
                shutil.copyfile(source, copy)
        state = checkpoint.read_state()
        best_step = state.best_evaluated_step
        for path in [*checkpoint, *(self.best_files(best_step) if best_step is not None else ())]:
            if path.is_file():
                shutil.copyfile(path, target.checkpoint_dir / path.name)
        self._copy_evaluations(target, state.num_timesteps)
        return target

    @classmethod
    def require(cls, path: Path) -> RunFolder:
        """The run (or model) folder ``path`` names, else ``FileNotFoundError`` saying why."""
        if not Path(path).exists():
            raise FileNotFoundError(f"{path}: no such file or folder")
        folder = cls.containing(path)
        if folder is None:
            raise FileNotFoundError(f"{path}: not a run folder (no {CONFIG_FILE} with {CHECKPOINT_DIR}/ or "
                                    f"{FINAL_MODEL} inside)")
        return folder

    @classmethod
    def containing(cls, path: Path) -> RunFolder | None:
        """The run folder that is ``path`` or holds it (a checkpoint file, ``checkpoints/``)."""
        path = Path(path)
        for folder in (path, path.parent, path.parent.parent):
            if cls(folder).looks_like_run():
                return cls(folder)
        return None

    # curriculum state ------------------------------------------------------------------

    def read_state(self) -> CurriculumState | None:
        """The state of the latest checkpoint, None before the first one."""
        path = self.state_file
        return CurriculumState.from_json(path.read_text()) if path.is_file() else None

    # checkpoints -----------------------------------------------------------------------

    def checkpoint(self, steps: int) -> CheckpointFiles:
        return checkpoint_files(self.checkpoint_dir, steps)

    def checkpoint_steps(self) -> list[int]:
        """Steps of the checkpoints whose model file exists, in increasing order."""
        steps = []
        for path in self.checkpoint_dir.glob("rl_model_*_steps.zip"):
            try:
                steps.append(int(path.name[len("rl_model_"):-len("_steps.zip")]))
            except ValueError:
                continue
        return sorted(steps)

    def newest_policy(self, prefer_final: bool = True) -> tuple[Path, Path]:
        """(model, normalization statistics): the final model, else (or when not
        ``prefer_final``) the newest complete checkpoint."""
        if prefer_final and self.final_model.is_file():
            return self.final_model, self.final_vecnormalize
        files = self.latest_checkpoint()
        if files is None:
            raise FileNotFoundError(f"{self.path}: no final model and no complete checkpoint yet")
        return files.model, files.vecnormalize

    def latest_checkpoint(self) -> CheckpointFiles | None:
        """The newest checkpoint whose files all exist."""
        for steps in reversed(self.checkpoint_steps()):
            files = self.checkpoint(steps)
            if files.complete():
                return files
        return None

    def save_checkpoint(self, model, venv, state: CurriculumState, random_state: dict[str, Any],
                        keep: int) -> CheckpointFiles:
        """Model (with optimizer), normalization statistics, curriculum state and random
        generators of one step, each renamed into place, then the folder's state file; the
        oldest checkpoints beyond ``keep`` are removed."""
        self.checkpoint_dir.mkdir(parents=True, exist_ok=True)
        files = self.checkpoint(state.num_timesteps)
        _atomic_save(files.model, model.save)
        _atomic_save(files.vecnormalize, lambda tmp: venv.save(str(tmp)))
        _atomic_save(files.random_state, lambda tmp: tmp.write_bytes(pickle.dumps(random_state)))
        atomic_write_text(files.state, state.to_json())
        atomic_write_text(self.state_file, state.to_json())
        for old in self.checkpoint_steps()[:-keep]:
            for path in self.checkpoint(old):
                path.unlink(missing_ok=True)
        self._prune_best(state.best_evaluated_step)
        return files

    def best_files(self, steps: int) -> tuple[Path, Path]:
        """The model and statistics of the stage's best evaluated policy, of env step ``steps``."""
        return (self.checkpoint_dir / f"best_model_{steps}_steps.zip",
                self.checkpoint_dir / f"best_vecnormalize_{steps}_steps.pkl")

    def save_best(self, model, venv, steps: int) -> None:
        """Keep the policy of a stage's new best evaluation (older ones go at the next checkpoint,
        once no saved state names them)."""
        self.checkpoint_dir.mkdir(parents=True, exist_ok=True)
        model_file, statistics = self.best_files(steps)
        _atomic_save(model_file, model.save)
        _atomic_save(statistics, lambda tmp: venv.save(str(tmp)))

    def _prune_best(self, keep: int | None) -> None:
        for path in [*self.checkpoint_dir.glob("best_model_*_steps.zip"),
                     *self.checkpoint_dir.glob("best_vecnormalize_*_steps.pkl")]:
            if keep is None or path.name not in {f.name for f in self.best_files(keep)}:
                path.unlink(missing_ok=True)

    def save_final(self, model, venv) -> None:
        _atomic_save(self.final_model, model.save)
        _atomic_save(self.final_vecnormalize, lambda tmp: venv.save(str(tmp)))

    # episodes --------------------------------------------------------------------------

    def append_episodes(self, records: Iterable[EpisodeRecord]) -> None:
        append_episodes(self.episodes_file, records)

    def read_episodes(self) -> list[EpisodeRecord]:
        return read_episodes(self.episodes_file)

    def truncate_episodes(self, max_step: int) -> None:
        """Forget episodes and evaluations logged after ``max_step`` (a resumed run redoes them)."""
        truncate_episodes(self.episodes_file, max_step)
        truncate_episodes(self.evaluations_file, max_step)

    def append_evaluations(self, records: Iterable[EvaluationRecord]) -> None:
        append_evaluations(self.evaluations_file, records)

    def read_evaluations(self) -> list[EvaluationRecord]:
        return read_evaluations(self.evaluations_file)

    # stages ----------------------------------------------------------------------------

    def stage_policy_files(self, stage_index: int, stage: str) -> tuple[Path, Path]:
        """The policy stage ``stage_index`` (from 0) handed on, and its statistics."""
        model = self.path / STAGES_DIR / f"{stage_index + 1:02d}_{stage}.zip"
        return model, statistics_beside(model)

    def save_stage_policy(self, stage_index: int, stage: str, model, venv) -> None:
        model_file, statistics = self.stage_policy_files(stage_index, stage)
        model_file.parent.mkdir(parents=True, exist_ok=True)
        _atomic_save(model_file, model.save)
        _atomic_save(statistics, lambda tmp: venv.save(str(tmp)))
