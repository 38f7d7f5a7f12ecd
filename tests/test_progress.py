"""The console's progress bar ends where the stage will: its max_steps or the run's budget."""

from __future__ import annotations

from myo_sds.curricula.schema import AdvanceRule, Stage
from myo_sds.envs.baoding_task import BaodingKnobs
from myo_sds.training.progress import StageProgressBar


def stage(max_steps: int | None) -> Stage:
    return Stage("s", {}, BaodingKnobs.parse(), AdvanceRule(threshold=0.5, window=10, max_steps=max_steps))


def bar_total(max_steps: int | None, stage_steps: int, run_steps: int, budget: int, capsys) -> tuple[int, str]:
    bar = StageProgressBar(enabled=True, n_stages=3)
    bar.start_stage(1, stage(max_steps), stage_steps, run_steps, budget)
    total = bar.bar.total
    bar.close()
    return total, capsys.readouterr().out


def test_the_bar_ends_at_the_stage_limit_or_the_run_budget_whichever_comes_first(capsys):
    # A 10M-step stage begun at 1M of a 2M-step run: the run ends 1M steps into the stage.
    total, text = bar_total(10_000_000, 0, 1_000_000, 2_000_000, capsys)
    assert total == 1_000_000 and "at most 10,000,000 env steps (the run's budget ends at 1,000,000)" in text
    # Resumed 400k into a 1M-step stage of a long run: the stage's limit.
    total, text = bar_total(1_000_000, 400_000, 5_400_000, 100_000_000, capsys)
    assert total == 1_000_000 and "budget" not in text
    # No stage limit: the rest of the run.
    total, _ = bar_total(None, 100, 1_100, 5_000, capsys)
    assert total == 100 + 3_900
