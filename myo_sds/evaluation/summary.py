"""A run at a glance, while it trains or after it ended: per stage, env steps and wall time
spent, the measured value against the threshold, and how the current stage is trending."""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from myo_sds.curricula.advancement import episode_metric
from myo_sds.curricula.schema import EVALUATION_METRICS, load_curriculum
from myo_sds.envs.task_specs import TASK_SPECS
from myo_sds.evaluation.episodes import per_start_phase
from myo_sds.evaluation.update_sizes import UpdateSizes, format_steps, recent_update_sizes
from myo_sds.run_folder import EpisodeRecord, RunFolder

TREND_POINTS = 5  # measured values shown across the current stage
BREAKDOWN_EPISODES = 2000  # the current stage's latest episodes, split by start phase
WINDOW_BEFORE_CHECKPOINT = 100  # episodes shown for a run without a checkpoint yet


@dataclass
class StageSummary:
    index: int  # from 1, as on the console
    name: str
    status: str  # passed | timed_out | plateaued | stop | current | not reached
    env_steps: int
    wall_s: float
    episodes: int
    metric: str | None
    threshold: float | None
    window: int | None
    measured: float | None  # at the transition, or now for the current stage
    trend: list[tuple[int, float]] = field(default_factory=list)  # (run env step, measured) in the current stage
    # The current stage's latest episodes by start phase (Baoding: the targets'; the die: the goal's
    # angle): a stage mean that stops rising often hides sectors where the task always fails.
    by_start_phase: dict[str, dict[str, Any]] = field(default_factory=dict)
    # The stage's periodic evaluations (``evaluate`` in the curriculum): best and last mean score,
    # the step of the best, and the step of the policy handed to the next stage (None: its last).
    evaluated_best: float | None = None
    evaluated_last: float | None = None
    evaluated_best_step: int | None = None
    handed_off_step: int | None = None
    evaluated_best_reward: float | None = None  # the best evaluation's mean return
    evaluated_last_reward: float | None = None
    # The stage-end probe of the policy handed on (``probe`` in the curriculum).
    probe: dict[str, Any] | None = None
    # The rest-start signal: the stage's training episodes that began with the balls at rest (not
    # placed on their targets), by direction: how many, their median solved steps and mean score.
    rest_starts: dict[str, dict[str, Any]] = field(default_factory=dict)
    # The stage's rest starts by the targets' start phase: from which phases the policy picks
    # the resting balls up (the 2022 start puts the targets on them, at 135 degrees).
    rest_by_start_phase: dict[str, dict[str, Any]] = field(default_factory=dict)


@dataclass
class RunSummary:
    run_dir: str
    status: str
    env_steps: int
    wall_s: float
    stages: list[StageSummary]
    # When the state above was written (Unix time). A process killed without warning leaves
    # "running" behind, so the age of its last checkpoint is what tells a live run from a dead one.
    saved_at: float | None = None
    # The newest saved policy's action std over the 39 muscles: (mean, min, max). A std that has
    # collapsed (the 2022 winner's ended at a mean of 0.116, min 0.086) no longer explores.
    action_std: tuple[float, float, float] | None = None
    start_phase_name: str = "the start phase"  # what the episodes' start phase measures (the task's)
    # Approximate KL, clip fraction and explained variance of the newest updates (TensorBoard).
    update_sizes: UpdateSizes | None = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _metric_values(records: list[EpisodeRecord], metric: str) -> np.ndarray:
    return np.array([episode_metric(metric, r) for r in records])


