"""The console's view of a curriculum run: one progress bar per stage.

A run's step budget (often 100M env steps) says nothing about when a stage will pass, so the
bar counts the current stage's env steps toward its ``max_steps``, or toward the run's budget
when that ends first (so its time estimate is the stage's or the run's end, whichever comes
first), and its text says how far the measured value is from the threshold.
"""

from __future__ import annotations

import math
import sys
import time

from myo_sds.curricula.schema import Stage, stage_label


class StageProgressBar:
    """A tqdm bar for the current stage, replaced at each stage change."""

    def __init__(self, enabled: bool, n_stages: int) -> None:
        self.enabled, self.n_stages = enabled, n_stages
        self.bar = None
        self.started_at, self.started_steps = time.perf_counter(), 0

    def start_stage(self, index: int, stage: Stage, stage_steps: int, run_steps: int, budget: int) -> None:
        from tqdm import tqdm

        self.close()
        rule = stage.advance
        # The bar ends where the stage will: at its max_steps, or where the run's budget ends first.
        limit = budget - run_steps + stage_steps
        if rule is not None and rule.max_steps is not None:
            limit = min(limit, rule.max_steps)
        over = (f"over {rule.window} episodes" if rule is None or rule.window_metric == rule.metric
                else "in a stage evaluation")
        ends = "" if rule is None or rule.max_steps is None or limit == rule.max_steps else \
            f" (the run's budget ends at {limit:,})"
        self.write(f"{stage_label(index, stage.name)} of {self.n_stages}"
                   + (f": until {rule.metric} >= {rule.threshold:g} {over}, at most "
                      f"{rule.max_steps or limit:,} env steps{ends}" if rule is not None
                      else ": until the step budget is spent"))
        self.bar = tqdm(total=limit, initial=stage_steps, unit="step", unit_scale=True, dynamic_ncols=True,
                        desc=f"stage {index + 1}/{self.n_stages}", disable=not self.enabled, smoothing=0.1,
                        mininterval=0.5 if sys.stderr.isatty() else 30.0)
        self.started_at, self.started_steps = time.perf_counter(), run_steps

    def update(self, steps: int) -> None:
        if self.bar is not None:
            self.bar.update(steps)

    def describe(self, measured: float, rule_text: str, run_steps: int) -> None:
        """Set the bar's text: the stage's measured value against its threshold, the speed."""
        if self.bar is None:
            return
        rate = (run_steps - self.started_steps) / max(time.perf_counter() - self.started_at, 1e-9)
        value = "-" if math.isnan(measured) else f"{measured:.3f}"
        self.bar.set_postfix_str(f"{rule_text.format(value=value)} | run {run_steps / 1e6:.2f}M steps | "
                                 f"{rate:.0f} steps/s", refresh=False)

    def write(self, text: str) -> None:
        from tqdm import tqdm

        tqdm.write(text)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
