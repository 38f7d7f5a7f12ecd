"""The stage advancement rule as a pure function of what happened in the stage.

No simulator or model is needed to test it: the training loop feeds it the episode
results of the current stage and the env steps spent in it.
"""

from __future__ import annotations

import enum
import math
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field

from myo_sds.curricula.schema import AdvanceRule
from myo_sds.envs.metrics import EpisodeResult


class Decision(enum.Enum):
    STAY = "stay"
    PASSED = "passed"  # threshold reached: go to the next stage
    TIMED_OUT = "timed_out"  # max_steps reached unpassed, on_max_steps: advance
    STOP = "stop"  # max_steps reached unpassed, on_max_steps: stop


def episode_metric(metric: str, result: EpisodeResult) -> float:
    """The value one episode contributes to an advancement metric (``result``: anything with
    the episode's official ``score`` and ``dropped``, e.g. a logged episode row)."""
    if metric == "score":
        return result.score
    if metric == "survival":
        return 0.0 if result.dropped else 1.0
    raise ValueError(f"unknown metric {metric!r}")


@dataclass
class StageProgress:
    """What the rule looks at: env steps in the stage and its recent episode metric values."""

    steps: int = 0
    episodes: int = 0
    recent: deque[float] = field(default_factory=deque)

    def record(self, values: Iterable[float], window: int) -> None:
        for value in values:
            self.recent.append(value)
            self.episodes += 1
            while len(self.recent) > window:
                self.recent.popleft()

    @property
    def measured(self) -> float:
        """Mean of the recent values (nan before the first episode)."""
        return sum(self.recent) / len(self.recent) if self.recent else math.nan


def decide(rule: AdvanceRule | None, progress: StageProgress) -> Decision:
    """Whether the stage is passed, goes on, or ran out of steps.

    Passed needs a full window of episodes whose mean reaches the threshold, after at least
    ``min_steps``. A stage without a rule never ends by itself.
    """
    if rule is None:
        return Decision.STAY
    full_window = len(progress.recent) >= rule.window
    if progress.steps >= rule.min_steps and full_window and progress.measured >= rule.threshold:
        return Decision.PASSED
    if rule.max_steps is not None and progress.steps >= rule.max_steps:
        return Decision.TIMED_OUT if rule.on_max_steps == "advance" else Decision.STOP
    return Decision.STAY