def summarize(run_dir: str | Path) -> RunSummary:
    """The summary of a run folder (its latest checkpoint's state and its episode log)."""
    folder = RunFolder(run_dir)
    if not folder.path.is_dir():
        raise FileNotFoundError(f"{folder.path}: no such run folder")
    state = folder.read_state()
    if state is None:
        raise FileNotFoundError(f"{folder.path}: no checkpoint yet, nothing to summarize")
    curriculum = load_curriculum(folder.curriculum_file)
    records = [r for r in folder.read_episodes() if r.step <= state.num_timesteps]
    start_walls = state.stage_start_walls(records)
    stages = []
    for index, stage in enumerate(curriculum.stages):
        rule = stage.advance
        base = StageSummary(index + 1, stage.name, "not reached", 0, 0.0, 0, rule.metric if rule else None,
                            rule.threshold if rule else None, rule.window if rule else None, None)
        if index < len(state.history):
            transition = state.history[index]
            base.status, base.env_steps, base.episodes = transition.decision, transition.stage_steps, transition.stage_episodes
            base.wall_s = start_walls[index + 1] - start_walls[index]
            base.measured = None if math.isnan(transition.measured) else transition.measured
            base.evaluated_best, base.handed_off_step = transition.best_evaluated, transition.handed_off_step
            base.evaluated_best_reward, base.probe = transition.best_evaluated_reward, transition.probe
        elif index == state.stage_index:
            base.status = "current" if state.status.value in ("running", "interrupted", "time_limit") else state.status.value
            base.env_steps, base.episodes = state.num_timesteps - state.stage_start_step, state.stage_episodes
            base.wall_s = state.wall_s - start_walls[index]
            base.measured = float(np.mean(state.recent)) if state.recent else None
            base.evaluated_best, base.evaluated_last = state.best_evaluated, state.last_evaluated
            base.evaluated_best_step = state.best_evaluated_step
            base.evaluated_best_reward, base.evaluated_last_reward = state.best_evaluated_reward, state.last_evaluated_reward
            in_stage = [r for r in records if r.stage_index == index]
            if rule is not None and in_stage:
                values = _metric_values(in_stage, rule.window_metric)
                steps = np.array([r.step for r in in_stage])
                for mark in np.linspace(steps[0], steps[-1], TREND_POINTS):
                    upto = values[steps <= mark][-rule.window:]
                    if len(upto):
                        base.trend.append((int(mark), float(upto.mean())))
            base.by_start_phase = per_start_phase(in_stage[-BREAKDOWN_EPISODES:])
        if index <= state.stage_index:
            in_stage = [r for r in records if r.stage_index == index]
            base.rest_starts = rest_starts(in_stage)
            base.rest_by_start_phase = per_start_phase([r for r in in_stage if r.start == "rest"])
        stages.append(base)
    # An exported model (no checkpoints of its own) is a snapshot: its file times say nothing.
    saved_at = folder.state_file.stat().st_mtime if folder.checkpoint_dir.is_dir() else None
    return RunSummary(str(folder.path), state.status.value, state.num_timesteps, state.wall_s, stages, saved_at,
                      _action_std(folder), TASK_SPECS[curriculum.task].start_phase_name,
                      recent_update_sizes(folder.tensorboard_dir))


def before_first_checkpoint(run_dir: str | Path) -> str | None:
    """What ``--status`` says of a run that has no checkpoint yet (nothing to summarize): when the
    first comes and what its episode log shows so far. None for a folder with a checkpoint."""
    from myo_sds.curricula.run_config import load_run_config

    folder = RunFolder(run_dir)
    if not folder.path.is_dir() or folder.read_state() is not None or not folder.config_file.is_file():
        return None
    config = load_run_config(folder.config_file)
    text = f"{folder.path}: no checkpoint yet (the first at {config.checkpoint_every:,} env steps)"
    records = folder.read_episodes()
    if not records:
        return text + "; no episode has ended yet"
    last, recent = records[-1], records[-WINDOW_BEFORE_CHECKPOINT:]
    stage = config.curriculum.stages[last.stage_index].name
    return (f"{text}; its episode log: {len(records):,} episodes up to env step {last.step:,}, stage "
            f"{last.stage_index + 1} ({stage}); the last {len(recent)}: score {np.mean([r.score for r in recent]):.3f}, "
            f"{np.mean([r.dropped for r in recent]):.0%} dropped, median solved steps "
            f"{np.median([r.solved_steps for r in recent]):.0f}")


