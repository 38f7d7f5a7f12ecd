"""Env steps per second: our env, the official myosuite env, and bare ``mj_step`` physics.

Each contender runs the same number of control steps with the same random actions on one
core, resetting whenever an episode ends, in interleaved rounds (so that a noisy neighbour
on the machine slows all of them alike); the best round of each is reported.

    python benchmarks/env_speed.py [--steps 3000] [--rounds 3] [--task baoding] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

import mujoco
import numpy as np

from envs.baoding import FRAME_SKIP, BaodingEnv

OFFICIAL_IDS = {"p1": "myoChallengeBaodingP1-v1", "p2": "myoChallengeBaodingP2-v1"}


def _env_loop(env, actions: np.ndarray) -> Callable[[], None]:
    def run() -> None:
        env.reset(seed=0)
        for action in actions:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
    return run


def _bare_loop(actions: np.ndarray) -> Callable[[], None]:
    """The physics floor: ``FRAME_SKIP`` substeps per control step, no observation or reward."""
    model = BaodingEnv().model
    data = mujoco.MjData(model)

    def run() -> None:
        mujoco.mj_resetData(model, data)
        for action in actions:
            data.ctrl[:] = 1.0 / (1.0 + np.exp(-5.0 * (action - 0.5)))
            mujoco.mj_step(model, data, FRAME_SKIP)
    return run


def measure(steps: int = 3000, rounds: int = 3, preset: str = "p1") -> dict[str, float]:
    """Best-of-``rounds`` control steps per second for each available contender."""
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, 39)).astype(np.float32)
    contenders = {"ours": _env_loop(BaodingEnv(preset), actions), "bare_mj_step": _bare_loop(actions)}
    try:
        import gymnasium as gym
        import myosuite  # noqa: F401  (registers the official ids)

        contenders["official"] = _env_loop(gym.make(OFFICIAL_IDS[preset]).unwrapped, actions)
    except ImportError:
        pass
    best = {name: 0.0 for name in contenders}
    for _ in range(rounds):
        for name, run in contenders.items():
            start = time.perf_counter()
            run()
            best[name] = max(best[name], steps / (time.perf_counter() - start))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--preset", choices=sorted(OFFICIAL_IDS), default="p1")
    parser.add_argument("--json", help="also write the results to this file")
    args = parser.parse_args()
    rates = measure(args.steps, args.rounds, args.preset)
    result = {"preset": args.preset, "steps_per_s": rates}
    for name in ("official", "bare_mj_step"):
        if name in rates:
            result[f"ours/{name}"] = rates["ours"] / rates[name]
    for name, rate in rates.items():
        print(f"{name:>14}: {rate:8.0f} env steps/s")
    for key, value in result.items():
        if key.startswith("ours/"):
            print(f"{key:>22}: {value:.3f}x")
    if args.json:
        with open(args.json, "w") as file:
            json.dump(result, file, indent=2)


if __name__ == "__main__":
    main()
