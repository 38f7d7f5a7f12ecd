"""Whether a die policy turns the die toward its goal: where a die stage stalls.

Deterministic episodes on our env. For each, the orientation error (the norm of the Euler-angle
differences, as the score measures it) at the start, its smallest value during the episode and
at the end, the position error at the end, solved steps and whether the die fell; then the same
grouped by the start's error in 15-degree bins. A policy that only holds the die shows a smallest
error equal to the start's; one that turns it, a smallest error below it. The step at which the
smallest error came (median) and the error at ``--at-step`` (e.g. a stage's training horizon)
say whether the turn stops there. Each episode's turn is also cut into strokes (``strokes``):
how many separate turns toward the goal it made, and when the second began (a regrasp).

    python experiments/die_turns.py ~/runs/die_p1-s0 --load-checkpoint 3000000 --env stage:rotate-30deg

``experiments/die_yardstick.py`` plays PKU-MARL's 2022 policy through the same trace.
"""

from __future__ import annotations

from myo_sds import set_process_environment

set_process_environment()  # before NumPy, torch and MuJoCo load: pinned kernels, short OpenMP spins

import argparse
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from myo_sds.evaluation.checkpoints import choose_env, load_policy, resolve_checkpoint
from myo_sds.evaluation.episodes import make_env

BIN_DEG = 15
# A stroke: a run of steps over which the orientation error (smoothed over 5 steps) falls by at
# least STROKE_RATE per step, gaps of up to STROKE_GAP steps allowed, falling STROKE_MIN in all.
STROKE_RATE = math.radians(0.3)
STROKE_GAP = 3
STROKE_MIN = math.radians(8.0)


@dataclass(frozen=True)
class TurnRecord:
    """One episode's turn: errors in rad, position in m, steps counted from 0."""

    start_error: float
    smallest_error: float
    end_error: float
    end_position: float
    solved_steps: int
    dropped: bool
    score: float
    smallest_at: int
    error_at_step: float
    strokes: int
    second_stroke_at: int | None  # the step the second stroke began (a regrasp), if any


def strokes(errors: Sequence[float]) -> list[tuple[int, int]]:
    """(first step, last step) of each stroke of an episode's orientation errors."""
    series = np.asarray(errors, dtype=float)
    if len(series) < 3:
        return []
    smooth = np.convolve(np.pad(series, 2, mode="edge"), np.ones(5) / 5, mode="valid")
    turning = np.flatnonzero(np.diff(smooth) < -STROKE_RATE) + 1
    if not len(turning):
        return []
    runs = np.split(turning, np.flatnonzero(np.diff(turning) > STROKE_GAP + 1) + 1)
    return [(int(run[0]), int(run[-1])) for run in runs if smooth[max(run[0] - 1, 0)] - smooth[run[-1]] >= STROKE_MIN]


def turn_record(env, act: Callable, seed: int, at_step: int) -> TurnRecord:
    """Play one episode with ``act(obs, state, episode_start) -> (action, state)`` on a die env,
    ours or MyoSuite's (errors are read from the observation: the same layout on both)."""
    obs, _ = env.reset(seed=seed)
    errors, state, start, solved, dropped = [float(np.linalg.norm(obs[60:63]))], None, True, 0, False
    while True:
        action, state = act(obs, state, start)
        start = False
        obs, _, terminated, truncated, info = env.step(action)
        errors.append(float(np.linalg.norm(obs[60:63])))
        solved += int(bool(info["solved"]))
        if terminated or truncated:
            dropped = bool(terminated)
            break
    cuts = strokes(errors)
    return TurnRecord(errors[0], min(errors), errors[-1], float(np.linalg.norm(obs[51:54])), solved, dropped,
                      float(solved > 5), int(np.argmin(errors)), errors[min(at_step, len(errors) - 1)],
                      len(cuts), cuts[1][0] if len(cuts) > 1 else None)


def print_turn_table(rows: Sequence[TurnRecord], at_step: int) -> None:
    """The episodes grouped by the start's orientation error in 15-degree bins."""
    print(f"{'start error, deg':>17} {'episodes':>8} {'score':>6} {'mean start':>10} {'smallest error':>14} "
          f"{'at step (median)':>16} {f'at step {at_step}':>11} {'end error':>9} {'end position, cm':>16} "
          f"{'solved steps':>12} {'strokes':>7} {'2nd at':>6}")
    bins = np.floor(np.degrees([r.start_error for r in rows]) / BIN_DEG).astype(int)
    for k in sorted(set(bins.tolist())):
        group = [r for r, b in zip(rows, bins) if b == k]
        mean = lambda field: float(np.mean([getattr(r, field) for r in group]))  # noqa: E731
        second = [r.second_stroke_at for r in group if r.second_stroke_at is not None]
        print(f"{f'{k * BIN_DEG}-{(k + 1) * BIN_DEG}':>17} {len(group):>8} {mean('score'):>6.2f} "
              f"{math.degrees(mean('start_error')):>8.1f}dg {math.degrees(mean('smallest_error')):>12.1f}dg "
              f"{np.median([r.smallest_at for r in group]):>16.0f} {math.degrees(mean('error_at_step')):>9.1f}dg "
              f"{math.degrees(mean('end_error')):>7.1f}dg {100 * mean('end_position'):>16.2f} {mean('solved_steps'):>12.1f} "
              f"{mean('strokes'):>7.2f} {(f'{np.median(second):.0f}' if second else '-'):>6}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("policy", help="a model folder, run folder or checkpoint .zip")
    parser.add_argument("--env", default="p1", help="a preset (p1, p2) or stage:NAME")
    parser.add_argument("--load-checkpoint", type=int, default=None)
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--seed", type=int, default=0, help="episode i is reset with seed + i")
    parser.add_argument("--at-step", type=int, default=64, help="also report the error at this step")
    args = parser.parse_args()

    ref = resolve_checkpoint(args.policy, args.load_checkpoint)
    choice = choose_env(ref, args.env)
    if choice.task != "die":
        parser.error(f"{args.policy}: a {choice.task} policy; this script reads die episodes")
    policy = load_policy(ref, choice.task)
    env = make_env(choice)
    rows = [turn_record(env, policy.act, args.seed + episode, args.at_step) for episode in range(args.episodes)]
    print(f"{len(rows)} episodes of {ref.label} on {choice.label}: score {np.mean([r.score for r in rows]):.3f}, "
          f"dropped {np.mean([r.dropped for r in rows]):.0%}")
    print_turn_table(rows, args.at_step)


if __name__ == "__main__":
    main()
