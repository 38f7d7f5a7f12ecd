"""Official MyoChallenge 2022 metrics, shared by the envs, the training callback and the evaluator.

Baoding (myosuite ``BaodingEnv.get_metrics``): an episode's score is its number of solved
steps divided by the 200-step horizon, so steps lost to an early drop count as unsolved.
Die reorientation (``ReorientEnv.get_metrics``): an episode scores 1 when it was solved on
more than 5 steps, else 0. The score is the mean over episodes. Effort is the mean over
episodes of the per-step muscle activation norm ``|act| / 39``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

PHASE_SECTOR_DEG = 45  # Baoding phases (the targets' angle on their orbit) are reported in sectors this wide
PHASE_SECTORS = 360 // PHASE_SECTOR_DEG


def phase_sector(phase: float) -> int:
    """Index of the 45-degree sector holding a phase in radians (any value; taken mod 2 pi)."""
    if not 0.0 <= phase <= 2 * math.pi:
        phase %= 2 * math.pi
    # min(): a phase that rounds to exactly 2 pi belongs to the last sector
    return min(int(math.degrees(phase) // PHASE_SECTOR_DEG), PHASE_SECTORS - 1)


def sector_name(index: int) -> str:
    return f"{index * PHASE_SECTOR_DEG}-{(index + 1) * PHASE_SECTOR_DEG}"


@dataclass(frozen=True)
class EpisodeResult:
    """What one finished episode contributes to the official metrics."""

    solved_steps: int
    length: int
    horizon: int
    dropped: bool
    effort: float  # mean over the episode's steps of |act| / n_muscles
    direction: str | None = None  # Baoding: hold, cw or ccw
    task: str = "baoding"
    start_phase: float | None = None  # Baoding: the targets' start angle on their orbit, rad in [0, 2 pi)
    # Baoding: per phase sector of the first target, the steps spent there and the solved ones:
    # which part of the orbit a policy fails to carry the balls through.
    steps_by_target_phase: tuple[int, ...] | None = None
    solved_by_target_phase: tuple[int, ...] | None = None
    # The episode's return under the env's reward weights (None: not known, e.g. the official env).
    reward: float | None = None
    # How the episode began (Baoding): "on_targets" (the balls placed on their targets), "rest"
    # (the balls where the hand holds them, the targets wherever the task starts them) or
    # "recorded" (a banked state of an earlier episode); None where the task does not say.
    start: str | None = None
    # With chained goals (``goal_chain``): how many goals the episode reached (None: no chain).
    goals_reached: int | None = None

    @property
    def score(self) -> float:
        """Official per-episode score of the task (its registered rule)."""
        from myo_sds.envs.task_specs import TASK_SPECS

        return TASK_SPECS[self.task].episode_score(self.solved_steps, self.horizon)

    def to_dict(self) -> dict:
        return {**asdict(self), "score": self.score}


def official_score(episodes: Sequence[EpisodeResult]) -> float:
    """Mean official per-episode score; ``nan`` for no episodes."""
    return float(np.mean([e.score for e in episodes])) if episodes else math.nan


def mean_effort(episodes: Sequence[EpisodeResult]) -> float:
    return float(np.mean([e.effort for e in episodes])) if episodes else math.nan


def drop_rate(episodes: Sequence[EpisodeResult]) -> float:
    return float(np.mean([e.dropped for e in episodes])) if episodes else math.nan


def mean_confidence_interval(values: Sequence[float], z: float = 1.96) -> tuple[float, float, float]:
    """``(mean, low, high)``: the mean and its normal-approximation 95% interval."""
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return math.nan, math.nan, math.nan
    mean = float(values.mean())
    half = z * float(values.std(ddof=1)) / math.sqrt(values.size) if values.size > 1 else 0.0
    return mean, mean - half, mean + half
