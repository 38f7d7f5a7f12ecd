"""Curriculum files and run configs, the stage advancement rule, the PPO schedule, and the
bundled curricula (``*.yaml`` beside this file). Imports no simulator and no torch."""

from myo_sds.curricula.advancement import Decision, decide
from myo_sds.curricula.run_config import RunConfig, load_run_config
from myo_sds.curricula.schema import ConfigError, Curriculum, load_curriculum
from myo_sds.curricula.state import CurriculumState, RunStatus, Transition

__all__ = ["ConfigError", "Curriculum", "CurriculumState", "Decision", "RunConfig", "RunStatus", "Transition",
           "decide", "load_curriculum", "load_run_config"]
