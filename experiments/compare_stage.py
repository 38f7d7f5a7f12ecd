"""One stage in several runs side by side, by env steps into that stage: a branch against the
chain it came from (same start policy, one setting changed).

Per bin of ``--bin`` env steps of the stage: the mean stage-evaluation return (20 deterministic
episodes on the stage's own task, the same seeds in every run) and the training episodes' score
and drop rate, placed on the targets and at rest.

    python experiments/compare_stage.py rotate-20s ~/runs/baoding_sds-s0 ~/runs/rotate20_lr3e-5-s0
    python experiments/compare_stage.py fixed-10s ~/runs/baoding_sds-s0 ~/runs/branch@fixed-10s-again --by-direction

``RUN@STAGE`` compares another stage of that run (a branch that renamed the stage); with
``--by-direction`` the training episodes' score, drop rate and median solved steps per direction
(and, with chained goals, the mean number of goals reached).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd


def stage_start(run: Path, stage: str) -> int:
    """The run env step at which ``stage`` began (0 for a run's first stage, or before the
    run's first checkpoint)."""
    state_file = run / "curriculum_state.json"
    if not state_file.is_file():
        return 0
    state = json.loads(state_file.read_text())
    names = [h["stage"] for h in state["history"]]
    if stage not in names:
        # The current stage, or one begun after the newest checkpoint (the state file is older
        # than the logs): the last step logged under another stage before this one's first.
        logged = pd.concat([pd.read_csv(run / name, usecols=["step", "stage"])
                            for name in ("episodes.csv", "evaluations.csv") if (run / name).is_file()])
        first = logged[logged.stage == stage].step.min()
        before = logged[(logged.stage != stage) & (logged.step <= first)].step
        return max(state["stage_start_step"] if state["history"] else 0, int(before.max()) if len(before) else 0)
    index = names.index(stage)
    return 0 if index == 0 else state["history"][index - 1]["at_step"]


def table(run: Path, stage: str, bin_steps: int, by_direction: bool = False) -> pd.DataFrame:
    start = stage_start(run, stage)
    evaluations = pd.read_csv(run / "evaluations.csv")
    evaluations = evaluations[(evaluations.stage == stage) & (evaluations.kind == "periodic")]
    evaluations = evaluations.assign(bin=(evaluations.step - start) // bin_steps)
    rows = {"eval return": evaluations.groupby("bin").reward.mean(), "eval score": evaluations.groupby("bin").score.mean()}
    if not (run / "episodes.csv").is_file():  # a resumable export carries no episode log
        return pd.DataFrame(rows)
    episodes = pd.read_csv(run / "episodes.csv")
    episodes = episodes[episodes.stage == stage]
    episodes = episodes.assign(bin=(episodes.step - start) // bin_steps)
    rows["training score"] = episodes.groupby("bin").score.mean()
    for start_kind in ("on_targets", "rest", "recorded"):
        of_kind = episodes[episodes.start == start_kind]
        if of_kind.empty:
            continue
        rows[f"{start_kind} score"] = of_kind.groupby("bin").score.mean()
        rows[f"{start_kind} dropped"] = of_kind.groupby("bin").dropped.mean()
    for direction in sorted(episodes.direction.unique()) if by_direction else ():
        of_direction = episodes[episodes.direction == direction].groupby("bin")
        rows[f"{direction} score"] = of_direction.score.mean()
        rows[f"{direction} dropped"] = of_direction.dropped.mean()
        rows[f"{direction} median solved"] = of_direction.solved_steps.median()
        if "goals" in episodes and episodes.goals.notna().any():  # chained goals: the mean number reached
            rows[f"{direction} goals"] = of_direction.goals.mean()
    return pd.DataFrame(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("stage")
    parser.add_argument("runs", nargs="+", help="run folders; RUN@STAGE for another stage of that run")
    parser.add_argument("--bin", type=int, default=200_000, help="env steps of the stage per row")
    parser.add_argument("--by-direction", action="store_true", help="training episodes per direction too")
    args = parser.parse_args()
    pd.set_option("display.width", 250)
    for spec in args.runs:
        folder, _, stage = spec.partition("@")
        run, stage = Path(folder).expanduser(), stage or args.stage
        if not (run / "evaluations.csv").is_file():
            print(f"{run.name}: no evaluation yet\n")
            continue
        frame = table(run, stage, args.bin, args.by_direction)
        frame.index = [f"{b * args.bin / 1e6:g}-{(b + 1) * args.bin / 1e6:g}M" for b in frame.index]
        print(f"{run.name}, {stage}:")
        print(frame.round(2).to_string(na_rep="-"))
        print(f"  best evaluation {np.nanmax(frame['eval return']):.0f} (bin mean)\n")


if __name__ == "__main__":
    main()
