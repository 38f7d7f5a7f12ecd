"""Learning curves of run folders and score histograms of evaluations."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from myo_sds.curricula.state import Transition
from myo_sds.envs.metrics import phase_sector, sector_name
from myo_sds.evaluation.checkpoints import EvaluationError
from myo_sds.evaluation.episodes import EvaluationReport
from myo_sds.run_folder import RunFolder


def trailing_mean(values: np.ndarray, window: int) -> np.ndarray:
    """Mean of the last ``window`` values at each point (fewer at the start)."""
    sums = np.cumsum(np.insert(np.asarray(values, dtype=float), 0, 0.0))
    index = np.arange(1, len(values) + 1)
    start = np.maximum(index - window, 0)
    return (sums[index] - sums[start]) / (index - start)


def plot_learning_curve(run_dir: Path, path: Path, window: int | None = None) -> None:
    """Score and survival of training episodes against env steps, stage changes marked; below,
    when the goal's start phase varies, the score of each 45-degree start-phase sector. The
    trailing ``window`` defaults to 50 episodes, more on long runs (1/200 of the episodes) so
    that a curve of millions of steps stays readable."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    run = RunFolder(run_dir)
    if not run.episodes_file.is_file():
        raise EvaluationError(f"{run_dir}: no training episodes logged yet to plot a learning curve from")
    rows = run.read_episodes()
    window = window or max(50, len(rows) // 200)
    steps = np.array([r.step for r in rows])
    scores = np.array([r.score for r in rows])
    survival = 1.0 - np.array([r.dropped for r in rows], dtype=float)
    # Runs begun before start phases were logged have none.
    phases = [r.start_phase for r in rows]
    by_phase = len({p for p in phases if p is not None}) > 1
    fig, axes = plt.subplots(2 if by_phase else 1, 1, figsize=(9, 8 if by_phase else 4.5), sharex=True, squeeze=False)
    ax = axes[0, 0]
    if len(rows):
        ax.plot(steps, trailing_mean(scores, window), color="C0", label=f"score (mean of last {window} episodes)")
    state = run.read_state()
    history = state.history if state is not None else []
    for entry in history:
        ax.axvline(entry.at_step, color="gray", linestyle="--", linewidth=1)
        ax.text(entry.at_step, 0.98, f" {entry.stage} {entry.decision}", rotation=90,
                va="top", ha="right", fontsize=7, transform=ax.get_xaxis_transform())
    # Each stage's threshold over the steps it ran (the current stage's up to the last episode).
    thresholds = _stage_thresholds(run, history, int(steps[-1]) if len(rows) else 0)
    for index, (start, end, threshold) in enumerate(thresholds):
        ax.hlines(threshold, start, end, colors="C3", linestyles=":", linewidth=1.5,
                  label="stage threshold" if index == 0 else None)
    axes[-1, 0].set_xlabel("env steps")
    ax.set_ylabel("score of training episodes")
    top = max([0.1, float(scores.max()) if len(rows) else 0.0] + [t for _, _, t in thresholds])
    ax.set_ylim(0, min(1.0, 1.15 * top))
    # The drop rate on its own axis, so it shows even when every episode drops (1.0) or none does.
    drops = ax.twinx()
    if len(rows):
        drops.plot(steps, 1.0 - trailing_mean(survival, window), color="C1", alpha=0.8, label="drop rate")
    drops.set_ylim(-0.02, 1.05)
    drops.set_ylabel("drop rate", color="C1")
    fig.suptitle(f"{run_dir.name}: training episodes by stage")
    handles = ax.get_legend_handles_labels()
    extra = drops.get_legend_handles_labels()
    ax.legend(handles[0] + extra[0], handles[1] + extra[1], loc="lower left", bbox_to_anchor=(0, 1.0), ncol=3,
              fontsize=8, frameon=False)
    if by_phase:
        sectors = np.array([phase_sector(p) if p is not None else -1 for p in phases])
        below = axes[1, 0]
        for k in sorted(set(sectors[sectors >= 0].tolist())):
            chosen = sectors == k
            below.plot(steps[chosen], trailing_mean(scores[chosen], window), linewidth=1,
                       color=plt.get_cmap("tab10")(k), label=f"{sector_name(k)} deg")
        for entry in history:
            below.axvline(entry.at_step, color="gray", linestyle="--", linewidth=1)
        below.set_ylabel(f"score by start phase\n(last {window} episodes of each)")
        below.set_ylim(0, ax.get_ylim()[1])
        below.legend(loc="upper left", ncol=4, fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_run_comparison(run_dirs: Sequence[Path], path: Path,
                        window: int | None = None) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Training score of several runs in one figure, against env steps (left) and hours of
    training (right): what a setting costs is judged on both. Each stage a run passed or left is a
    dot on its curve. The same trailing ``window`` for every run (default: 50 episodes, more for
    long runs, 1/200 of the shortest log). Returns each run's plotted (env steps, hours, score)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [RunFolder(run_dir) for run_dir in run_dirs]
    logs = {}
    for run in runs:
        rows = run.read_episodes()
        if not rows:
            raise EvaluationError(f"{run.path}: no training episodes logged yet to compare")
        logs[run.path.name] = (run, rows)
    window = window or max(50, min(len(rows) for _, rows in logs.values()) // 200)
    fig, (by_steps, by_hours) = plt.subplots(1, 2, figsize=(12, 4.5), sharey=True)
    curves = {}
    for index, (name, (run, rows)) in enumerate(logs.items()):
        steps = np.array([r.step for r in rows])
        hours = np.array([r.wall_s for r in rows]) / 3600.0
        score = trailing_mean(np.array([r.score for r in rows]), window)
        curves[name] = (steps, hours, score)
        color = plt.get_cmap("tab10")(index % 10)
        by_steps.plot(steps, score, color=color, label=name)
        by_hours.plot(hours, score, color=color, label=name)
        state = run.read_state()
        for entry in state.history if state is not None else []:
            at = min(int(np.searchsorted(steps, entry.at_step)), len(steps) - 1)
            by_steps.plot(steps[at], score[at], "o", color=color, markersize=5)
            by_hours.plot(hours[at], score[at], "o", color=color, markersize=5)
            by_steps.annotate(f" {entry.stage} {entry.decision}", (steps[at], score[at]), fontsize=7, color=color)
    by_steps.set_xlabel("env steps")
    by_hours.set_xlabel("hours of training")
    by_steps.set_ylabel(f"score of training episodes\n(mean of the last {window})")
    by_steps.set_ylim(0, 1.0)
    by_hours.legend(loc="upper left", fontsize=8, frameon=False)
    fig.suptitle("runs compared (dots: a stage passed or left)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return curves


def _stage_thresholds(run: RunFolder, history: list[Transition], last_step: int) -> list[tuple[int, int, float]]:
    """``(first step, last step, threshold)`` of each stage the run has been in that has one."""
    from myo_sds.curricula.schema import ConfigError, load_curriculum

    try:
        stages = load_curriculum(run.curriculum_file).stages
    except ConfigError:
        return []
    bounds = [0] + [entry.at_step for entry in history]
    reached = len(history) + 1 if len(history) < len(stages) else len(history)
    spans = []
    for index in range(min(reached, len(stages))):
        rule = stages[index].advance
        end = bounds[index + 1] if index + 1 < len(bounds) else max(last_step, bounds[index])
        if rule is not None:
            spans.append((bounds[index], end, rule.threshold))
    return spans


def plot_score_histogram(reports: Sequence[EvaluationReport], path: Path) -> None:
    """Episode scores as small multiples: one row per policy, one panel per env it was
    evaluated on, each panel's mean dashed and written in its title (scores lie in [0, 1])."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    policies = list(dict.fromkeys(r.checkpoint.label for r in reports))
    envs = list(dict.fromkeys(r.env.label for r in reports))
    fig, axes = plt.subplots(len(policies), len(envs), figsize=(2.6 * len(envs) + 0.6, 1.9 * len(policies) + 0.5),
                             sharex=True, squeeze=False)
    bins = np.linspace(0.0, 1.0, 21)
    for row, policy in enumerate(policies):
        for column, env in enumerate(envs):
            ax = axes[row][column]
            found = [r for r in reports if r.checkpoint.label == policy and r.env.label == env]
            if not found:
                ax.set_axis_off()
                continue
            values = np.array([e.score for e in found[0].episodes])
            ax.hist(values, bins=bins, color=plt.get_cmap("tab10")(row % 10), alpha=0.8)
            ax.axvline(values.mean(), color="black", linestyle="--", linewidth=1)
            ax.set_title(f"{env}: mean {values.mean():.3f}", fontsize=8)
            ax.tick_params(labelsize=7)
            if column == 0:
                ax.set_ylabel(_short(policy), fontsize=7)
            if row == len(policies) - 1:
                ax.set_xlabel("episode score", fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _short(label: str, width: int = 28) -> str:
    """A policy's label cut to fit beside a panel, keeping its end (the folder and file)."""
    return label if len(label) <= width else "..." + label[-(width - 3):]
