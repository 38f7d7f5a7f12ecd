"""Official MyoChallenge metrics of trained policies, on our env and on myosuite's own env.

    python evaluate.py runs/quickstart [--env p1|p2|stage:NAME] [--official] [--episodes 50]
                       [--json out.json] [--plots out/] [--video out.mp4]
    python evaluate.py runA runB/checkpoints/rl_model_200000_steps.zip   # side by side
    python evaluate.py models/baoding_p1_2022 --env p1_2022 --official --start-noise 0,0.02 --episodes 100

P1's start is fixed and the policy deterministic, so without start noise every P1 episode is the
same one: --start-noise RAD moves each hand joint by U(-RAD, RAD) at reset (the same draw on our
env and the official one) and scores the policy rather than one replay of it.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from myo_sds import set_process_environment
from myo_sds.cli import sigint_held


def _noise_list(text: str) -> list[float]:
    try:
        values = [float(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected radians, e.g. 0.02 or 0,0.02") from None
    if not values or any(not (v >= 0 and v < float("inf")) for v in values):
        raise argparse.ArgumentTypeError(f"{text!r}: expected radians >= 0, e.g. 0.02 or 0,0.02")
    return values


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("targets", nargs="+", type=Path, metavar="RUN_DIR_OR_CHECKPOINT")
    parser.add_argument("--env", default="p1",
                        help="p1 (default; MyoSuite 3.0.0's P1), p1_2022 (the 2022 leaderboard's P1 start), p2, "
                             "or stage:NAME of the run's curriculum; several comma-separated")
    parser.add_argument("--official", action="store_true", help="also evaluate the presets on myosuite's official env")
    parser.add_argument("--episodes", type=int, default=50, help="episodes per policy and env (default 50)")
    parser.add_argument("--start-noise", type=_noise_list, default=[0.0], metavar="RAD[,RAD...]",
                        help="move each hand joint by U(-RAD, RAD) at reset (default 0); several comma-separated, "
                             "e.g. 0,0.02, evaluate each")
    parser.add_argument("--seed", type=int, default=0, help="episode i is reset with seed + i")
    parser.add_argument("--workers", type=int, default=1, help="parallel worker processes for the episodes")
    parser.add_argument("--load-checkpoint", type=int, metavar="STEPS", help="a run's checkpoint at STEPS")
    parser.add_argument("--load-last-checkpoint", action="store_true", help="a run's newest checkpoint, not its final model")
    parser.add_argument("--json", type=Path, help="write the numbers (and per-episode results) here")
    parser.add_argument("--plots", type=Path, metavar="DIR", help="learning curve and score histogram PNGs")
    parser.add_argument("--video", type=Path, metavar="FILE",
                        help="MP4 of the best and worst episodes of the first evaluation (the first with start "
                             "noise, if any), replayed on our env")
    parser.add_argument("--video-episodes", type=int, default=2, help="episodes in the video: half best, half worst")
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error("--episodes must be >= 1")
    if args.video_episodes < 1:
        parser.error("--video-episodes must be >= 1")
    return args


def _curve_names(refs) -> dict[Path, str]:
    """One learning-curve file name per run (a run's checkpoints share its curve); runs whose
    folders have the same name are told apart by a number, so no file is written over another."""
    runs = list(dict.fromkeys(ref.run_dir.resolve() for ref in refs if ref.run_dir is not None))
    names: dict[Path, str] = {}
    for run in runs:
        name, n = run.name, 2
        while name in names.values():
            name, n = f"{run.name}-{n}", n + 1
        names[run] = name
    return names


def _learning_curve(ev, ref, folder: Path, name: str) -> str:
    """Draw (or, for a model folder without an episode log, copy the shipped) learning curve of
    ``ref``'s run into ``folder``; what was done, or why there is none, as one line. Never raises
    for a missing curve: the other outputs are still written."""
    import shutil

    path = folder / f"learning_curve_{name}.png"
    try:
        ev.plot_learning_curve(ref.run_dir, path)
    except ev.EvaluationError as error:
        shipped = ref.run_dir / "learning_curve.png"
        if not shipped.is_file():
            return f"no learning curve for {ref.label}: {error}"
        shutil.copyfile(shipped, path)
        return f"wrote {path} (the curve shipped with {ref.run_dir}: it has no episode log to draw one from)"
    return f"wrote {path}"


def _run_comparison(ev, refs, folder: Path) -> str:
    """With two or more run folders that logged episodes, their training curves in one figure."""
    from myo_sds.run_folder import RunFolder

    runs = list(dict.fromkeys(ref.run_dir for ref in refs if ref.run_dir is not None
                              and RunFolder(ref.run_dir).episodes_file.is_file()))
    if len(runs) < 2:
        return "no run comparison: it needs two or more run folders with training episodes"
    path = folder / "learning_curves_compared.png"
    ev.plot_run_comparison(runs, path)
    return f"wrote {path} ({len(runs)} runs by env steps and by hours)"


def main(argv: list[str] | None = None) -> int:
    try:
        with sigint_held():  # NumPy, MuJoCo and torch load here
            set_process_environment()  # before NumPy, torch and MuJoCo load (headless rendering too)
            args = parse_args(argv)
            import mujoco  # noqa: F401  (the envs import it when the first is built)

            from myo_sds import evaluation as ev
            from myo_sds.curricula.schema import ConfigError
    except KeyboardInterrupt:
        print("\ninterrupted: nothing written", file=sys.stderr)
        return 130

    try:
        refs = [ev.resolve_checkpoint(t, args.load_checkpoint, args.load_last_checkpoint) for t in args.targets]
        names = [name.strip() for name in args.env.split(",") if name.strip()]
        choices = []
        for ref in refs:
            ref_choices = []
            for name in names:
                for noise in args.start_noise:
                    ref_choices.append(ev.choose_env(ref, name, start_noise=noise))
                    if args.official and not name.startswith("stage:"):
                        ref_choices.append(ev.choose_env(ref, name, official=True, start_noise=noise))
            choices.append(ref_choices)
        reports = []
        for ref, ref_choices in zip(refs, choices):
            for choice in ref_choices:
                print(f"evaluating {ref.label} on {choice.label}: {args.episodes} episodes ...", flush=True)
                reports.append(ev.evaluate(ref, choice, args.episodes, args.seed, args.workers))
        from myo_sds import numerics

        machine = numerics.describe()
        print()
        print(ev.format_table(reports))
        print(f"numerics {machine['fingerprint']} ({machine['cpu']}): a machine with the same fingerprint "
              "replays these episodes bit for bit")
        if args.json:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(json.dumps({"numerics": machine, "reports": [r.summary() for r in reports]}, indent=2))
            print(f"\nwrote {args.json}")
        if args.plots:
            ev.plot_score_histogram(reports, args.plots / "score_histogram.png")
            print(f"wrote {args.plots / 'score_histogram.png'}")
            names = _curve_names(refs)
            for ref in refs:
                if ref.run_dir is None:
                    print(f"no learning curve for {ref.label}: it is not inside a run or model folder")
            for run, name in names.items():
                ref = next(r for r in refs if r.run_dir is not None and r.run_dir.resolve() == run)
                print(_learning_curve(ev, ref, args.plots, name))
            print(_run_comparison(ev, refs, args.plots))
        if args.video:
            # Episodes with start noise differ from each other; without it a fixed start repeats one.
            shown = next((r for r in reports if r.env.start_noise and not r.env.official), reports[0])
            picks = ev.chosen_episodes(shown, args.video_episodes)
            frames = ev.record_video(shown.checkpoint, shown.env, args.video, picks)
            print(f"wrote {args.video} ({frames} frames: {'; '.join(f'{c} (seed {s})' for s, c in picks)})")
    except (ev.EvaluationError, ConfigError, RuntimeError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("\ninterrupted: nothing written after the last 'wrote' line", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
