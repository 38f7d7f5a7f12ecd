"""Official-metric evaluation of trained checkpoints, on our env and on myosuite's own env.

Episode ``i`` of an evaluation is reset with seed ``seed + i``. Our presets draw task
instances exactly as the official env does, so the same seeds give the same episodes on
both; with a deterministic policy the two scores then agree (tests/test_evaluation.py).
"""

from __future__ import annotations

import math
import multiprocessing
import pickle
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from curricula.training import CHECKPOINT_DIR, EPISODES_FILE, STATE_FILE, checkpoint_files, latest_checkpoint
from envs import TASKS
from envs.metrics import EpisodeResult, official_score, drop_rate, mean_confidence_interval, mean_effort

OFFICIAL_IDS = {("baoding", "p1"): "myoChallengeBaodingP1-v1", ("baoding", "p2"): "myoChallengeBaodingP2-v1",
                ("die", "p1"): "myoChallengeDieReorientP1-v0", ("die", "p2"): "myoChallengeDieReorientP2-v0"}
_OFFICIAL_DIRECTIONS = ("hold", "cw", "ccw")  # myosuite's Task enum values 0, 1, 2


class EvaluationError(ValueError):
    """A checkpoint or env that cannot be evaluated; the message says why and what to do."""


@dataclass(frozen=True)
class CheckpointRef:
    """A saved policy and the normalization statistics of the same step."""

    model: Path
    vecnormalize: Path
    run_dir: Path | None

    @property
    def label(self) -> str:
        return str(self.run_dir.name + "/" + self.model.name if self.run_dir else self.model)


@dataclass(frozen=True)
class EnvChoice:
    """Which env to evaluate on: a preset or a curriculum stage, ours or the official one."""

    task: str
    name: str  # "p1", "p2" or "stage:NAME"
    knobs: dict[str, Any]
    official: bool = False

    @property
    def label(self) -> str:
        return f"{'official' if self.official else 'ours'}:{self.name}"


@dataclass
class EvaluationReport:
    checkpoint: CheckpointRef
    env: EnvChoice
    seed: int
    episodes: list[EpisodeResult] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        scores = [e.score for e in self.episodes]
        mean, low, high = mean_confidence_interval(scores)
        per_direction = {}
        for direction in sorted({e.direction for e in self.episodes if e.direction}):
            values = [e.score for e in self.episodes if e.direction == direction]
            d_mean, d_low, d_high = mean_confidence_interval(values)
            per_direction[direction] = {"episodes": len(values), "score": d_mean, "ci95": [d_low, d_high]}
        return {
            "checkpoint": str(self.checkpoint.model),
            "run_dir": str(self.checkpoint.run_dir) if self.checkpoint.run_dir else None,
            "env": self.env.name,
            "official_env": self.env.official,
            "seed": self.seed,
            "episodes": len(self.episodes),
            "score": official_score(self.episodes),
            "score_ci95": [low, high],
            "effort": mean_effort(self.episodes),
            "drop_rate": drop_rate(self.episodes),
            "mean_length": float(np.mean([e.length for e in self.episodes])) if self.episodes else math.nan,
            "per_direction": per_direction,
            "per_start_phase": per_start_phase(self.episodes),
            "per_episode": [e.to_dict() for e in self.episodes],
        }


PHASE_SECTOR_DEG = 45


def per_start_phase(episodes: Sequence[EpisodeResult]) -> dict[str, dict[str, Any]]:
    """Score and drop rate by the goal's start phase, in 45-degree sectors ("0-45", ...).

    Empty unless the start phase varies between episodes (stages with random phases, P2's
    random start offsets): a policy's average can hide sectors where it always drops the balls.
    """
    phased = [e for e in episodes if e.start_phase is not None]
    if len({e.start_phase for e in phased}) < 2:
        return {}
    sectors: dict[int, list[EpisodeResult]] = {}
    for e in phased:
        sectors.setdefault(phase_sector(e.start_phase), []).append(e)
    return {sector_name(k): {"episodes": len(members), "score": official_score(members),
                             "drop_rate": drop_rate(members)}
            for k, members in sorted(sectors.items())}


