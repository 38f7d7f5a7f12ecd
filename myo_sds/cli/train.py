"""Train a recurrent PPO policy through a YAML curriculum.

    python train.py --config configs/quickstart.yaml [--set ppo.learning_rate=3e-4 ...]
    myo-sds-train --config quickstart             # a bundled config, by name
    python train.py --resume runs/quickstart-20261122-101500-s0 [--max-hours 8] [--total-steps N]
    python train.py --status runs/quickstart-20261122-101500-s0 [--json summary.json]
    python train.py --export runs/quickstart-20261122-101500-s0 --to models/quickstart [--load-checkpoint N] [--best]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from myo_sds import bundled_path, set_process_environment
from myo_sds.cli import sigint_held, train_command


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--config", type=Path,
                        help="run config YAML (configs/*.yaml), or the name of a bundled one (quickstart, baoding_p1, ...)")
    source.add_argument("--resume", type=Path, metavar="RUN_DIR", help="continue this run from its latest checkpoint")
    source.add_argument("--status", type=Path, metavar="RUN_DIR",
                        help="print the run's stage table (steps, hours, measured value against the threshold) and exit")
    parser.add_argument("--json", type=Path, metavar="FILE", help="with --status: also write the summary as JSON")
    source.add_argument("--export", type=Path, metavar="RUN_DIR",
                        help="copy the run's final model (else its latest checkpoint) with its statistics, curriculum "
                             "state, config and curriculum to --to, for sharing")
    parser.add_argument("--to", type=Path, metavar="DIR", help="with --export: the model folder to write")
    parser.add_argument("--load-checkpoint", type=int, metavar="STEPS", help="with --export: that checkpoint")
    parser.add_argument("--best", action="store_true",
                        help="with --export: the best evaluated policy of the checkpoint's stage (its stage "
                             "evaluation's best so far), not the checkpoint's own")
    parser.add_argument("--resumable", action="store_true",
                        help="with --export: write what --resume needs (config, curriculum, one checkpoint with its "
                             "optimizer, statistics, curriculum and random state) and the stage table, not a model "
                             "folder; to carry a run to another machine")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="override a config value, e.g. --set n_envs=8 --set ppo.batch_size=256")
    parser.add_argument("--seed", type=int, help="same as --set seed=N")
    parser.add_argument("--n-envs", type=int, help="same as --set n_envs=N")
    parser.add_argument("--total-steps", type=int,
                        help="same as --set total_steps=N; with --resume, raises the run's step budget")
    parser.add_argument("--init-from", type=Path, metavar="MODEL",
                        help="with --config: start from this trained policy (a model or run folder, or a "
                             "checkpoint .zip): its weights, optimizer state and normalization statistics")
    parser.add_argument("--run-dir", type=Path, help="run folder (default: a new one under output_dir)")
    parser.add_argument("--overwrite", action="store_true", help="replace --run-dir if it exists")
    parser.add_argument("--max-hours", type=float, metavar="H",
                        help="stop after H hours of training in this call (checkpointed; --resume continues)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--background", action="store_true",
                        help="train at idle priority (Linux SCHED_IDLE): only on CPU time other processes leave, "
                             "so a run beside it keeps most of its speed")
    parser.add_argument("--print-config", action="store_true",
                        help="with --config (and --set): print every setting the run would use and where it came "
                             "from (file, base, --set, defaults, preset, default), then exit")
    args = parser.parse_args(argv)
    if args.export and args.to is None:
        parser.error("--export needs --to DIR")
    if args.best and (not args.export or args.resumable):
        parser.error("--best exports a stage's best evaluated policy: use it with --export, without --resumable "
                     "(a resumable export carries the stage's best already)")
    if args.resume and (args.overrides or args.seed is not None or args.n_envs is not None or args.run_dir):
        parser.error("--resume continues a run as configured; only --total-steps, --max-hours, "
                     "--no-progress and --background apply")
    if args.init_from and not args.config:
        parser.error("--init-from starts a new run: use it with --config")
    if args.print_config and not args.config:
        parser.error("--print-config shows a config's settings: use it with --config")
    if args.config is not None and not args.config.exists():
        args.config = bundled_path("configs", str(args.config)) or args.config  # else: "file not found"
    for flag, key in (("seed", "seed"), ("n_envs", "n_envs"), ("total_steps", "total_steps")):
        if getattr(args, flag) is not None and not args.resume:
            args.overrides.append(f"{key}={getattr(args, flag)}")
    return args


def _print(text: str) -> int:
    try:
        print(text, flush=True)
    except BrokenPipeError:  # `train.py --status RUN | head`
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0


def show_status(run_dir: Path, json_path: Path | None) -> int:
    import json

    from myo_sds.curricula.schema import ConfigError
    from myo_sds.evaluation.summary import before_first_checkpoint, format_summary, summarize

    try:
        if (early := before_first_checkpoint(run_dir)) is not None:
            if json_path is not None:
                json_path.write_text(json.dumps({"run_dir": str(run_dir), "status": "no checkpoint yet",
                                                 "message": early}, indent=2))
            return _print(early)
        summary = summarize(run_dir)
    except (ConfigError, FileNotFoundError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    _print(format_summary(summary))
    if json_path is not None:
        json_path.write_text(json.dumps(summary.to_dict(), indent=2))
    return 0


def export(run_dir: Path, destination: Path, steps: int | None, resumable: bool, best: bool = False) -> int:
    """A model folder (with its model card) or, ``resumable``, what ``--resume`` needs of the
    run (with its stage table), of the newest checkpoint or the one at ``steps``; ``best``: the
    model folder of that checkpoint's stage's best evaluated policy."""
    from myo_sds.evaluation.model_card import write_model_card
    from myo_sds.evaluation.summary import format_summary, summarize
    from myo_sds.run_folder import RunFolder, atomic_write_text

    try:
        run = RunFolder.require(run_dir)
        checkpoint = None if steps is None else run.checkpoint(steps)
        if checkpoint is not None and not checkpoint.complete():
            raise FileNotFoundError(f"{run_dir}: no complete checkpoint at {steps} steps")
        if best:
            checkpoint = run.best_of_stage(checkpoint)
        if resumable:
            target = run.export_resumable(destination, checkpoint)
            # The run's stage table (its newest checkpoint's), with the hours its episode log gives.
            # Named by the run's folder name, not this machine's path to it.
            summary = summarize(run.path)
            summary.run_dir = run.path.name
            atomic_write_text(target.path / "STATUS.txt", format_summary(summary) + "\n")
        else:
            target = run.export_model(destination, checkpoint)
            write_model_card(target.path, run.path)
    except FileNotFoundError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    if resumable:
        print(f"wrote {target.path}: continue with `{train_command()} --resume {target.path}` "
              "(copy it out of a source tree first: a resumed run writes its logs there)")
    else:
        print(f"wrote {target.path}: {', '.join(sorted(p.name for p in target.path.iterdir()))}")
    return 0


def _left_behind(trainer, args) -> str:
    """What an interrupted start or resume leaves: a new run without a checkpoint is removed."""
    if args is not None and args.resume:
        return f"the run is as its last checkpoint left it; continue with `{train_command()} --resume {args.resume}`"
    if trainer is None:
        return "before the first step; no run folder was kept"
    if trainer.folder.latest_checkpoint() is None:
        trainer.folder.remove()
        return "before the first checkpoint; no run folder was kept"
    return f"continue with `{train_command()} --resume {trainer.run_dir}`"


def main(argv: list[str] | None = None) -> int:
    started: list = []  # the trainer, once made
    args = None
    try:
        with sigint_held():  # the standard library's compiled modules load here
            set_process_environment()  # before NumPy, torch and MuJoCo load
            args = parse_args(argv)
        if args.background:  # before any thread starts: threads inherit the class
            from myo_sds.threads import run_at_idle_priority

            try:
                run_at_idle_priority()
            except OSError as error:
                print(f"error: {error}", file=sys.stderr)
                return 2
        return _main(args, started)
    except KeyboardInterrupt:
        # Before the run's own handler was in place (or a second Ctrl-C): say what is left.
        print(f"\ninterrupted: {_left_behind(started[0] if started else None, args)}", file=sys.stderr)
        return 130


def _main(args: argparse.Namespace, started: list) -> int:
    if args.status:
        return show_status(args.status, args.json)
    if args.export:
        return export(args.export, args.to, args.load_checkpoint, args.resumable, args.best)
    with sigint_held():  # NumPy (the config's), MuJoCo and torch load here
        from myo_sds.curricula.run_config import load_run_config
        from myo_sds.curricula.schema import ConfigError
        from myo_sds.run_folder import RunFolder

        try:
            # Check the config before torch and MuJoCo load, so a typo is reported at once.
            if args.resume:
                load_run_config(RunFolder.require(args.resume).config_file)
            else:
                config = load_run_config(args.config, tuple(args.overrides))
        except (ConfigError, FileNotFoundError) as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        if args.print_config:
            from myo_sds.config_report import format_config

            return _print(format_config(config))
        import mujoco  # noqa: F401  (the envs import it when the first is built)

        from myo_sds.curricula.state import RunStatus
        from myo_sds.training import CurriculumTrainer

    try:
        if args.resume:
            trainer = CurriculumTrainer.resume(args.resume, progress=not args.no_progress,
                                               total_steps=args.total_steps)
        else:
            trainer = CurriculumTrainer.start(args.config, tuple(args.overrides), args.run_dir,
                                              args.overwrite, progress=not args.no_progress,
                                              init_from=args.init_from)
    except (ConfigError, FileNotFoundError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    started.append(trainer)
    try:
        print(f"run folder: {trainer.run_dir}  (seed {trainer.config.seed})")
        state = trainer.run(max_wall_s=args.max_hours * 3600 if args.max_hours is not None else None)
    except Exception:
        print(f"error: training failed; {_left_behind(trainer, args)}", file=sys.stderr)
        raise
    finally:
        trainer.close()
    print(f"{state.status.value} at step {state.num_timesteps}, stage {state.stage_index + 1}/"
          f"{len(trainer.config.curriculum.stages)} ({trainer.stage.name}); run folder: {trainer.run_dir}")
    return {RunStatus.INTERRUPTED: 130, RunStatus.DIVERGED: 1}.get(state.status, 0)


if __name__ == "__main__":
    sys.exit(main())
