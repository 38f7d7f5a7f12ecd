"""Our chain's stage evaluations over the 2022 winner's, stage by stage, on the same scale.

Both are the mean return of 20 deterministic episodes on the stage's own task (their reward
weights: pos_dist 1 + 1, alive 1, solved 5; an episode's maximum is ~1,200) against env steps
in the stage. Theirs come from `evaluations.csv` beside this file (`extract.py`); ours from a
run folder's `evaluations.csv` (`configs/baoding_sds.yaml`, whose stages follow theirs). Prints,
per stage, ours and theirs at our latest evaluated step (each the mean of the evaluations
within +-200k env steps of it) and their ratio, then the stage table (env steps, hours,
evaluation return first -> best -> last, ours beside theirs); draws one panel per stage.

    python experiments/winner_2022/overlay.py ~/runs/baoding_sds-s0 --out experiments/winner_2022/overlay.png
    python experiments/winner_2022/overlay.py ~/runs/baoding_sds-s0 --also ~/runs/branch-a ~/runs/branch-b
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

from myo_sds.run_folder import RunFolder

HERE = Path(__file__).resolve().parent
# Our stage -> their stages (in order; a later one continues the earlier one's step count).
THEIR_STAGES = {"hold-rsi": (1,), "rotate-30s": (2,), "rotate-25s": (3,), "rotate-20s": (4,), "rotate-15s": (5,),
                "fixed-10s": (6,), "fixed-9s": (7,), "fixed-8s": (8,), "fixed-7s": (9, 10), "fixed-6s": (11,),
                "fixed-5s": (12,)}
BRANCH_COLORS = ("tab:orange", "tab:green", "tab:red", "tab:purple")  # --also runs, in order
COMPARE_SPAN = 200_000  # env steps either side of a step whose evaluations are averaged


def their_curves() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per our stage name: (env steps in the stage, their mean evaluation return)."""
    by_stage: dict[int, list[tuple[int, float]]] = {}
    with (HERE / "evaluations.csv").open(newline="") as file:
        for row in csv.DictReader(file):
            by_stage.setdefault(int(row["stage"]), []).append((int(row["step"]), float(row["mean_return"])))
    curves = {}
    for name, numbers in THEIR_STAGES.items():
        steps, values, offset = [], [], 0
        for number in numbers:
            rows = by_stage[number]
            steps += [offset + s for s, _ in rows]
            values += [v for _, v in rows]
            offset = steps[-1]
        curves[name] = (np.array(steps), np.array(values))
    return curves


