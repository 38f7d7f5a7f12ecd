"""Whether a die policy turns the die toward its goal: where a die stage stalls.

Deterministic episodes on our env. For each, the orientation error (the norm of the Euler-angle
differences, as the score measures it) at the start, its smallest value during the episode and
at the end, the position error at the end, solved steps and whether the die fell; then the same
grouped by the start's error in 15-degree bins. A policy that only holds the die shows a smallest
error equal to the start's; one that turns it, a smallest error below it. The step at which the
smallest error came (median) and the error at ``--at-step`` (e.g. a stage's training horizon)
say whether the turn stops there.

    python experiments/die_turns.py ~/runs/die_p1-s0 --load-checkpoint 3000000 --env stage:rotate-30deg
"""

from __future__ import annotations

from myo_sds import set_process_environment

set_process_environment()  # before NumPy, torch and MuJoCo load: pinned kernels, short OpenMP spins

import argparse
import math

import numpy as np

from myo_sds.evaluation.checkpoints import choose_env, load_policy, resolve_checkpoint
from myo_sds.evaluation.episodes import make_env

BIN_DEG = 15


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
    rows = []
    for episode in range(args.episodes):
        obs, _ = env.reset(seed=args.seed + episode)
        start_error = float(np.linalg.norm(obs[60:63]))
        errors, state, start = [start_error], None, True
        while True:
            action, state = policy.act(obs, state, start)
            start = False
            obs, _, terminated, truncated, info = env.step(action)
            errors.append(-info["rot_dist"])
            if terminated or truncated:
                break
        result = info["episode_result"]
        rows.append((start_error, min(errors), -info["rot_dist"], -info["pos_dist"], result.solved_steps,
                     result.dropped, result.score, int(np.argmin(errors)), errors[min(args.at_step, len(errors) - 1)]))
    data = np.array(rows, dtype=float)
    print(f"{len(rows)} episodes of {ref.label} on {choice.label}: score {data[:, 6].mean():.3f}, "
          f"dropped {data[:, 5].mean():.0%}")
    print(f"{'start error, deg':>17} {'episodes':>8} {'score':>6} {'mean start':>10} {'smallest error':>14} "
          f"{'at step (median)':>16} {f'at step {args.at_step}':>11} {'end error':>9} {'end position, cm':>16} "
          f"{'solved steps':>12}")
    bins = np.floor(np.degrees(data[:, 0]) / BIN_DEG).astype(int)
    for k in sorted(set(bins.tolist())):
        group = data[bins == k]
        print(f"{f'{k * BIN_DEG}-{(k + 1) * BIN_DEG}':>17} {len(group):>8} {group[:, 6].mean():>6.2f} "
              f"{math.degrees(group[:, 0].mean()):>8.1f}dg {math.degrees(group[:, 1].mean()):>12.1f}dg "
              f"{np.median(group[:, 7]):>16.0f} {math.degrees(group[:, 8].mean()):>9.1f}dg {math.degrees(group[:, 2].mean()):>7.1f}dg "
              f"{100 * group[:, 3].mean():>16.2f} {group[:, 4].mean():>12.1f}")


if __name__ == "__main__":
    main()
