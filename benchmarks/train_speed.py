"""Training throughput: ours against the 2022 winner's setup and the bare-physics ceiling.

    python benchmarks/train_speed.py [--steps 8192] [--config configs/baoding_sds.yaml] [--json FILE]
    python benchmarks/train_speed.py --config configs/baoding_p1_2022.yaml --reference-from-config

- reference: the winner's setup: myosuite's official Baoding P1 env in a SubprocVecEnv with one
  env per core, sb3-contrib RecurrentPPO with the stock MlpLstmPolicy and the winner's phase-2
  hyper-parameters (shared by ``PpoConfig`` / ``PolicyConfig`` defaults); with
  ``--reference-from-config``, stock sb3-contrib on the same recipe as ours (the config's
  network, PPO settings and number of envs, one SubprocVecEnv process per env, as the 2022
  phase-1 policy was trained);
- ours: ``train.py``'s default Baoding config, on its first curriculum stage;
- ceiling: bare ``mj_step`` physics of the config's task (its substeps per env step: Baoding 10,
  the die 5) in one process per core.

Each training run is timed after a first warm-up rollout; wall time is split into env
stepping, policy inference (rest of the rollout) and the PPO update.
"""

from __future__ import annotations

from myo_sds import set_process_environment

set_process_environment()  # before NumPy, torch and MuJoCo load: pinned kernels, short OpenMP spins

import argparse
import json
import multiprocessing
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def _timed_learn(model, venv_inner, steps: int) -> dict[str, float]:
    """Run the reference's plain ``learn`` for ``steps`` env steps (after one warm-up rollout)
    and split its time; the model is not saved, so its ``train`` can be wrapped."""
    from myo_sds.training.rollout import WallClock

    rollout = model.n_steps * model.n_envs
    model.learn(rollout, reset_num_timesteps=False)  # warm-up: process start, first allocations
    env_timer, update_timer = WallClock(), WallClock()
    venv_inner.step_wait = env_timer.wrap(venv_inner.step_wait)
    venv_inner.step_async = env_timer.wrap(venv_inner.step_async)
    model.train = update_timer.wrap(model.train)
    start_steps, start = model.num_timesteps, time.perf_counter()
    model.learn(steps, reset_num_timesteps=False)
    wall = time.perf_counter() - start
    done = model.num_timesteps - start_steps
    return {"env_steps": done, "wall_s": wall, "steps_per_s": done / wall,
            "env_stepping_share": env_timer.seconds / wall, "update_share": update_timer.seconds / wall,
            "inference_and_other_share": 1 - (env_timer.seconds + update_timer.seconds) / wall}


def _official_env():
    import gymnasium as gym
    import myosuite  # noqa: F401

    return gym.make("myoChallengeBaodingP1-v1")


def run_reference(steps: int, n_envs: int, config: Path | None = None) -> dict[str, float]:
    """Stock sb3-contrib on the official env: the winner's phase-2 settings with ``n_envs``
    envs, or (``config``) that run config's policy, PPO settings and envs."""
    import torch
    from sb3_contrib import RecurrentPPO
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

    from myo_sds.curricula.run_settings import PolicyConfig, PpoConfig

    policy, ppo = PolicyConfig(), PpoConfig()
    if config is not None:
        from myo_sds.curricula.run_config import load_run_config

        run = load_run_config(config)
        policy, ppo, n_envs = run.policy, run.ppo, run.n_envs
    inner = SubprocVecEnv([_official_env for _ in range(n_envs)])
    venv = VecNormalize(inner, gamma=ppo.gamma)
    model = RecurrentPPO(
        "MlpLstmPolicy", venv, learning_rate=ppo.learning_rate, n_steps=ppo.n_steps, batch_size=ppo.batch_size,
        n_epochs=ppo.n_epochs, gamma=ppo.gamma, gae_lambda=ppo.gae_lambda, clip_range=ppo.clip_range,
        ent_coef=ppo.ent_coef, vf_coef=ppo.vf_coef, max_grad_norm=ppo.max_grad_norm,
        target_kl=ppo.target_kl, seed=0, device="cpu",
        policy_kwargs={"lstm_hidden_size": policy.lstm_hidden_size, "enable_critic_lstm": True,
                       "shared_lstm": False, "net_arch": {"pi": list(policy.net_arch), "vf": list(policy.net_arch)},
                       "activation_fn": torch.nn.ReLU, "log_std_init": policy.log_std_init,
                       "ortho_init": policy.ortho_init})
    try:
        return _timed_learn(model, inner, steps)
    finally:
        venv.close()