def our_curves(run_dir: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per stage name of the run: (env steps in the stage, mean evaluation return)."""
    folder = RunFolder(run_dir)
    every = folder.read_evaluations()
    records = [r for r in every if r.kind in ("periodic", "final") and r.reward is not None]
    starts: dict[int, int] = {}
    state = folder.read_state()
    if state is not None:
        starts = dict(enumerate(state.stage_starts()))
    # A running run's stage begun after its latest checkpoint: the step of the previous stage's
    # last record (its end-of-stage probe, else its last evaluation, <= 40k env steps earlier).
    for index in sorted({r.stage_index for r in records} - set(starts)):
        starts[index] = max((r.step for r in every if r.stage_index < index), default=0)
    curves: dict[str, tuple[list[int], list[float]]] = {}
    for r in records:
        steps, values = curves.setdefault(r.stage, ([], []))
        steps.append(r.step - starts.get(r.stage_index, 0))
        values.append(r.reward)
    return {name: (np.array(s), np.array(v)) for name, (s, v) in curves.items()}


def rate_changes(run_dir: Path) -> dict[str, list[tuple[int, float]]]:
    """Per stage name: (env steps into the stage, new rate) wherever the learning rate stepped by
    more than 10% inside a stage (an edit of the run's curriculum; a decaying schedule moves
    <1% per update), read from the run's TensorBoard log (none in a resumable export)."""
    from myo_sds.curricula.schema import load_curriculum
    from myo_sds.evaluation.update_sizes import read_scalars

    folder = RunFolder(run_dir)
    state = folder.read_state()
    if state is None or not folder.tensorboard_dir.is_dir():
        return {}
    names = [stage.name for stage in load_curriculum(folder.curriculum_file).stages]
    starts = state.stage_starts()
    rates = sorted(read_scalars(folder.tensorboard_dir)["learning_rate"].items())
    changes: dict[str, list[tuple[int, float]]] = {}
    for (_, before), (step, after) in zip(rates, rates[1:]):
        index = int(np.searchsorted(starts, step, side="right")) - 1
        if abs(after - before) > 0.1 * before and step - starts[index] > 10_000:
            changes.setdefault(names[index], []).append((step - starts[index], after))
    return changes


def near(steps: np.ndarray, values: np.ndarray, at: int) -> float:
    """Mean of the evaluations within COMPARE_SPAN of `at`; where there are none (their stage 1
    was evaluated every ~0.5-1M env steps), the line between the neighbouring two."""
    mask = np.abs(steps - at) <= COMPARE_SPAN
    return float(values[mask].mean()) if mask.any() else float(np.interp(at, steps, values))


def compare(ours: dict, theirs: dict) -> list[str]:
    lines = [f"{'stage':<12} {'at':>7} {'ours':>6} {'theirs':>6} {'ratio':>6}  best ours / theirs"]
    for name, (steps, values) in ours.items():
        if name not in theirs or not len(steps):
            continue
        t_steps, t_values = theirs[name]
        at = int(steps[-1])
        # Their first evaluation came after 40k env steps of the stage (480k in stage 1).
        mine, yours = near(steps, values, at), near(t_steps, t_values, max(at, int(t_steps[0])))
        lines.append(f"{name:<12} {at / 1e6:>6.2f}M {mine:>6.0f} {yours:>6.0f} {mine / yours:>6.2f}  "
                     f"{values.max():.0f} / {t_values.max():.0f}")
    return lines


def stage_table(run_dir: Path, ours: dict) -> list[str]:
    """Markdown: per stage, ours (env steps, hours, evaluation return first -> best -> last) beside theirs."""
    from myo_sds.evaluation.summary import summarize

    theirs = {}
    with (HERE / "stages.csv").open(newline="") as file:
        for row in csv.DictReader(file):
            theirs[int(row["stage"])] = row
    lines = ["| stage | ours: status | env steps | hours | return first -> best -> last | theirs: env steps | return first -> best -> last |",
             "|---|---|---|---|---|---|---|"]
    for stage in summarize(run_dir).stages:
        if stage.name in THEIR_STAGES:
            rows = [theirs[n] for n in THEIR_STAGES[stage.name]]
            their_steps = f"{sum(int(r['env_steps']) for r in rows) / 1e6:.2f}M"
            their_returns = (f"{float(rows[0]['eval_first']):.0f} -> {max(float(r['eval_best']) for r in rows):.0f}"
                             f" -> {float(rows[-1]['eval_last']):.0f}")
        elif stage.env_steps or stage.name in ours:  # a stage of ours that their chain did not have
            their_steps, their_returns = "- (ours only)", "-"
        else:
            continue
        values = ours.get(stage.name, (np.array([]), np.array([])))[1]
        our_returns = f"{values[0]:.0f} -> {values.max():.0f} -> {values[-1]:.0f}" if len(values) else "-"
        lines.append(f"| {stage.name} | {stage.status} | {stage.env_steps / 1e6:.2f}M | {stage.wall_s / 3600:.1f} | "
                     f"{our_returns} | {their_steps} | {their_returns} |")
    return lines


def plot(ours: dict, theirs: dict, path: Path, label: str, changes: dict | None = None,
         branches: dict[str, dict] | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(THEIR_STAGES)
    fig, axes = plt.subplots(3, 4, figsize=(16, 10), sharey=True)
    for ax, name in zip(axes.flat, names):
        t_steps, t_values = theirs[name]
        ax.plot(t_steps / 1e6, t_values, color="0.55", lw=1, label="2022 winner")
        ax.axhline(t_values.max(), color="0.55", lw=0.8, ls=":")
        if name in ours:
            steps, values = ours[name]
            ax.plot(steps / 1e6, values, color="tab:blue", lw=1.2, label=label)
        for (branch, curves), color in zip((branches or {}).items(), BRANCH_COLORS):
            if name in curves:
                steps, values = curves[name]
                ax.plot(steps / 1e6, values, color=color, lw=1.0, label=branch)
        for at, rate in (changes or {}).get(name, []):
            ax.axvline(at / 1e6, color="tab:blue", lw=0.8, ls="--")
            ax.text(at / 1e6, 60, f" lr {rate:.2g}", color="tab:blue", fontsize=8)
        ax.set_title(name, fontsize=10)
        ax.grid(alpha=0.3)
    extra = [name for name in ours if name not in THEIR_STAGES]  # stages of ours only, on the last panel
    if extra:
        for name in extra:
            steps, values = ours[name]
            axes.flat[-1].plot(steps / 1e6, values, lw=1.2, label=name)
        axes.flat[-1].set_title("ours only: " + ", ".join(extra), fontsize=10)
        axes.flat[-1].grid(alpha=0.3)
    else:
        axes.flat[-1].axis("off")
    for ax in axes[:, 0]:
        ax.set_ylabel("evaluation return (20 episodes)")
    for ax in axes[-1]:
        ax.set_xlabel("env steps in the stage (M)")
    axes.flat[0].legend(fontsize=8, loc="lower right")
    fig.suptitle("Stage evaluations: the 2022 winner's chain (grey; dotted: its best, our stage's early pass) and ours")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", type=Path, help="a run folder (or a resumable export) of configs/baoding_sds.yaml")
    parser.add_argument("--out", type=Path, default=HERE / "overlay.png", help="the figure (PNG)")
    parser.add_argument("--label", default=None, help="our curve's legend (default: the run folder's name)")
    parser.add_argument("--also", type=Path, nargs="*", default=[], metavar="RUN",
                        help=f"branches of the run (at most {len(BRANCH_COLORS)}), drawn beside it and compared")
    args = parser.parse_args()
    if len(args.also) > len(BRANCH_COLORS):
        parser.error(f"--also: at most {len(BRANCH_COLORS)} runs, got {len(args.also)}")
    ours, theirs = our_curves(args.run), their_curves()
    print("\n".join(compare(ours, theirs)))
    print("\n".join(stage_table(args.run, ours)))
    changes = rate_changes(args.run)
    for name, marks in changes.items():
        print(f"{name}: learning rate changed at " + ", ".join(f"{at / 1e6:.2f}M (to {rate:.2g})" for at, rate in marks))
    branches = {run.name: our_curves(run) for run in args.also}
    for name, curves in branches.items():
        print(f"\n{name}:\n" + "\n".join(compare(curves, theirs)))
    plot(ours, theirs, args.out, args.label or args.run.name, changes, branches)
    print(f"figure: {args.out}")


if __name__ == "__main__":
    main()
