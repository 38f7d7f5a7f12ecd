"""A video of chosen evaluation episodes, replayed on our env with an overlay."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from myo_sds.evaluation.checkpoints import CheckpointRef, EnvChoice, load_policy
from myo_sds.evaluation.episodes import EvaluationReport, make_env, run_episode


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


@functools.lru_cache(maxsize=1)
def _font():
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=18)
    except TypeError:  # Pillow < 10.1 has one bitmap size
        return ImageFont.load_default()


def _overlay(frame: np.ndarray, lines: list[str]) -> np.ndarray:
    from PIL import Image, ImageDraw

    image = Image.fromarray(frame)
    draw = ImageDraw.Draw(image)
    font = _font()
    y = 8
    for line in lines:
        draw.text((10, y), line, fill=(255, 255, 255), font=font, stroke_width=2, stroke_fill=(0, 0, 0))
        y += 24
    return np.asarray(image)


def record_video(ref: CheckpointRef, choice: EnvChoice, path: Path, episodes: list[tuple[int, str]]) -> int:
    """Render the given ``(seed, caption)`` episodes of our env to an MP4 at real time, with an
    overlay (the policy and task, caption, step, solved, score so far); each episode's last frame is held for
    :data:`HOLD_LAST_FRAME_S` with its result. Returns the frame count."""
    import imageio

    policy = load_policy(ref, choice.task)
    env = make_env(EnvChoice(choice.task, choice.name, choice.distribution, official=False), render=True)
    frames: list[np.ndarray] = []
    who = f"{ref.label} on {choice.label}"  # which policy, on which task
    for number, (seed, caption) in enumerate(episodes, start=1):
        steps: list[tuple[np.ndarray, bool]] = []
        result = run_episode(policy, env, choice, seed, steps)
        solved = 0
        title = f"episode {number}/{len(episodes)}: {caption} (seed {seed})"
        for step, (image, solved_now) in enumerate(steps, start=1):
            solved += solved_now
            frames.append(_overlay(image, [who, title, f"step {step}/{result.horizon}",
                                           f"solved: {'yes' if solved_now else 'no'}",
                                           f"score so far {solved / result.horizon:.3f}"]))
        ending = f"balls dropped at step {result.length}" if result.dropped else "episode complete"
        last = _overlay(steps[-1][0], [who, title, ending, f"score {result.score:.3f}"])
        frames += [last] * int(HOLD_LAST_FRAME_S * VIDEO_FPS)
    env.close()
    path.parent.mkdir(parents=True, exist_ok=True)
    imageio.mimwrite(path, frames, fps=VIDEO_FPS, codec="libx264", quality=7, macro_block_size=16)
    return len(frames)


