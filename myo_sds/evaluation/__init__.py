"""Official-metric evaluation of trained checkpoints, on our env and on myosuite's own env:
which checkpoint (``checkpoints``), its episodes and their report (``episodes``), the printed
table (``table``), plots (``plots``) and a video (``video``)."""

from myo_sds.envs.metrics import phase_sector, sector_name
from myo_sds.evaluation.checkpoints import (
    CheckpointRef,
    EnvChoice,
    EvaluationError,
    LoadedPolicy,
    choose_env,
    load_policy,
    resolve_checkpoint,
    run_task,
)
from myo_sds.evaluation.episodes import (
    EvaluationReport,
    evaluate,
    per_start_phase,
    per_target_phase,
    run_episode,
)
from myo_sds.evaluation.plots import (
    plot_learning_curve,
    plot_run_comparison,
    plot_score_histogram,
    trailing_mean,
)
from myo_sds.evaluation.summary import RunSummary, StageSummary, format_summary, summarize
from myo_sds.evaluation.table import format_table
from myo_sds.evaluation.video import chosen_episodes, record_video

__all__ = ["CheckpointRef", "EnvChoice", "EvaluationError", "EvaluationReport", "LoadedPolicy",
           "choose_env", "chosen_episodes", "evaluate", "format_table", "load_policy", "per_start_phase",
           "per_target_phase", "phase_sector", "plot_learning_curve", "plot_run_comparison", "plot_score_histogram", "record_video", "resolve_checkpoint",
           "run_episode", "run_task", "sector_name", "trailing_mean", "RunSummary", "StageSummary", "format_summary",
           "summarize"]