def rest_starts(records: list[EpisodeRecord]) -> dict[str, dict[str, Any]]:
    """Of ``records``, the episodes begun with the balls at rest, by direction: count, median
    solved steps, mean score (empty when none did, or the log predates the ``start`` column)."""
    by_direction: dict[str, list[EpisodeRecord]] = {}
    for r in records:
        if r.start == "rest":
            by_direction.setdefault(r.direction or "all", []).append(r)
    return {direction: {"episodes": len(members),
                        "median_solved_steps": float(np.median([r.solved_steps for r in members])),
                        "score": float(np.mean([r.score for r in members]))}
            for direction, members in sorted(by_direction.items())}


def _action_std(folder: RunFolder) -> tuple[float, float, float] | None:
    """(mean, min, max) of the newest saved policy's action std, None without a saved policy."""
    from stable_baselines3.common.save_util import load_from_zip_file

    checkpoint = folder.latest_checkpoint()
    model = checkpoint.model if checkpoint is not None else folder.final_model
    if not model.is_file():
        return None
    _, params, _ = load_from_zip_file(model, load_data=False, device="cpu")
    std = params["policy"]["log_std"].exp()
    return float(std.mean()), float(std.min()), float(std.max())


STAGE_COLUMNS = ("stage", "status", "env steps", "hours", "episodes", "measured / threshold")


def stage_rows(summary: RunSummary) -> tuple[tuple[str, ...], list[tuple[str, ...]]]:
    """The stage table's header and one row of text per stage (``--status`` and model cards)."""
    rows = []
    for s in summary.stages:
        target = _target(s)
        rows.append((f"{s.index} {s.name}", s.status, f"{s.env_steps:,}", f"{s.wall_s / 3600:.2f}", f"{s.episodes:,}",
                     target))
    if any(s.evaluated_best is not None for s in summary.stages):
        return STAGE_COLUMNS + ("evaluated (deterministic)",), [
            row + (_evaluated(s),) for row, s in zip(rows, summary.stages)]
    return STAGE_COLUMNS, rows


def _target(s: StageSummary) -> str:
    """The stage's advancement value against its threshold (an evaluation metric: the best
    evaluation's, with the training window's score beside it)."""
    if not s.metric:
        return "no advancement rule"
    window = "-" if s.measured is None else f"{s.measured:.3f}"
    if s.metric == "eval_reward":
        best = "-" if s.evaluated_best_reward is None else f"{s.evaluated_best_reward:.0f}"
        return f"eval return {best} (best) / {s.threshold:g}; training score {window}"
    if s.metric == "eval_score":
        best = "-" if s.evaluated_best is None else f"{s.evaluated_best:.3f}"
        return f"eval score {best} (best) / {s.threshold:g}; training score {window}"
    return f"{s.metric} {window} / {s.threshold}"


def _evaluated(s: StageSummary) -> str:
    if s.evaluated_best is None:
        return "-"
    text = f"best {s.evaluated_best:.3f}"
    if s.evaluated_best_reward is not None:
        text += f" (return {s.evaluated_best_reward:.0f})"
    if s.evaluated_best_step is not None:
        text += f" at {format_steps(s.evaluated_best_step)}"
    if s.evaluated_last is not None:
        text += f", last {s.evaluated_last:.3f}"
        if s.evaluated_last_reward is not None:
            text += f" ({s.evaluated_last_reward:.0f})"
    if s.status not in ("current", "not reached"):
        text += f"; handed on {'the best' if s.handed_off_step is not None else 'its last'}"
    return text


def _status_line(summary: RunSummary, now: float) -> str:
    status = summary.status
    if status == "running" and summary.saved_at is None:
        status = "exported while its run was running"
    elif status == "running":
        saved = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(summary.saved_at))
        status = f"running as of its last checkpoint ({saved}, {max(0.0, now - summary.saved_at) / 60:.0f} min ago)"
    return f"{summary.run_dir}: {status}, {summary.env_steps:,} env steps, {summary.wall_s / 3600:.2f} h of training"


