"""Learning per sample and per second: ours against the 2022 winner's setup, first SDS stage.

    python benchmarks/learning_check.py [--budget 2000000] [--reference-budget 100000]
        [--seeds 0 1 2] [--out DIR] [--ours configs/baoding_sds.yaml]
        [--reference configs/reference_2022.yaml] [--reference-minutes M] [--skip-reference]
        [--skip-ours] [--reference-fast-update] [--add-results JSON ...]

Each setup trains on the first stage of its curriculum alone (the run ends when the stage's
threshold is reached, or at the budget), from the same seeds. Reported per setup and seed:
the env steps and wall seconds at which the stage threshold was reached (if it was), and the
score (mean over the last 100 training episodes) at fixed env steps; plus a plot of score
against env steps and against wall time.

The reference runs at ~60 env steps/s on 2 cores, so it gets its own, smaller budget. A run
that ends at its budget without reaching the threshold still bounds its time to the threshold
from below (more than its wall time), which is what the summary compares ours against. Results
of earlier runs (e.g. a reference run that took an hour) can be added with --add-results.
--reference-fast-update trains the reference with our whole-sequence LSTM update instead of
sb3-contrib's step-by-step loop: the same function (tests/test_speed_parts.py), ~2.5x faster, so
its curve against env steps can be followed further; its wall times are then not the
reference's.

Run folders are kept under OUT/runs/<setup>_s<seed>. Running the same command again continues
them instead of starting over: an interrupted or time-limited run resumes from its last
checkpoint, a larger --budget (or --reference-minutes) trains a finished run on, and a run that
is already done is only read. Delete a run folder to start it afresh.
"""

from __future__ import annotations

from myo_sds import set_process_environment

set_process_environment()  # before NumPy, torch and MuJoCo load: pinned kernels, short OpenMP spins

import argparse
import json
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

WINDOW = 100
# A first stage that passes on its evaluations (configs/baoding_sds.yaml's) is measured on its
# training episodes' score instead, as the results recorded so far were; no stage evaluation or
# probe takes time.
FIRST_STAGE_RULE = {"metric": "score", "threshold": 0.6, "window": 200}


def first_stage_curriculum(config: Path, folder: Path) -> Path:
    """A copy of the config's curriculum reduced to its first stage, without evaluations (an
    evaluation-gated stage passed at FIRST_STAGE_RULE)."""
    from myo_sds.curricula.run_config import load_run_config

    run = load_run_config(config)
    raw = yaml.safe_load(run.curriculum_path.read_text())
    stage = dict(raw["stages"][0])
    advance = stage.get("advance") or {}
    if str(advance.get("metric", "")).startswith("eval_"):
        stage["advance"] = {**FIRST_STAGE_RULE, "max_steps": advance.get("max_steps", 10_000_000)}
    stage.pop("evaluate", None)
    raw.pop("probe", None)
    raw["stages"] = [stage]
    path = folder / f"{config.stem}_first_stage.yaml"
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    return path


class Setup(NamedTuple):
    """One trained setup: a run config with its budget, time limit and overrides."""

    config: Path
    budget: int
    max_wall_s: float | None = None
    overrides: tuple[str, ...] = ()
    name: str | None = None  # defaults to the config's file name


def setup_name(result: dict) -> str:
    """A result's setup name (results of older runs carry only their config)."""
    return result.get("setup") or Path(result["config"]).stem


