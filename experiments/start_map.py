"""Where a Baoding policy can start turning the balls: solved steps and drops by start angle.

Deterministic episodes on our env from a stage's knobs (default: the chain's `fixed-10s`, the
2022 placement), with the targets starting at each of ``--angles`` (degrees on the orbit), in each
of ``--directions``, at ``--period`` s per revolution, the balls placed on the targets (``--rsi 1``)
or at rest (``--rsi 0``), each hand joint moved by up to ``--start-noise`` rad at reset. A dead
zone shows as a few starts with low solved steps and high drops between good ones; the default
angles cover the whole circle, where forgetting shows.

    python experiments/start_map.py ~/runs/baoding_sds-s0/stages/02_rotate-30s.zip --directions ccw cw \\
        --angles 90 112 127 135 143 157 180 --period 30 --rsi 1 0
"""

from __future__ import annotations

from myo_sds import set_process_environment

set_process_environment()  # before NumPy, torch and MuJoCo load: pinned kernels, short OpenMP spins

import argparse
import dataclasses
import math
import statistics

from myo_sds.envs.knobs import Range
from myo_sds.evaluation.checkpoints import choose_env, load_policy, resolve_checkpoint
from myo_sds.evaluation.episodes import make_env, run_episodes_together


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("policy", help="a model folder, run folder or checkpoint .zip")
    parser.add_argument("--env", default="stage:fixed-10s", help="the knobs to start from (a preset or stage:NAME)")
    parser.add_argument("--directions", nargs="+", default=["ccw", "cw"], choices=["ccw", "cw", "hold"])
    # The whole circle by default: a stage that trains a few starts can wear the others away.
    parser.add_argument("--angles", nargs="+", type=float, default=[0, 45, 90, 135, 180, 225, 270, 315])
    parser.add_argument("--period", type=float, default=30.0)
    parser.add_argument("--rsi", nargs="+", type=float, default=[1.0, 0.0],
                        help="1: the balls placed on the targets; 0: at rest")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--start-noise", type=float, default=0.02)
    args = parser.parse_args()

    ref = resolve_checkpoint(args.policy)
    policy = load_policy(ref, "baoding")
    base = choose_env(ref, args.env)
    print(f"{args.policy}: {args.episodes} episodes per start, period {args.period:g} s, start noise {args.start_noise}")
    print(f"{'start':<18}" + "".join(f"{a:>12g}" for a in args.angles) + "   (degrees; median solved steps / dropped)")
    envs = [make_env(dataclasses.replace(base, start_noise=args.start_noise)) for _ in range(args.episodes)]
    try:
        for rsi in args.rsi:
            for direction in args.directions:
                cells = []
                for angle in args.angles:
                    knobs = dataclasses.replace(base.distribution, direction=direction,
                                                period=Range(args.period, args.period), rsi_probability=rsi,
                                                start_angle=math.radians(angle), start_offset=None)
                    choice = dataclasses.replace(base, distribution=knobs, start_noise=args.start_noise)
                    for env in envs:
                        env.unwrapped.configure(distribution=knobs)
                    results = run_episodes_together(policy, envs, choice, range(args.episodes))
                    solved = statistics.median(r.solved_steps for r in results)
                    dropped = statistics.mean(r.dropped for r in results)
                    cells.append(f"{solved:5.0f} /{dropped:4.0%}")
                label = f"{'on targets' if rsi == 1 else 'at rest' if rsi == 0 else f'rsi {rsi:g}'} {direction}"
                print(f"{label:<18}" + "".join(f"{c:>12}" for c in cells), flush=True)
    finally:
        for env in envs:
            env.close()


if __name__ == "__main__":
    main()