def describe_directions(by_direction: dict[str, dict] | None) -> str:
    """``; by direction: ccw 7, return 412, median 5, 86% dropped; ...`` (empty for one direction
    or none; the return where it was recorded)."""
    if not by_direction or len(by_direction) < 2:
        return ""
    return "; by direction: " + "; ".join(
        f"{d} {v['episodes']}" + (f", return {v['reward']:.0f}" if v.get("reward") is not None else "")
        + f", median {v['median_solved_steps']:.0f}, {v['drop_rate']:.0%} dropped"
        for d, v in by_direction.items())


def format_summary(summary: RunSummary, now: float | None = None) -> str:
    """The summary as a table a person reads at a glance (``now``: Unix time, for the checkpoint's age)."""
    lines = [_status_line(summary, time.time() if now is None else now)]
    if summary.action_std is not None:
        mean, low, high = summary.action_std
        lines.append(f"action std of the newest saved policy: mean {mean:.3f} (min {low:.3f}, max {high:.3f})")
    if summary.update_sizes is not None:
        lines.append(f"updates, {summary.update_sizes.describe()}")
    header, rows = stage_rows(summary)
    widths = [max(len(str(r[i])) for r in (header, *rows)) for i in range(len(header))]
    for row in (header, *rows):
        lines.append("  ".join(str(v).ljust(w) for v, w in zip(row, widths)).rstrip())
    current = [s for s in summary.stages if s.trend]
    for s in current:
        points = ", ".join(f"{value:.3f} at {format_steps(step)}" for step, value in s.trend)
        metric = "training score" if s.metric in EVALUATION_METRICS else s.metric
        lines.append(f"stage {s.index} trend ({metric} over the last {s.window} episodes): {points}")
    rest = [s for s in summary.stages if s.rest_starts]
    if rest:
        lines.append("episodes begun with the balls at rest (not on their targets), by direction: "
                     "count, median solved steps")
        for s in rest:
            parts = "; ".join(f"{d} {v['episodes']:,}, {v['median_solved_steps']:.0f}" for d, v in s.rest_starts.items())
            lines.append(f"  stage {s.index} ({s.name}): {parts}")
    probed = [s for s in summary.stages if s.probe]
    if probed:
        env = probed[0].probe["env"]
        lines.append(f"stage-end probe of the policy handed on ({env}, {probed[0].probe['episodes']} episodes):")
        for s in probed:
            p = s.probe
            lines.append(f"  stage {s.index} ({s.name}): median solved steps {p['median_solved_steps']:.0f}, "
                         f"score {p['score']:.3f}, {p['drop_rate']:.0%} dropped{describe_directions(p.get('by_direction'))}")
    for s in summary.stages:
        if s.by_start_phase:
            n = sum(sector["episodes"] for sector in s.by_start_phase.values())
            lines.append(f"stage {s.index}, its last {n:,} episodes by {summary.start_phase_name}:")
            lines.extend(_sector_table(s.by_start_phase))
    for s in summary.stages:
        if s.rest_by_start_phase:
            n = sum(sector["episodes"] for sector in s.rest_by_start_phase.values())
            lines.append(f"stage {s.index}, its {n:,} episodes begun with the balls at rest, by {summary.start_phase_name}:")
            lines.extend(_sector_table(s.rest_by_start_phase))
    return "\n".join(lines)


def _drop_step(sector: dict[str, Any]) -> str:
    step = sector.get("drop_step")  # summaries written before it was recorded lack it
    return "-" if step is None else f"{step:.0f}"


def _sector_table(sectors: dict[str, dict[str, Any]]) -> list[str]:
    rows = [("  degrees", *sectors),
            ("  score", *(f"{v['score']:.2f}" for v in sectors.values())),
            ("  dropped", *(f"{v['drop_rate']:.0%}" for v in sectors.values())),
            ("  at step", *(_drop_step(v) for v in sectors.values())),
            ("  episodes", *(str(v["episodes"]) for v in sectors.values()))]
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return ["  ".join(v.ljust(w) for v, w in zip(row, widths)).rstrip() for row in rows]