def run_ours(steps: int, config: Path, overrides: tuple[str, ...] = ()) -> dict[str, float]:
    """``train.py``'s own loop on ``config``; the first rollout (warm-up) is not counted."""
    from myo_sds.curricula.run_config import load_run_config
    from myo_sds.training import CurriculumTrainer

    base = load_run_config(config, overrides)
    rollout = base.n_envs * base.ppo.n_steps
    budget = (f"total_steps={rollout + steps}",)
    with tempfile.TemporaryDirectory() as folder:
        trainer = CurriculumTrainer.start(config, overrides + budget, run_dir=Path(folder) / "run", progress=False)
        trainer.run()
        trainer.venv.close()
    timed = trainer.timings[1:]
    wall = sum(t.wall_s for t in timed)
    env, update = sum(t.env_s for t in timed), sum(t.update_s for t in timed)
    done = sum(t.steps for t in timed)
    return {"config": str(config), "env_steps": done, "wall_s": wall, "steps_per_s": done / wall,
            "env_stepping_share": env / wall, "update_share": update / wall,
            "inference_and_other_share": 1 - (env + update) / wall}


def _bare_worker(seconds: float, task: str = "baoding") -> float:
    import mujoco

    from myo_sds.envs.task_specs import TASK_SPECS

    env = TASK_SPECS[task].env_class()()
    model, data = env.model, mujoco.MjData(env.model)
    frame_skip = env.FRAME_SKIP
    rng = np.random.default_rng(os.getpid())
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        data.ctrl[:] = rng.uniform(0, 1, model.nu)
        mujoco.mj_step(model, data, frame_skip)
        steps += 1
        if steps % 30 == 0:  # episodes of about the length random actions give
            mujoco.mj_resetData(model, data)
            data.qpos[:] = env._init_qpos
    return steps / (time.perf_counter() - start)


def run_ceiling(cores: int, seconds: float = 10.0, task: str = "baoding") -> dict[str, float]:
    with multiprocessing.get_context("spawn").Pool(cores) as pool:
        rates = pool.starmap(_bare_worker, [(seconds, task)] * cores)
    return {"steps_per_s": float(sum(rates)), "processes": cores, "task": task}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=8192, help="timed env steps per training setup")
    parser.add_argument("--config", type=Path, default=REPO / "configs" / "baoding_sds.yaml")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="override a value of ours' config, as train.py --set")
    parser.add_argument("--skip-reference", action="store_true")
    parser.add_argument("--reference-from-config", action="store_true",
                        help="the reference runs the config's own recipe with stock sb3-contrib")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    cores = os.cpu_count() or 1
    results: dict[str, dict] = {"machine": {"cores": cores}}
    from myo_sds.curricula.run_config import load_run_config

    task = load_run_config(args.config, tuple(args.overrides)).curriculum.task
    results["ceiling"] = run_ceiling(cores, task=task)
    print(f"ceiling   (bare mj_step, {task}, {cores} processes): {results['ceiling']['steps_per_s']:7.0f} env steps/s",
          flush=True)
    results["ours"] = run_ours(args.steps, args.config, tuple(args.overrides))
    results["ours"]["overrides"] = args.overrides
    print(f"ours      ({args.config.name}): {results['ours']['steps_per_s']:7.0f} env steps/s", flush=True)
    if not args.skip_reference:
        recipe = args.config if args.reference_from_config else None
        results["reference"] = run_reference(args.steps, cores, recipe)
        results["reference"]["recipe"] = str(recipe) if recipe else "winner's phase-2 PPO, one env per core"
        print(f"reference (official env, SubprocVecEnv, stock sb3-contrib, {results['reference']['recipe']}): "
              f"{results['reference']['steps_per_s']:7.0f} env steps/s", flush=True)
    ours = results["ours"]["steps_per_s"]
    results["ours/ceiling"] = ours / results["ceiling"]["steps_per_s"]
    if "reference" in results:
        results["ours/reference"] = ours / results["reference"]["steps_per_s"]
    print()
    for name in ("ours", "reference"):
        if name in results:
            r = results[name]
            print(f"{name:>9} wall time: env stepping {r['env_stepping_share']:.0%}, inference and other "
                  f"{r['inference_and_other_share']:.0%}, PPO update {r['update_share']:.0%}")
    print(f"ours / ceiling:   {results['ours/ceiling']:.2f}x")
    if "ours/reference" in results:
        print(f"ours / reference: {results['ours/reference']:.2f}x")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