def train(config: Path, seed: int, budget: int, folder: Path, max_wall_s: float | None = None,
          overrides: tuple[str, ...] = (), setup: str | None = None) -> dict:
    """Train (or continue, or only read) the run ``folder/<setup>_s<seed>`` up to ``budget``
    env steps and ``max_wall_s`` seconds of training in all, and return its result."""
    from myo_sds.curricula.run_config import load_run_config
    from myo_sds.curricula.state import RunStatus
    from myo_sds.run_folder import RunFolder
    from myo_sds.training import CurriculumTrainer

    setup = setup or config.stem
    run_dir = folder / f"{setup}_s{seed}"
    run = RunFolder(run_dir)
    checkpoint = run.latest_checkpoint() if run_dir.is_dir() else None
    if checkpoint is None:
        curriculum = first_stage_curriculum(config, folder)
        trainer = CurriculumTrainer.start(
            config, overrides + (f"curriculum={curriculum}", f"seed={seed}", f"total_steps={budget}"),
            run_dir=run_dir, overwrite=True, progress=False)
        state = trainer.run(max_wall_s=max_wall_s)
    else:
        state = checkpoint.read_state()
        can_continue = state.status in (RunStatus.RUNNING, RunStatus.INTERRUPTED, RunStatus.TIME_LIMIT,
                                        RunStatus.BUDGET_REACHED)
        time_left = None if max_wall_s is None else max_wall_s - state.wall_s
        if can_continue and state.num_timesteps < budget and (time_left is None or time_left > 0):
            print(f"continuing {run_dir} from {state.num_timesteps} env steps", flush=True)
            trainer = CurriculumTrainer.resume(run_dir, progress=False, total_steps=budget)
            state = trainer.run(max_wall_s=time_left)
    rule = load_run_config(run.config_file).curriculum.stages[0].advance
    rows = run.read_episodes()
    steps = np.array([r.step for r in rows])
    wall = np.array([r.wall_s for r in rows])
    scores = np.array([r.score for r in rows])
    from myo_sds.evaluation import trailing_mean

    curve = trailing_mean(scores, WINDOW) if len(rows) else np.array([])
    passed = [t for t in state.history if t.decision == "passed"]
    return {"config": str(config), "setup": setup, "overrides": list(overrides), "seed": seed,
            "metric": rule.metric, "threshold": rule.threshold, "window": rule.window,
            "status": state.status.value, "env_steps": state.num_timesteps, "wall_s": state.wall_s,
            "steps_per_s": state.num_timesteps / max(state.wall_s, 1e-9),
            "reached_at_steps": passed[0].at_step if passed else None,
            "reached_at_wall_s": float(wall[steps <= passed[0].at_step][-1]) if passed and len(rows) else None,
            "curve": {"steps": steps.tolist(), "wall_s": wall.tolist(), "score": curve.tolist()}}


