"""The trainer: env and model construction, rollout collection, callbacks, the curriculum loop."""

from myo_sds.training.trainer import CurriculumTrainer

__all__ = ["CurriculumTrainer"]
