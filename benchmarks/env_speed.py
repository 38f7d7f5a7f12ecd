"""Env steps per second: our env, the official myosuite env, and bare ``mj_step`` physics.

Each contender runs the same number of control steps with the same random actions on one
core, in interleaved rounds (so that a noisy neighbour on the machine slows all of them
alike); the best round of each is reported. The envs reset whenever an episode ends; the bare
loop resets its state to the env's initial state at the same steps, so that it simulates the
same mix of in-hand contact and free fall. ``bare_mj_step`` never resets (after a drop it
times a ball or die falling freely); ``bare_mj_step_same_resets`` is the stricter floor.

    python benchmarks/env_speed.py [--task baoding|die] [--preset p1|p2] [--steps 3000] [--rounds 3] [--json FILE]
"""

from __future__ import annotations

from myo_sds import set_process_environment

set_process_environment()  # before NumPy, torch and MuJoCo load: pinned kernels, short OpenMP spins

import argparse
import json
import time
from collections.abc import Callable

import mujoco
import numpy as np

from myo_sds.envs import TASKS
from myo_sds.envs.task_specs import TASK_SPECS


def _env_loop(env, actions: np.ndarray, episode_ends: list[int] | None = None) -> Callable[[], None]:
    def run() -> None:
        env.reset(seed=0)
        for index, action in enumerate(actions):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                if episode_ends is not None:
                    episode_ends.append(index)
                env.reset()
    return run


def _bare_loop(env, actions: np.ndarray, episode_ends: list[int]) -> Callable[[], None]:
    """The physics floor: ``FRAME_SKIP`` substeps per control step, no observation or reward;
    the state goes back to the env's initial state after each step in ``episode_ends``."""
    model, frame_skip = env.model, env.FRAME_SKIP
    data = mujoco.MjData(model)
    ends = set(episode_ends)

    def start() -> None:
        mujoco.mj_resetData(model, data)
        data.qpos[:] = env._init_qpos

    def run() -> None:
        start()
        for index, action in enumerate(actions):
            data.ctrl[:] = 1.0 / (1.0 + np.exp(-5.0 * (action - 0.5)))
            mujoco.mj_step(model, data, frame_skip)
            if index in ends:
                start()
    return run


def measure(steps: int = 3000, rounds: int = 3, preset: str = "p1", task: str = "baoding") -> dict[str, float]:
    """Best-of-``rounds`` control steps per second for each available contender."""
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, 39)).astype(np.float32)
    ours = TASKS[task](preset)
    episode_ends: list[int] = []
    _env_loop(ours, actions, episode_ends)()  # where episodes end, for the bare loop
    contenders = {"ours": _env_loop(ours, actions),
                  "bare_mj_step": _bare_loop(TASKS[task](preset), actions, []),
                  "bare_mj_step_same_resets": _bare_loop(TASKS[task](preset), actions, episode_ends)}
    try:
        import gymnasium as gym
        import myosuite  # noqa: F401  (registers the official ids)

        contenders["official"] = _env_loop(gym.make(TASK_SPECS[task].official_ids[preset]).unwrapped, actions)
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
    parser.add_argument("--task", choices=sorted(TASKS), default="baoding")
    parser.add_argument("--preset", choices=("p1", "p2"), default="p1")
    parser.add_argument("--json", help="also write the results to this file")
    args = parser.parse_args()
    rates = measure(args.steps, args.rounds, args.preset, args.task)
    result = {"task": args.task, "preset": args.preset, "steps_per_s": rates}
    for name in ("official", "bare_mj_step", "bare_mj_step_same_resets"):
        if name in rates:
            result[f"ours/{name}"] = rates["ours"] / rates[name]
    for name, rate in rates.items():
        print(f"{name:>26}: {rate:8.0f} env steps/s")
    for key, value in result.items():
        if key.startswith("ours/"):
            print(f"{key:>31}: {value:.3f}x")
    if args.json:
        with open(args.json, "w") as file:
            json.dump(result, file, indent=2)


if __name__ == "__main__":
    main()
