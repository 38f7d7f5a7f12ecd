"""Curriculum files and run configs, the stage advancement rule, the PPO schedule, and the
bundled curricula (``*.yaml`` beside this file). Imports no simulator and no torch."""

from myo_sds.curricula.advancement import Decision, StageProgress, decide
from myo_sds.curricula.schema import (
           ConfigError,
           Curriculum,
           RunConfig,
           load_curriculum,
           load_run_config,
)

__all__ = ["ConfigError", "Curriculum", "Decision", "RunConfig", "StageProgress", "decide",
           "load_curriculum", "load_run_config"]
