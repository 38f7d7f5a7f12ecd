"""``episodes.csv`` of a run folder: one row per training episode (:class:`EpisodeRecord`).

Only :class:`myo_sds.run_folder.RunFolder` calls these, with its own file's path.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

EPISODE_COLUMNS = ("step", "wall_s", "stage_index", "stage", "score", "solved_steps", "length", "dropped",
                   "effort", "direction", "start_phase")


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

    def to_row(self) -> tuple:
        phase = "" if self.start_phase is None else f"{self.start_phase:.4f}"
        return (self.step, f"{self.wall_s:.2f}", self.stage_index, self.stage, f"{self.score:.6g}", self.solved_steps,
                self.length, int(self.dropped), f"{self.effort:.6g}", self.direction or "", phase)

    @classmethod
    def from_row(cls, row: dict[str, str]) -> EpisodeRecord:
        phase = row.get("start_phase") or ""
        return cls(int(row["step"]), float(row["wall_s"]), int(row["stage_index"]), row["stage"], float(row["score"]),
                   int(row["solved_steps"]), int(row["length"]), row["dropped"] == "1", float(row["effort"]),
                   row["direction"], float(phase) if phase else None)



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
    """Drop episodes logged after the checkpoint a resumed run restarts from, and a row that a
    kill cut short."""
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
