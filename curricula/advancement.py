"""The stage advancement rule as a pure function of what happened in the stage.

No simulator or model is needed to test it: it reads the curriculum state (the current
stage's env steps and its window of episode metric values), which the training loop updates.
"""

from __future__ import annotations

import enum
import math

from myo_sds.curricula.schema import AdvanceRule
from myo_sds.curricula.state import CurriculumState
from myo_sds.envs.metrics import EpisodeResult


class Decision(enum.Enum):
    STAY = "stay"
    PASSED = "passed"  # threshold reached: go to the next stage
    TIMED_OUT = "timed_out"  # max_steps reached unpassed, on_max_steps: advance
    STOP = "stop"  # max_steps reached or plateaued unpassed, on_max_steps: stop
    PLATEAUED = "plateaued"  # no gain for plateau_steps, on_max_steps: advance


def episode_metric(metric: str, result: EpisodeResult) -> float:
    """The value one episode contributes to an advancement metric (``result``: anything with
    the episode's official ``score`` and ``dropped``, e.g. a logged episode row)."""
    if metric == "score":
        return result.score
    if metric == "survival":
        return 0.0 if result.dropped else 1.0
    raise ValueError(f"unknown metric {metric!r}")


def measured_value(rule: AdvanceRule, state: CurriculumState) -> float:
    """The value the rule compares with its threshold: the window's mean once the window is full,
    or the stage's latest evaluation (nan when there is none yet)."""
    if rule.metric == "eval_score":
        return math.nan if state.last_evaluated is None else state.last_evaluated
    if rule.metric == "eval_reward":
        return math.nan if state.last_evaluated_reward is None else state.last_evaluated_reward
    return state.measured if len(state.recent) >= rule.window else math.nan


def decide(rule: AdvanceRule | None, state: CurriculumState) -> Decision:
    """Whether the stage is passed, goes on, or ran out of steps.

    Passed needs, after at least ``min_steps``, a full window of episodes whose mean reaches the
    threshold (for an evaluation metric: the latest evaluation at the threshold). Plateaued:
    ``plateau_steps`` env steps since the window's mean last rose ``plateau_gain`` above its best. A stage without a rule never ends by itself.
    """
    if rule is None:
        return Decision.STAY
    if state.stage_steps >= rule.min_steps and measured_value(rule, state) >= rule.threshold:
        return Decision.PASSED
    if rule.max_steps is not None and state.stage_steps >= rule.max_steps:
        return Decision.TIMED_OUT if rule.on_max_steps == "advance" else Decision.STOP
    if (rule.plateau_steps is not None and state.best_measured is not None and state.stage_steps >= rule.min_steps
            and state.stage_steps - state.best_at_stage_step >= rule.plateau_steps):
        return Decision.PLATEAUED if rule.on_max_steps == "advance" else Decision.STOP
    return Decision.STAY