def phase_sector(phase: float) -> int:
    """Index of the 45-degree sector holding a start phase in radians [0, 2 pi)."""
    # min(): a phase that rounds to exactly 2 pi belongs to the last sector
    return min(int(math.degrees(phase) // PHASE_SECTOR_DEG), 360 // PHASE_SECTOR_DEG - 1)


def sector_name(index: int) -> str:
    return f"{index * PHASE_SECTOR_DEG}-{(index + 1) * PHASE_SECTOR_DEG}"


# -- finding checkpoints -----------------------------------------------------------------

def _find_run_dir(path: Path) -> Path | None:
    for folder in (path, path.parent, path.parent.parent):
        if (folder / "config.yaml").is_file() and (folder / CHECKPOINT_DIR).is_dir():
            return folder
    return None


def resolve_checkpoint(target: str | Path, checkpoint_steps: int | None = None,
                       last_checkpoint: bool = False) -> CheckpointRef:
    """The policy a command-line target names.

    A run folder means its final model (or, with ``last_checkpoint``, its newest checkpoint;
    with ``checkpoint_steps``, that checkpoint); a ``.zip`` means that file, with the
    statistics saved beside it under SB3's naming.
    """
    path = Path(target)
    if not path.exists():
        raise EvaluationError(f"{path}: no such run folder or checkpoint")
    if path.is_dir():
        run_dir = _find_run_dir(path)
        if run_dir is None:
            raise EvaluationError(f"{path}: not a run folder (no config.yaml and checkpoints/ inside)")
        folder = run_dir / CHECKPOINT_DIR
        if checkpoint_steps is not None:
            files = checkpoint_files(folder, checkpoint_steps)
            if not files.model.is_file():
                raise EvaluationError(f"{files.model}: no checkpoint at {checkpoint_steps} steps")
            return CheckpointRef(files.model, files.vecnormalize, run_dir)
        final = run_dir / "final_model.zip"
        if final.is_file() and not last_checkpoint:
            return CheckpointRef(final, run_dir / "final_vecnormalize.pkl", run_dir)
        files = latest_checkpoint(run_dir)
        if files is None:
            raise EvaluationError(f"{run_dir}: no final model and no complete checkpoint yet")
        return CheckpointRef(files.model, files.vecnormalize, run_dir)
    if path.suffix != ".zip":
        raise EvaluationError(f"{path}: expected a run folder or a model .zip")
    name = path.name
    if name.startswith("rl_model_") and name.endswith("_steps.zip"):
        stats = path.with_name(name.replace("rl_model_", "rl_model_vecnormalize_").replace(".zip", ".pkl"))
    else:
        stats = path.with_name(name.replace("model", "vecnormalize").replace(".zip", ".pkl"))
    return CheckpointRef(path, stats, _find_run_dir(path.parent))


@dataclass
class LoadedPolicy:
    model: Any
    normalizer: Any  # VecNormalize with frozen statistics, or None

    def act(self, obs: np.ndarray, state, episode_start: bool):
        batch = obs[None]
        if self.normalizer is not None:
            batch = self.normalizer.normalize_obs(batch)
        action, state = self.model.predict(batch, state=state, episode_start=np.array([episode_start]),
                                           deterministic=True)
        return action[0], state


def load_policy(ref: CheckpointRef, task: str) -> LoadedPolicy:
    """Load a model and its statistics (frozen), checking they fit the task's observation."""
    from sb3_contrib import RecurrentPPO

    if not ref.model.is_file():
        raise EvaluationError(f"{ref.model}: checkpoint not found")
    try:
        model = RecurrentPPO.load(ref.model, device="cpu")
    except Exception as error:  # zipfile, pickle and torch errors alike
        raise EvaluationError(f"{ref.model}: cannot load this checkpoint ({type(error).__name__}: {error}); "
                              "it is not a complete RecurrentPPO model archive") from None
    expected = TASKS[task].OBS_SIZE
    shape = model.observation_space.shape
    if shape != (expected,):
        raise EvaluationError(f"{ref.model}: the policy takes observations of shape {shape}, but the "
                              f"{task} env gives ({expected},): it was trained on another task")
    normalizer = None
    if ref.vecnormalize.is_file():
        try:
            with ref.vecnormalize.open("rb") as file:
                normalizer = pickle.load(file)
        except Exception as error:
            raise EvaluationError(f"{ref.vecnormalize}: cannot read normalization statistics ({error})") from None
        normalizer.training = False  # evaluation never updates the statistics
        normalizer.norm_reward = False
    else:
        raise EvaluationError(f"{ref.vecnormalize}: normalization statistics of this checkpoint not found "
                              "(they are saved beside the model under SB3's names)")
    return LoadedPolicy(model, normalizer)


def run_task(ref: CheckpointRef) -> str:
    """The task a checkpoint was trained on: from its run folder, else from its observation size."""
    if ref.run_dir is not None:
        curriculum = yaml.safe_load((ref.run_dir / "curriculum.yaml").read_text())
        return curriculum.get("task", "baoding")
    from stable_baselines3.common.save_util import load_from_zip_file

    try:
        data, _, _ = load_from_zip_file(ref.model, load_data=True, device="cpu")
        shape = data["observation_space"].shape
    except Exception:  # load_policy reports an unreadable checkpoint with a clear message
        return "baoding"
    for name, env_cls in TASKS.items():
        if shape == (env_cls.OBS_SIZE,):
            return name
    return "baoding"


def choose_env(ref: CheckpointRef, name: str, official: bool = False) -> EnvChoice:
    """Parse ``p1``, ``p2`` or ``stage:NAME`` (a stage of the checkpoint's own curriculum)."""
    from curricula.schema import load_curriculum
    from curricula.training import stage_knobs

    task = run_task(ref)
    if name in ("p1", "p2"):
        choice = EnvChoice(task, name, {"preset": name}, official)
    elif name.startswith("stage:"):
        if official:
            raise EvaluationError(f"--env {name}: the official env has only the p1 and p2 tasks")
        if ref.run_dir is None:
            raise EvaluationError(f"--env {name}: {ref.model} is not inside a run folder, so it has no curriculum")
        curriculum = load_curriculum(ref.run_dir / "curriculum.yaml")
        try:
            stage = curriculum.stages[curriculum.stage_index(name[len("stage:"):])]
        except KeyError as error:
            raise EvaluationError(f"--env {name}: {error.args[0]}") from None
        choice = EnvChoice(task, name, stage_knobs(stage), official)
    else:
        raise EvaluationError(f"--env {name!r}: expected p1, p2 or stage:NAME")
    if official and (task, name) not in OFFICIAL_IDS:
        raise EvaluationError(f"no official env for {task} {name}")
    return choice


# -- rollouts ----------------------------------------------------------------------------

def _make_env(choice: EnvChoice, render: bool = False):
    if choice.official:
        import gymnasium as gym

        try:
            import myosuite  # noqa: F401  (registers the official ids)
        except ImportError:
            raise EvaluationError("--official needs the myosuite package: pip install myosuite==3.0.0") from None
        return gym.make(OFFICIAL_IDS[(choice.task, choice.name)])
    return TASKS[choice.task](render_mode="rgb_array" if render else None, **choice.knobs)


def _official_direction(env) -> str | None:
    which = getattr(env.unwrapped, "which_task", None)
    return _OFFICIAL_DIRECTIONS[which.value] if which is not None else None


def run_episode(policy: LoadedPolicy, env, choice: EnvChoice, seed: int, frames: list | None = None) -> EpisodeResult:
    """One deterministic episode; the LSTM state starts fresh. With ``frames``, each step's
    rendered image and whether the step was solved are appended to it."""
    obs, _ = env.reset(seed=seed)
    state, start = None, True
    solved = length = 0
    effort = 0.0
    while True:
        action, state = policy.act(obs, state, start)
        start = False
        obs, _, terminated, truncated, info = env.step(action)
        if frames is not None:
            frames.append((env.render(), bool(info["solved"])))
        length += 1
        solved += int(bool(info["solved"]))
        effort -= float(info["act_reg"])
        if terminated or truncated:
            break
    if not choice.official:
        return info["episode_result"]
    horizon = env.spec.max_episode_steps
    return EpisodeResult(solved_steps=solved, length=length, horizon=horizon, dropped=bool(terminated),
                         effort=effort / length, direction=_official_direction(env), task=choice.task)


def _episodes_worker(args: tuple[CheckpointRef, EnvChoice, list[int]]) -> list[EpisodeResult]:
    import torch

    ref, choice, seeds = args
    torch.set_num_threads(1)  # the same arithmetic whatever the number of workers
    policy = load_policy(ref, choice.task)
    env = _make_env(choice)
    return [run_episode(policy, env, choice, seed) for seed in seeds]


def evaluate(ref: CheckpointRef, choice: EnvChoice, episodes: int, seed: int = 0, workers: int = 1) -> EvaluationReport:
    """Run ``episodes`` deterministic episodes (seeds ``seed .. seed + episodes - 1``)."""
    load_policy(ref, choice.task)  # fail early, in this process, with a clear message
    seeds = [seed + i for i in range(episodes)]
    workers = max(1, min(workers, episodes))
    if workers == 1:
        results = _episodes_worker((ref, choice, seeds))
    else:
        chunks = [seeds[i::workers] for i in range(workers)]
        with multiprocessing.get_context("spawn").Pool(workers) as pool:
            parts = pool.map(_episodes_worker, [(ref, choice, chunk) for chunk in chunks])
        by_seed = {s: r for chunk, part in zip(chunks, parts) for s, r in zip(chunk, part)}
        results = [by_seed[s] for s in seeds]
    return EvaluationReport(ref, choice, seed, results)


def chosen_episodes(report: EvaluationReport, count: int) -> list[tuple[int, str]]:
    """Seeds and captions of the evaluation's best and worst episodes (by score, then length),
    best first: ``count`` episodes, half of them the best ones."""
    episodes = report.episodes
    order = sorted(range(len(episodes)), key=lambda i: (episodes[i].score, episodes[i].length))
    best = order[::-1][: count - count // 2]
    worst = [i for i in order if i not in best][: count // 2]
    total = len(episodes)
    picks = [(i, f"best of {total}") for i in best] + [(i, f"worst of {total}") for i in worst[::-1]]
    return [(report.seed + i, caption) for i, caption in picks]


VIDEO_FPS = 40  # the control rate of the Baoding env: real time
HOLD_LAST_FRAME_S = 2.0  # each episode's last frame stays this long, with its result


def _overlay(frame: np.ndarray, lines: list[str]) -> np.ndarray:
    from PIL import Image, ImageDraw, ImageFont

    image = Image.fromarray(frame)
    draw = ImageDraw.Draw(image)
    try:
        font = ImageFont.load_default(size=18)
    except TypeError:  # Pillow < 10.1 has one bitmap size
        font = ImageFont.load_default()
    y = 8
    for line in lines:
        draw.text((10, y), line, fill=(255, 255, 255), font=font, stroke_width=2, stroke_fill=(0, 0, 0))
        y += 24
    return np.asarray(image)


def record_video(ref: CheckpointRef, choice: EnvChoice, path: Path, episodes: list[tuple[int, str]]) -> int:
    """Render the given ``(seed, caption)`` episodes of our env to an MP4 at real time, with an
    overlay (caption, step, solved, score so far); each episode's last frame is held for
    :data:`HOLD_LAST_FRAME_S` with its result. Returns the frame count."""
    import imageio

    policy = load_policy(ref, choice.task)
    env = _make_env(EnvChoice(choice.task, choice.name, choice.knobs, official=False), render=True)
    frames: list[np.ndarray] = []
    for number, (seed, caption) in enumerate(episodes, start=1):
        steps: list[tuple[np.ndarray, bool]] = []
        result = run_episode(policy, env, choice, seed, steps)
        solved = 0
        title = f"episode {number}/{len(episodes)}: {caption} (seed {seed})"
        for step, (image, solved_now) in enumerate(steps, start=1):
            solved += solved_now
            frames.append(_overlay(image, [title, f"step {step}/{result.horizon}",
                                           f"solved: {'yes' if solved_now else 'no'}",
                                           f"score so far {solved / result.horizon:.3f}"]))
        ending = f"balls dropped at step {result.length}" if result.dropped else "episode complete"
        last = _overlay(steps[-1][0], [title, ending, f"score {result.score:.3f}"])
        frames += [last] * int(HOLD_LAST_FRAME_S * VIDEO_FPS)
    env.close()
    path.parent.mkdir(parents=True, exist_ok=True)
    imageio.mimwrite(path, frames, fps=VIDEO_FPS, codec="libx264", quality=7, macro_block_size=16)
    return len(frames)


# -- plots -------------------------------------------------------------------------------

def trailing_mean(values: np.ndarray, window: int) -> np.ndarray:
    """Mean of the last ``window`` values at each point (fewer at the start)."""
    sums = np.cumsum(np.insert(np.asarray(values, dtype=float), 0, 0.0))
    index = np.arange(1, len(values) + 1)
    start = np.maximum(index - window, 0)
    return (sums[index] - sums[start]) / (index - start)


def plot_learning_curve(run_dir: Path, path: Path, window: int = 50) -> None:
    """Score and survival of training episodes against env steps, stage changes marked; below,
    when the goal's start phase varies, the score of each 45-degree start-phase sector."""
    import csv
    import json

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    episodes_file = run_dir / EPISODES_FILE
    if not episodes_file.is_file():
        raise EvaluationError(f"{run_dir}: no {EPISODES_FILE} to plot a learning curve from")
    with episodes_file.open(newline="") as file:
        rows = list(csv.DictReader(file))
    steps = np.array([int(r["step"]) for r in rows])
    scores = np.array([float(r["score"]) for r in rows])
    survival = 1.0 - np.array([int(r["dropped"]) for r in rows])
    # Runs begun before start phases were logged have no such column.
    phases = [r.get("start_phase") or "" for r in rows]
    by_phase = len({p for p in phases if p}) > 1
    fig, axes = plt.subplots(2 if by_phase else 1, 1, figsize=(9, 8 if by_phase else 4.5), sharex=True, squeeze=False)
    ax = axes[0, 0]
    if len(rows):
        ax.plot(steps, trailing_mean(scores, window), color="C0", label=f"score (mean of last {window} episodes)")
    state_file = run_dir / STATE_FILE
    history = json.loads(state_file.read_text()).get("history", []) if state_file.is_file() else []
    for entry in history:
        ax.axvline(entry["at_step"], color="gray", linestyle="--", linewidth=1)
        ax.text(entry["at_step"], 0.98, f" {entry['stage']} {entry['decision']}", rotation=90,
                va="top", ha="right", fontsize=7, transform=ax.get_xaxis_transform())
    # Each stage's threshold over the steps it ran (the current stage's up to the last episode).
    thresholds = _stage_thresholds(run_dir, history, int(steps[-1]) if len(rows) else 0)
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
        sectors = np.array([phase_sector(float(p)) if p else -1 for p in phases])
        below = axes[1, 0]
        for k in sorted(set(sectors[sectors >= 0].tolist())):
            chosen = sectors == k
            below.plot(steps[chosen], trailing_mean(scores[chosen], window), linewidth=1,
                       color=plt.get_cmap("tab10")(k), label=f"{sector_name(k)} deg")
        for entry in history:
            below.axvline(entry["at_step"], color="gray", linestyle="--", linewidth=1)
        below.set_ylabel(f"score by start phase\n(last {window} episodes of each)")
        below.set_ylim(0, ax.get_ylim()[1])
        below.legend(loc="upper left", ncol=4, fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _stage_thresholds(run_dir: Path, history: list[dict[str, Any]], last_step: int) -> list[tuple[int, int, float]]:
    """``(first step, last step, threshold)`` of each stage the run has been in that has one."""
    from curricula.schema import ConfigError, load_curriculum

    try:
        stages = load_curriculum(run_dir / "curriculum.yaml").stages
    except ConfigError:
        return []
    bounds = [0] + [entry["at_step"] for entry in history]
    reached = len(history) + 1 if len(history) < len(stages) else len(history)
    spans = []
    for index in range(min(reached, len(stages))):
        rule = stages[index].advance
        end = bounds[index + 1] if index + 1 < len(bounds) else max(last_step, bounds[index])
        if rule is not None:
            spans.append((bounds[index], end, rule.threshold))
    return spans


def plot_score_histogram(reports: Sequence[EvaluationReport], path: Path) -> None:
    """Episode scores of each report, as outlines over bins fitted to the data, each mean marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    scores = [np.array([e.score for e in report.episodes]) for report in reports]
    top = max([0.01] + [float(s.max()) for s in scores if len(s)])
    bins = np.linspace(0, top * 1.05, 21)
    colors = plt.get_cmap("tab10")
    for index, (report, values) in enumerate(zip(reports, scores)):
        color = colors(index % 10)
        # Earlier series drawn wider, so a later one with the same counts leaves them visible.
        ax.hist(values, bins=bins, histtype="step", linewidth=1.5 + 2.0 * (len(reports) - 1 - index), color=color,
                label=f"{report.checkpoint.label} on {report.env.label} (mean {values.mean():.3f})")
        ax.axvline(values.mean(), color=color, linestyle="--", linewidth=1)
    ax.set_xlabel("episode score (solved steps / horizon)")
    ax.set_ylabel("episodes")
    ax.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def format_table(reports: Sequence[EvaluationReport]) -> str:
    """Side-by-side table, one column per (checkpoint, env)."""
    summaries = [r.summary() for r in reports]
    columns = [f"{r.checkpoint.label} | {r.env.label}" for r in reports]
    directions = sorted({d for s in summaries for d in s["per_direction"]})
    rows = [("episodes", [str(s["episodes"]) for s in summaries]),
            ("score", [f"{s['score']:.3f} [{s['score_ci95'][0]:.3f}, {s['score_ci95'][1]:.3f}]" for s in summaries]),
            ("effort", [f"{s['effort']:.4f}" for s in summaries]),
            ("drop rate", [f"{s['drop_rate']:.3f}" for s in summaries]),
            ("mean length", [f"{s['mean_length']:.1f}" for s in summaries])]

    def breakdown(key: str, group: str, text: Callable[[dict], str]) -> list[str]:
        return [text(s[key][group]) if group in s[key] else "-" for s in summaries]

    for direction in directions:
        rows.append((f"score {direction}",
                     breakdown("per_direction", direction, lambda d: f"{d['score']:.3f} (n={d['episodes']})")))
    sectors = sorted({k for s in summaries for k in s["per_start_phase"]}, key=lambda k: int(k.split("-")[0]))
    for sector in sectors:
        rows.append((f"score, start {sector} deg", breakdown(
            "per_start_phase", sector, lambda d: f"{d['score']:.3f} (n={d['episodes']}, drops {d['drop_rate']:.0%})")))
    width = max(len(name) for name, _ in rows)
    col_width = [max(len(c), *(len(cells[i]) for _, cells in rows)) for i, c in enumerate(columns)]
    lines = [" " * width + "  " + "  ".join(c.ljust(w) for c, w in zip(columns, col_width))]
    lines += [name.ljust(width) + "  " + "  ".join(v.ljust(w) for v, w in zip(cells, col_width)) for name, cells in rows]
    return "\n".join(lines)