def plot(results: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (by_steps, by_wall) = plt.subplots(1, 2, figsize=(12, 4.5))
    for r in results:
        label = f"{setup_name(r)} seed {r['seed']}"
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


def score_at(result: dict, step: int) -> float | None:
    """The run's trailing score at ``step`` env steps (None if the run ended before)."""
    steps = np.array(result["curve"]["steps"])
    if not len(steps) or result["env_steps"] < step:
        return None
    scores = np.array(result["curve"]["score"])
    upto = steps <= step
    return float(scores[upto][-1]) if upto.any() else None


def first_reached(result: dict, level: float) -> tuple[int, float] | None:
    """Env steps and wall seconds at which the trailing score (over a full window of
    episodes) first reaches ``level``; None if it never does."""
    scores = np.array(result["curve"]["score"])[WINDOW - 1:]
    hits = np.flatnonzero(scores >= level)
    if not len(hits):
        return None
    index = hits[0] + WINDOW - 1
    return int(result["curve"]["steps"][index]), float(result["curve"]["wall_s"][index])


# Score levels, as fractions of the stage threshold, at which setups are compared by the
# env steps and time they first need to get there.
LEVEL_FRACTIONS = (0.1, 0.15, 0.2, 0.25, 0.5)


def summarize(results: list[dict], marks: list[int]) -> str:
    """Per-step and per-second comparison of the setups, as text."""
    setups: dict[str, list[dict]] = {}
    for r in results:
        setups.setdefault(setup_name(r), []).append(r)
    threshold = results[0]["threshold"]
    lines = [f"score (mean of last {WINDOW} training episodes) at env steps, mean over seeds "
             "((n): over the n seeds whose runs got that far):",
             f"{'setup':>18} {'seeds':>5} {'steps/s':>8} " + " ".join(f"{m // 1000:>6}k   " for m in marks)]
    for name, runs in setups.items():
        cells = []
        for mark in marks:
            values = [v for v in (score_at(r, mark) for r in runs) if v is not None]
            count = f"({len(values)})" if 0 < len(values) < len(runs) else ""
            cells.append(f"{np.mean(values):7.3f}{count:<3}" if values else f"{'-':>7}   ")
        speed = np.mean([r["steps_per_s"] for r in runs])
        lines.append(f"{name:>18} {len(runs):>5} {speed:8.0f} " + " ".join(cells))
    lines.append("env steps (k) / wall seconds at which each seed first reaches a score:")
    levels = [round(threshold * f, 3) for f in LEVEL_FRACTIONS]
    lines.append(f"{'setup':>18} {'seed':>5} " + " ".join(f"{level:>13}" for level in levels))
    for name, runs in setups.items():
        for r in runs:
            cells = [f"{hit[0] // 1000:>6}k/{hit[1]:>5.0f}s" if hit else f"{'-':>13}"
                     for hit in (first_reached(r, level) for level in levels)]
            lines.append(f"{name:>18} {r['seed']:>5} " + " ".join(cells))
    lines.append(f"time to the stage threshold ({threshold}):")
    for name, runs in setups.items():
        reached = [r for r in runs if r["reached_at_steps"] is not None]
        parts = [f"seed {r['seed']}: {r['reached_at_steps']} steps, {r['reached_at_wall_s']:.0f} s"
                 if r["reached_at_steps"] is not None else
                 f"seed {r['seed']}: not within {r['env_steps']} steps, > {r['wall_s']:.0f} s" for r in runs]
        verdict = (f"all seeds by {max(r['reached_at_wall_s'] for r in reached):.0f} s"
                   if len(reached) == len(runs) else f"{len(reached)}/{len(runs)} seeds")
        lines.append(f"{name:>18}: {verdict} ({'; '.join(parts)})")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--budget", type=int, default=2_000_000, help="env steps per run of ours")
    parser.add_argument("--reference-budget", type=int, default=100_000,
                        help="env steps per reference run (~30 min each at the reference's speed)")
    parser.add_argument("--reference-minutes", type=float,
                        help="also end each reference run after this much training time, e.g. the time "
                             "ours took to the threshold: a reference run that has not reached it by then "
                             "is slower in wall time")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--ours", type=Path, default=REPO / "configs" / "baoding_sds.yaml")
    parser.add_argument("--reference", type=Path, default=REPO / "configs" / "reference_2022.yaml")
    parser.add_argument("--skip-reference", action="store_true")
    parser.add_argument("--skip-ours", action="store_true")
    parser.add_argument("--reference-fast-update", action="store_true",
                        help="train the reference with the whole-sequence LSTM update (same function, faster) "
                             "to follow its curve against env steps further; its wall times are then not the reference's")
    parser.add_argument("--add-results", type=Path, nargs="*", default=[],
                        help="learning_check.json files of earlier runs to include in the summary and plot")
    parser.add_argument("--out", type=Path, default=Path("learning_check"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    results = [r for path in args.add_results for r in json.loads(path.read_text())]
    reference_wall_s = args.reference_minutes * 60 if args.reference_minutes is not None else None
    setups = [] if args.skip_ours else [Setup(args.ours, args.budget)]
    if not args.skip_reference:
        fast = args.reference_fast_update
        setups.append(Setup(args.reference, args.reference_budget, reference_wall_s,
                            ("policy.fast_lstm_update=true",) if fast else (),
                            f"{args.reference.stem}_fast_update" if fast else None))
    runs = args.out / "runs"
    runs.mkdir(exist_ok=True)
    for setup in setups:
        for seed in args.seeds:
            result = train(setup.config, seed, setup.budget, runs, setup.max_wall_s,
                           setup.overrides, setup.name)
            results.append(result)
            (args.out / "learning_check.json").write_text(json.dumps(results, indent=2))
            if result["status"] == "interrupted":
                print(f"interrupted; run the same command again to continue from {runs}")
                sys.exit(130)
            reached = (f"reached {result['threshold']} at {result['reached_at_steps']} steps, "
                       f"{result['reached_at_wall_s']:.0f} s" if result["reached_at_steps"] else
                       f"did not reach {result['threshold']} in {result['env_steps']} steps")
            print(f"{result['setup']:>16} seed {seed}: {result['steps_per_s']:.0f} steps/s, {reached}", flush=True)
    common = min(r["env_steps"] for r in results)
    marks = sorted({int(common * f) // 1000 * 1000 for f in (0.25, 0.5, 0.75, 1.0)}
                   | {m for m in (250_000, 500_000, 1_000_000, 2_000_000) if m > common
                      and any(r["env_steps"] >= m for r in results)})
    summary = summarize(results, marks)
    (args.out / "summary.txt").write_text(summary + "\n")
    plot(results, args.out / "learning_check.png")
    print(summary)
    print(f"wrote {args.out / 'learning_check.json'}, summary.txt and learning_check.png")


if __name__ == "__main__":
    main()
