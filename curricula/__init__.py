"""Curriculum files, the stage advancement rule and the curriculum training loop."""

from curricula.advancement import Decision, StageProgress, decide
from curricula.schema import ConfigError, Curriculum, RunConfig, load_curriculum, load_run_config

__all__ = ["ConfigError", "Curriculum", "Decision", "RunConfig", "StageProgress", "decide",
           "load_curriculum", "load_run_config"]
