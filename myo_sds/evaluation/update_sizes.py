"""How large a run's recent PPO updates were, from its TensorBoard log (``--status``).

A policy whose action std has shrunk moves further in KL for the same step in its mean (the KL
of a mean shift grows as 1 / std^2), so at a constant learning rate its updates grow. The stage
table does not show that; these few numbers do. What size is right is for a same-start
comparison to say, not a fixed KL.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

# What SB3 logs once per update, and what it is called here.
UPDATE_SCALARS = {"approx_kl": "train/approx_kl", "clip_fraction": "train/clip_fraction",
                  "explained_variance": "train/explained_variance", "learning_rate": "train/learning_rate"}


@dataclass
class UpdateSizes:
    updates: int  # how many of the newest updates the figures cover
    first_step: int  # the run env steps of the first and last of them
    last_step: int
    approx_kl_median: float
    approx_kl_p90: float
    clip_fraction_median: float
    explained_variance_median: float
    learning_rate: float  # the newest update's

    def describe(self) -> str:
        return (f"the last {self.updates} updates ({format_steps(self.first_step)}-{format_steps(self.last_step)} env steps): "
                f"approx KL median {self.approx_kl_median:.3f} (90th percentile {self.approx_kl_p90:.3f}), "
                f"clip fraction {self.clip_fraction_median:.2f}, explained variance {self.explained_variance_median:.2f}, "
                f"learning rate {self.learning_rate:.3g}")


def format_steps(step: int) -> str:
    """Env steps as people read them: 16.31M, or 18,432 below a million."""
    return f"{step / 1e6:.2f}M" if step >= 1_000_000 else f"{step:,}"


def read_scalars(tensorboard_dir: str | Path, last: int | None = None) -> dict[str, dict[int, float]]:
    """Each of UPDATE_SCALARS by env step. A resumed run logs its steps from the last checkpoint
    again in a new event file: a file's steps from where a newer file begins are superseded.
    With ``last``, files are read newest first only until that many updates are found."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    series: dict[str, dict[int, float]] = {name: {} for name in UPDATE_SCALARS}
    superseded_from = None  # the first step of the newest file read so far
    for events in sorted(Path(tensorboard_dir).glob("events.out.tfevents.*"), key=_created, reverse=True):
        accumulator = EventAccumulator(str(events), size_guidance={"scalars": 0})
        accumulator.Reload()
        logged = set(accumulator.Tags()["scalars"])
        first = None
        for name, tag in UPDATE_SCALARS.items():
            if tag not in logged:
                continue
            for event in accumulator.Scalars(tag):
                first = event.step if first is None else min(first, event.step)
                if superseded_from is None or event.step < superseded_from:
                    series[name][event.step] = event.value
        if first is not None:
            superseded_from = first if superseded_from is None else min(superseded_from, first)
        if last is not None and len(series["approx_kl"]) >= last:
            break
    return series


def _created(events: Path) -> tuple[int, str]:
    """Event file names carry their creation time (seconds): write order."""
    parts = events.name.split(".")
    stamp = parts[3] if len(parts) > 3 and parts[3].isdigit() else "0"
    return int(stamp), events.name


def recent_update_sizes(tensorboard_dir: str | Path, last: int = 100) -> UpdateSizes | None:
    """Medians over the newest ``last`` updates; None when the log holds no update yet."""
    if not Path(tensorboard_dir).is_dir():
        return None
    series = read_scalars(tensorboard_dir, last)
    kl = series["approx_kl"]
    if not kl:
        return None
    steps = sorted(kl)[-last:]

    def values(name: str) -> np.ndarray:
        return np.array([series[name][s] for s in steps if s in series[name]], dtype=float)

    clip, variance, rate = values("clip_fraction"), values("explained_variance"), values("learning_rate")
    return UpdateSizes(updates=len(steps), first_step=steps[0], last_step=steps[-1],
                       approx_kl_median=float(np.median(values("approx_kl"))),
                       approx_kl_p90=float(np.percentile(values("approx_kl"), 90)),
                       clip_fraction_median=float(np.median(clip)) if len(clip) else float("nan"),
                       explained_variance_median=float(np.median(variance)) if len(variance) else float("nan"),
                       learning_rate=float(rate[-1]) if len(rate) else float("nan"))
