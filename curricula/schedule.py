"""The PPO settings in force at a stage and env step.

The run config's ``ppo`` sets them; each stage's ``ppo`` overrides some from its start until a
later stage changes them again; the run's warm-up overrides rollout length, minibatch size and
epochs for its first env steps; a learning rate may decay log-linearly from where it was set.
A pure function of the config and the step, so the trainer, a resumed run and the tests all see
the same schedule.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from myo_sds.curricula.run_config import RunConfig
from myo_sds.curricula.run_settings import STAGE_PPO_SETTINGS, LearningRateDecay


@dataclass(frozen=True)
class PpoSettings:
    """What the trainer applies to the model before each rollout: the stage-changeable settings
    (``STAGE_PPO_SETTINGS``), the learning rate as a number at this step."""

    learning_rate: float
    n_steps: int
    batch_size: int
    n_epochs: int
    clip_range: float
    ent_coef: float
    target_kl: float | None = None  # SB3's early stop of an update's epochs (None: all epochs)
    sequence_length: int | None = None  # the update's LSTM sequences cut every this many steps (None: not)


def ppo_settings_at(config: RunConfig, stage_index: int, stage_starts: Sequence[int], step: int) -> PpoSettings:
    """The settings at env step ``step`` of the run, in stage ``stage_index``.

    Args:
        stage_starts: the env step at which each stage up to ``stage_index`` began.
    """
    base = config.ppo
    values = {name: getattr(base, name) for name in STAGE_PPO_SETTINGS if name != "learning_rate"}
    rate, rate_set_at = base.learning_rate, 0
    for index, stage in enumerate(config.curriculum.stages[: stage_index + 1]):
        overrides = stage.ppo.as_dict()
        if "learning_rate" in overrides:
            rate, rate_set_at = overrides.pop("learning_rate"), stage_starts[index]
        values.update(overrides)
    warmup = base.warmup
    if warmup.active(step):
        values.update({k: v for k in ("n_steps", "batch_size", "n_epochs") if (v := getattr(warmup, k)) is not None})
    learning_rate = rate.at(step - rate_set_at) if isinstance(rate, LearningRateDecay) else rate
    return PpoSettings(learning_rate=learning_rate, **values)
