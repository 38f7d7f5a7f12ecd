"""``episodes.csv`` of a run folder: one row per training episode (:class:`EpisodeRecord`);
``evaluations.csv``: one row per stage evaluation or stage-end probe (:class:`EvaluationRecord`).

Only :class:`myo_sds.run_folder.RunFolder` calls these, with its own file's path.
"""

from __future__ import annotations

import csv
import json
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

EPISODE_COLUMNS = ("step", "wall_s", "stage_index", "stage", "score", "solved_steps", "length", "dropped",
                   "effort", "direction", "start_phase", "reward", "start", "goals")


@dataclass(frozen=True)
class EpisodeRecord:
    """One row of ``episodes.csv``: a training episode and when it ended."""

    step: int
    wall_s: float  # the run's training wall time when the episode ended
    stage_index: int
    stage: str
    score: float
    solved_steps: int
    length: int
    dropped: bool
    effort: float
    direction: str
    start_phase: float | None  # rad; None in runs begun before it was logged
    reward: float | None = None  # the episode's return under the stage's reward weights
    start: str | None = None  # on_targets | rest | recorded (EpisodeResult.start)
    goals: int | None = None  # goals reached, with chained goals (EpisodeResult.goals_reached)

    def to_row(self) -> tuple:
        phase = "" if self.start_phase is None else f"{self.start_phase:.4f}"
        reward = "" if self.reward is None else f"{self.reward:.6g}"
        return (self.step, f"{self.wall_s:.2f}", self.stage_index, self.stage, f"{self.score:.6g}", self.solved_steps,
                self.length, int(self.dropped), f"{self.effort:.6g}", self.direction or "", phase, reward,
                self.start or "", "" if self.goals is None else self.goals)

    @classmethod
    def from_row(cls, row: dict[str, str]) -> EpisodeRecord:
        phase, reward = row.get("start_phase") or "", row.get("reward") or ""
        return cls(int(row["step"]), float(row["wall_s"]), int(row["stage_index"]), row["stage"], float(row["score"]),
                   int(row["solved_steps"]), int(row["length"]), row["dropped"] == "1", float(row["effort"]),
                   row["direction"], float(phase) if phase else None, float(reward) if reward else None,
                   row.get("start") or None, int(row["goals"]) if row.get("goals") else None)



EVALUATION_COLUMNS = ("step", "stage_index", "stage", "kind", "env", "episodes", "score", "reward", "drop_rate",
                      "median_solved_steps", "best", "first_seed", "by_direction")


@dataclass(frozen=True)
class EvaluationRecord:
    """One row of ``evaluations.csv``: deterministic episodes of the policy of env step ``step``.

    ``kind``: ``periodic`` (the stage's ``evaluate``), ``final`` (its last policy, at the stage's
    end) or ``probe`` (the curriculum's stage-end probe of the policy handed on); ``best``: it became
    the stage's best; ``first_seed``: its episodes were reset with seeds ``first_seed ..
    first_seed + episodes - 1`` (``evaluate.py --seed`` replays them); ``by_direction``: Baoding's
    episodes, mean return, median solved steps and drop rate per direction (JSON in the file)."""

    step: int
    stage_index: int
    stage: str
    kind: str
    env: str
    episodes: int
    score: float
    reward: float | None
    drop_rate: float
    median_solved_steps: float
    best: bool = False
    first_seed: int = 0  # files written before the column existed evaluated seeds 0 ..
    by_direction: dict[str, dict] | None = None

    def to_row(self) -> tuple:
        reward = "" if self.reward is None else f"{self.reward:.6g}"
        directions = json.dumps(self.by_direction, separators=(",", ":")) if self.by_direction else ""
        return (self.step, self.stage_index, self.stage, self.kind, self.env, self.episodes, f"{self.score:.6g}", reward,
                f"{self.drop_rate:.6g}", f"{self.median_solved_steps:g}", int(self.best), self.first_seed, directions)

    @classmethod
    def from_row(cls, row: dict[str, str]) -> EvaluationRecord:
        return cls(int(row["step"]), int(row["stage_index"]), row["stage"], row["kind"], row["env"], int(row["episodes"]),
                   float(row["score"]), float(row["reward"]) if row["reward"] else None, float(row["drop_rate"]),
                   float(row["median_solved_steps"]), row["best"] == "1", int(row.get("first_seed") or 0),
                   json.loads(row["by_direction"]) if row.get("by_direction") else None)


def append_evaluations(path: Path, records: Iterable[EvaluationRecord]) -> None:
    """Add rows; a run begun before the last columns existed keeps its header, and its rows match it."""
    new = not path.exists()
    n_columns = len(EVALUATION_COLUMNS) if new else len(_header(path))
    with path.open("a", newline="") as file:
        writer = csv.writer(file)
        if new:
            writer.writerow(EVALUATION_COLUMNS)
        writer.writerows(record.to_row()[:n_columns] for record in records)


def read_evaluations(path: Path) -> list[EvaluationRecord]:
    if not path.is_file():
        return []
    with path.open(newline="") as file:
        return [EvaluationRecord.from_row(row) for row in csv.DictReader(file)]


def append_episodes(path: Path, records: Iterable[EpisodeRecord]) -> None:
    """Add rows to the file; a run begun before the last columns existed keeps its header, and
    its rows match it."""
    new = not path.exists()
    n_columns = len(EPISODE_COLUMNS) if new else len(_header(path))
    with path.open("a", newline="") as file:
        writer = csv.writer(file)
        if new:
            writer.writerow(EPISODE_COLUMNS)
        for record in records:
            writer.writerow(record.to_row()[:n_columns])


def read_episodes(path: Path) -> list[EpisodeRecord]:
    if not path.is_file():
        return []
    with path.open(newline="") as file:
        return [EpisodeRecord.from_row(row) for row in csv.DictReader(file)]


def truncate_episodes(path: Path, max_step: int) -> None:
    """Drop rows (episodes, evaluations) logged after the checkpoint a resumed run restarts from,
    and a row that a kill cut short."""
    if not path.exists():
        return
    with path.open(newline="") as file:
        rows = list(csv.reader(file))
    if not rows:
        path.unlink()
        return
    header = rows[0]

    def kept(row: Sequence[str]) -> bool:
        try:
            return len(row) == len(header) and int(row[0]) <= max_step
        except ValueError:
            return False

    tmp = path.with_name(f".{path.name}.tmp")
    with tmp.open("w", newline="") as file:
        csv.writer(file).writerows([header] + [row for row in rows[1:] if kept(row)])
    os.replace(tmp, path)


def _header(path: Path) -> list[str]:
    with path.open(newline="") as file:
        return next(csv.reader(file), [])
