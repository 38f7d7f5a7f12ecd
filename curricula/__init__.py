"""Curriculum files, the stage advancement rule and the curriculum training loop."""

from curricula.threads import limit_openmp_spinning

limit_openmp_spinning()  # before anything imports torch

from curricula.advancement import Decision, StageProgress, decide  # noqa: E402
from curricula.schema import ConfigError, Curriculum, RunConfig, load_curriculum, load_run_config  # noqa: E402

__all__ = ["ConfigError", "Curriculum", "Decision", "RunConfig", "StageProgress", "decide",
           "load_curriculum", "load_run_config"]
