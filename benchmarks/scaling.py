"""The Ray rollout backend against the local thread backend, and what more CPUs would give.

    python benchmarks/scaling.py [--steps 16384] [--workers 2] [--config configs/baoding_sds.yaml] [--json FILE]

Trains the config's first stage with the same total envs on both backends, alternating
(thread, ray, thread, ray), and reports env steps/s and the split of the Ray backend's wall
time (weight broadcast, sampling on the workers, gathering into the buffer, PPO update). From
the learner's own throughput L (samples x epochs per second of update) and a worker's sampling
rate r (env steps/s on one CPU), the expected throughput with W worker CPUs is

    synchronous:  1 / (1 / (W r) + epochs / L)       (efficiency 1 / (1 + epochs W r / L))
    overlapped:   min(W r, L / epochs)               (sampling the next rollout during the update)
"""

from __future__ import annotations

from myo_sds import set_process_environment

set_process_environment()  # before NumPy, torch and MuJoCo load: pinned kernels, short OpenMP spins

import argparse
import json
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def timed_run(config: Path, overrides: tuple[str, ...], steps: int) -> dict[str, float]:
    """A training of ``steps`` env steps after one untimed rollout; env steps/s and its split."""
    from myo_sds.curricula.run_config import load_run_config
    from myo_sds.training import CurriculumTrainer

    base = load_run_config(config, overrides)
    rollout = base.n_envs * base.ppo.n_steps
    with tempfile.TemporaryDirectory() as folder:
        trainer = CurriculumTrainer.start(config, overrides + (f"total_steps={rollout + steps}",),
                                          run_dir=Path(folder) / "run", progress=False)
        trainer.run(max_wall_s=None)
        ray_seconds = dict(getattr(trainer.rollouts, "seconds", {}))
        trainer.close()
    timed = trainer.timings[1:]
    wall = sum(t.wall_s for t in timed)
    update = sum(t.update_s for t in timed)
    done = sum(t.steps for t in timed)
    epochs = base.ppo.n_epochs
    result = {"env_steps": done, "wall_s": wall, "steps_per_s": done / wall, "update_s": update,
              "learner_samples_x_epochs_per_s": done * epochs / update, "n_envs": base.n_envs, "epochs": epochs}
    if ray_seconds:
        first = trainer.timings[0].wall_s  # the untimed rollout's share of the Ray split is removed pro rata
        scale = wall / (wall + first)
        result["split"] = {**{k: v * scale / wall for k, v in ray_seconds.items()}, "update": update / wall}
    return result


def estimate(r: float, learner: float, epochs: int, cpus: int) -> dict[str, float]:
    synchronous = 1.0 / (1.0 / (cpus * r) + epochs / learner)
    return {"cpus": cpus, "synchronous": synchronous, "efficiency": synchronous / (cpus * r),
            "overlapped": min(cpus * r, learner / epochs)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", type=Path, default=REPO / "configs" / "baoding_sds.yaml")
    parser.add_argument("--steps", type=int, default=16384)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    import ray

    ray.init(num_cpus=args.workers, include_dashboard=False, log_to_driver=False)
    ray_overrides = ("rollout.backend=ray", f"rollout.workers={args.workers}")
    runs: dict[str, list[dict]] = {"thread": [], "ray": []}
    for _ in range(args.rounds):
        runs["thread"].append(timed_run(args.config, (), args.steps))
        runs["ray"].append(timed_run(args.config, ray_overrides, args.steps))
        print(f"thread {runs['thread'][-1]['steps_per_s']:6.0f}  ray {runs['ray'][-1]['steps_per_s']:6.0f} env steps/s",
              flush=True)
    ray.shutdown()
    best = {name: max(results, key=lambda r: r["steps_per_s"]) for name, results in runs.items()}
    thread, remote = best["thread"], best["ray"]
    print(f"\nsame {thread['n_envs']} envs: thread {thread['steps_per_s']:.0f}, ray ({args.workers} workers) "
          f"{remote['steps_per_s']:.0f} env steps/s: ray / thread {remote['steps_per_s'] / thread['steps_per_s']:.2f}x")
    print("ray wall time: " + ", ".join(f"{k} {v:.0%}" for k, v in remote["split"].items()))
    learner = thread["learner_samples_x_epochs_per_s"]
    # A worker's rate on one CPU: its envs' share of the sampling time.
    r = remote["env_steps"] / (remote["split"]["sampling"] * remote["wall_s"]) / args.workers
    print(f"learner alone: {learner:,.0f} samples x epochs / s; one worker CPU samples {r:,.0f} env steps/s")
    estimates = [estimate(r, learner, thread["epochs"], cpus) for cpus in (16, 64, 256)]
    for e in estimates:
        print(f"  {e['cpus']:>3} worker CPUs: synchronous {e['synchronous']:7.0f} env steps/s "
              f"(efficiency {e['efficiency']:.0%}), overlapped {e['overlapped']:7.0f}")
    if args.json:
        args.json.write_text(json.dumps({"runs": runs, "worker_rate": r, "learner": learner, "estimates": estimates},
                                        indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
