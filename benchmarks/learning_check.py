"""Learning per sample and per second: ours against the 2022 winner's setup, first SDS stage.

    python benchmarks/learning_check.py [--budget 200000] [--seeds 0 1 2] [--out DIR]
        [--ours configs/baoding_sds.yaml] [--reference configs/reference_2022.yaml]

Each setup trains on the first stage of its curriculum alone (the run ends when the stage's
threshold is reached, or at the budget), from the same seeds. Reported per setup and seed:
the env steps and wall seconds at which the stage threshold was reached (if it was), and the
score (mean over the last 100 training episodes) at fixed fractions of the budget; plus a plot
of score against env steps and against wall time.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

WINDOW = 100


def first_stage_curriculum(config: Path, folder: Path) -> Path:
    """A copy of the config's curriculum reduced to its first stage."""
    from curricula.schema import load_run_config

    run = load_run_config(config)
    raw = yaml.safe_load(run.curriculum_path.read_text())
    raw["stages"] = raw["stages"][:1]
    path = folder / f"{config.stem}_first_stage.yaml"
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    return path


def train(config: Path, seed: int, budget: int, folder: Path) -> dict:
    from curricula.training import CurriculumTrainer

    curriculum = first_stage_curriculum(config, folder)
    run_dir = folder / f"{config.stem}_s{seed}"
    trainer = CurriculumTrainer.start(config, (f"curriculum={curriculum}", f"seed={seed}", f"total_steps={budget}"),
                                      run_dir=run_dir, progress=False)
    rule = trainer.config.curriculum.stages[0].advance
    state = trainer.run()
    with (run_dir / "episodes.csv").open(newline="") as file:
        rows = list(csv.DictReader(file))
    steps = np.array([int(r["step"]) for r in rows])
    wall = np.array([float(r["wall_s"]) for r in rows])
    scores = np.array([float(r["score"]) for r in rows])
    from curricula.evaluation import trailing_mean

    curve = trailing_mean(scores, WINDOW) if len(rows) else np.array([])
    passed = [h for h in state.history if h["decision"] == "passed"]
    checkpoints = {}
    for fraction in (0.25, 0.5, 0.75, 1.0):
        upto = steps <= fraction * budget
        checkpoints[f"{fraction:.2f}"] = float(curve[upto][-1]) if upto.any() else None
    return {"config": str(config), "seed": seed, "metric": rule.metric, "threshold": rule.threshold,
            "window": rule.window, "env_steps": state.num_timesteps, "wall_s": state.wall_s,
            "steps_per_s": state.num_timesteps / max(state.wall_s, 1e-9),
            "reached_at_steps": passed[0]["at_step"] if passed else None,
            "reached_at_wall_s": float(wall[steps <= passed[0]["at_step"]][-1]) if passed and len(rows) else None,
            f"score_last_{WINDOW}_at_budget_fraction": checkpoints,
            "curve": {"steps": steps.tolist(), "wall_s": wall.tolist(), "score": curve.tolist()}}


def plot(results: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (by_steps, by_wall) = plt.subplots(1, 2, figsize=(12, 4.5))
    for r in results:
        label = f"{Path(r['config']).stem} seed {r['seed']}"
        by_steps.plot(r["curve"]["steps"], r["curve"]["score"], label=label)
        by_wall.plot(np.array(r["curve"]["wall_s"]) / 60, r["curve"]["score"], label=label)
    for axis, name in ((by_steps, "env steps"), (by_wall, "wall time (min)")):
        axis.axhline(results[0]["threshold"], color="gray", linestyle="--", linewidth=1)
        axis.set_xlabel(name)
        axis.set_ylabel(f"score, mean of last {WINDOW} training episodes")
    by_steps.legend(fontsize=7)
    fig.suptitle("first SDS stage: ours vs the 2022 winner's setup")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--budget", type=int, default=200_000, help="env steps per run")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--ours", type=Path, default=REPO / "configs" / "baoding_sds.yaml")
    parser.add_argument("--reference", type=Path, default=REPO / "configs" / "reference_2022.yaml")
    parser.add_argument("--skip-reference", action="store_true")
    parser.add_argument("--out", type=Path, default=Path("learning_check"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    configs = [args.ours] + ([] if args.skip_reference else [args.reference])
    results = []
    with tempfile.TemporaryDirectory() as folder:
        for seed in args.seeds:
            for config in configs:
                result = train(config, seed, args.budget, Path(folder))
                results.append(result)
                reached = (f"reached {result['threshold']} at {result['reached_at_steps']} steps, "
                           f"{result['reached_at_wall_s']:.0f} s" if result["reached_at_steps"] else
                           f"did not reach {result['threshold']} in {result['env_steps']} steps")
                print(f"{config.stem:>16} seed {seed}: {result['steps_per_s']:.0f} steps/s, {reached}; "
                      f"score by budget fraction {result[f'score_last_{WINDOW}_at_budget_fraction']}", flush=True)
                (args.out / "learning_check.json").write_text(json.dumps(results, indent=2))
    plot(results, args.out / "learning_check.png")
    print(f"wrote {args.out / 'learning_check.json'} and {args.out / 'learning_check.png'}")


if __name__ == "__main__":
    main()
