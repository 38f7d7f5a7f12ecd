"""Seconds per stage evaluation: its episodes one at a time against run together.

A stage evaluation (``evaluate`` in a curriculum) plays N deterministic episodes every few tens of
thousands of env steps while the training's envs and update wait. One at a time, each step is one
env step and one batch-1 forward pass on one core; together (``run_episodes_together``, what the
trainer runs), each step is one batched forward pass and the N envs stepped on every CPU. Both on
the same policy, env and seeds, in interleaved rounds; the best round of each is reported, with
the mean episode return of each (the same episodes up to the batched arithmetic's last bits).

    python benchmarks/stage_evaluation_speed.py [--model models/baoding_p1_2022] [--env p1_2022]
        [--start-noise 0.02] [--episodes 20] [--rounds 3]
"""

from __future__ import annotations

from myo_sds import set_process_environment

set_process_environment()  # before NumPy, torch and MuJoCo load

import argparse
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import torch

from myo_sds import evaluation as ev
from myo_sds.evaluation.episodes import make_env, run_episode, run_episodes_together
from myo_sds.threads import available_cpus


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", default="models/baoding_p1_2022")
    parser.add_argument("--env", default="p1_2022")
    parser.add_argument("--start-noise", type=float, default=0.02)
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()

    torch.set_num_threads(1)  # as the trainer's stage evaluation runs
    ref = ev.resolve_checkpoint(args.model)
    choice = ev.choose_env(ref, args.env, start_noise=args.start_noise)
    policy = ev.load_policy(ref, choice.task)
    seeds = range(args.episodes)
    one_env, envs = make_env(choice), [make_env(choice) for _ in seeds]
    timings: dict[str, list[float]] = {"one at a time": [], "together": []}
    returns: dict[str, float] = {}
    with ThreadPoolExecutor(available_cpus()) as pool:
        for _ in range(args.rounds):
            start = time.perf_counter()
            alone = [run_episode(policy, one_env, choice, seed) for seed in seeds]
            timings["one at a time"].append(time.perf_counter() - start)
            start = time.perf_counter()
            together = run_episodes_together(policy, envs, choice, seeds, pool if available_cpus() > 1 else None)
            timings["together"].append(time.perf_counter() - start)
    returns["one at a time"] = float(np.mean([e.reward for e in alone]))
    returns["together"] = float(np.mean([e.reward for e in together]))
    steps = sum(e.length for e in alone)
    print(f"{args.model} on {args.env} (start noise {args.start_noise}), {args.episodes} episodes, "
          f"{steps} env steps, {available_cpus()} CPUs; best of {args.rounds} rounds:")
    for name, seconds in timings.items():
        print(f"  {name:<14} {min(seconds):6.2f} s  mean return {returns[name]:.2f}")
    print(f"  speed-up {min(timings['one at a time']) / min(timings['together']):.2f}x")


if __name__ == "__main__":
    main()
