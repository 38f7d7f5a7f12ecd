"""The advancement rule and the curriculum state it reads, on synthetic episode results (no
simulator)."""

from __future__ import annotations

import json

import numpy as np

from myo_sds.curricula.advancement import (
    Decision,
    decide,
    episode_metric,
    measured_value,
)
from myo_sds.curricula.schema import AdvanceRule
from myo_sds.curricula.state import CurriculumState
from myo_sds.envs.metrics import EpisodeResult


def progress(values, steps=10_000, window=4):
    """A run in its second stage (begun at step 1,000), ``steps`` env steps into it."""
    state = CurriculumState(stage_index=1, stage_start_step=1_000, num_timesteps=1_000)
    state.record("s2", 1_000 + steps, values, window)
    return state


def test_threshold_needs_a_full_window():
    rule = AdvanceRule(metric="score", threshold=0.5, window=4)
    assert decide(rule, progress([0.9, 0.9, 0.9])) is Decision.STAY  # 3 of 4 episodes
    assert decide(rule, progress([0.9, 0.9, 0.9, 0.2])) is Decision.PASSED  # mean 0.725
    assert decide(rule, progress([0.5, 0.5, 0.5, 0.5])) is Decision.PASSED  # threshold reached exactly
    assert decide(rule, progress([0.9, 0.1, 0.3, 0.3])) is Decision.STAY  # mean 0.4
    assert decide(AdvanceRule(threshold=0.61, window=4), progress([0.9, 0.9, 0.3, 0.3])) is Decision.STAY


def test_window_keeps_only_the_most_recent_episodes():
    p = progress([0.0] * 10 + [1.0] * 4, window=4)
    assert p.recent == [1.0] * 4 and p.stage_episodes == 14 and p.measured == 1.0
    assert p.episodes_per_stage == {"s2": 14} and p.steps_per_stage == {"s2": 10_000} == {"s2": p.stage_steps}
    assert decide(AdvanceRule(threshold=1.0, window=4), p) is Decision.PASSED


def test_a_stage_ends_into_the_history_and_the_next_begins_empty():
    state = progress([0.25, 0.75], steps=3_000)
    transition = state.end_stage("s2", Decision.PASSED.value, wall_s=12.0)
    assert (transition.stage, transition.stage_index, transition.at_step) == ("s2", 1, 4_000)
    assert (transition.stage_steps, transition.stage_episodes, transition.measured) == (3_000, 2, 0.5)
    assert state.history == [transition] and state.stage_starts() == [0, 4_000]
    state.begin_next_stage()
    assert (state.stage_index, state.stage_start_step, state.stage_steps, state.stage_episodes) == (2, 4_000, 0, 0)
    assert state.recent == [] and np.isnan(state.measured)
    # The JSON a checkpoint holds reads back as the same state.
    assert CurriculumState.from_json(state.to_json()) == state


def test_a_stage_rewinds_to_an_earlier_policy_of_it_as_far_as_the_episode_log_reaches():
    from types import SimpleNamespace

    import pytest

    state = progress([0.5] * 40, steps=4_000)  # stage s2: steps 1,000-5,000, 40 episodes
    state.wall_s = 100.0
    # An episode ended every 100 steps from 2,000 on (the log of the stage's last 31 episodes).
    log = [SimpleNamespace(step=step, wall_s=step / 50) for step in range(2_000, 5_001, 100)]
    whole = CurriculumState.from_json(state.to_json())
    whole.rewind_current_stage(3_000, log)
    # 20 episodes ended after step 3,000 (3,100 ... 5,000); the last one by then at wall 60 s.
    assert (whole.num_timesteps, whole.stage_steps, whole.steps_per_stage["s2"]) == (3_000, 2_000, 2_000)
    assert (whole.stage_episodes, whole.episodes_per_stage["s2"], whole.wall_s) == (20, 20, 60.0)
    # A log that begins after step 3,000 (restarted by a resume) cannot say: counts stay.
    partial = CurriculumState.from_json(state.to_json())
    partial.rewind_current_stage(3_000, log[15:])
    assert (partial.num_timesteps, partial.stage_episodes, partial.wall_s) == (3_000, 40, 100.0)
    with pytest.raises(ValueError, match="step 500 is outside the current stage"):
        state.rewind_current_stage(500, log)


def test_min_steps_delays_passing():
    rule = AdvanceRule(threshold=0.5, window=2, min_steps=5000)
    assert decide(rule, progress([1, 1], steps=4999)) is Decision.STAY
    assert decide(rule, progress([1, 1], steps=5000)) is Decision.PASSED


def test_max_steps_ends_the_stage_unpassed_or_stops():
    advance = AdvanceRule(threshold=0.9, window=2, max_steps=1000)
    stop = AdvanceRule(threshold=0.9, window=2, max_steps=1000, on_max_steps="stop")
    assert decide(advance, progress([0.1, 0.1], steps=999)) is Decision.STAY
    assert decide(advance, progress([0.1, 0.1], steps=1000)) is Decision.TIMED_OUT
    assert decide(stop, progress([0.1, 0.1], steps=1000)) is Decision.STOP
    # Passing wins over timing out at the same check.
    assert decide(stop, progress([0.95, 0.95], steps=1000)) is Decision.PASSED


def plateau_run(means, rule, every=1_000):
    """A stage whose window mean is ``means[k]`` at stage step ``(k + 1) * every`` (one
    record per rollout, the window refilled with that mean); the decision after each."""
    state = CurriculumState()
    decisions = []
    for k, mean in enumerate(means):
        state.record("s", (k + 1) * every, [mean] * rule.window, rule.window, rule.tracked_gain)
        decisions.append(decide(rule, state))
    return state, decisions


def test_a_stage_without_gain_for_plateau_steps_ends_unpassed():
    rule = AdvanceRule(threshold=0.9, window=2, plateau_steps=4_000, plateau_gain=0.05)
    # Best 0.30 at 1k; 0.33, 0.34 and later 0.37-0.39 rise less than the gain, 0.36 at 5k more.
    means = [0.30, 0.33, 0.34, 0.32, 0.36, 0.35, 0.37, 0.39]
    state, decisions = plateau_run(means, rule)
    assert (state.best_measured, state.best_at_stage_step) == (0.36, 5_000)
    assert decisions == [Decision.STAY] * 8
    # The stage ends 4,000 steps after its best, at 9k.
    assert plateau_run(means + [0.38], rule)[1][-1] is Decision.PLATEAUED
    # Without the rise at 5k it would have ended at 5k.
    assert plateau_run([0.30, 0.33, 0.34, 0.32, 0.34], rule)[1][-1] is Decision.PLATEAUED
    stop = AdvanceRule(threshold=0.9, window=2, plateau_steps=3_000, plateau_gain=0.05, on_max_steps="stop")
    assert plateau_run([0.3, 0.3, 0.3, 0.3], stop)[1] == [Decision.STAY] * 3 + [Decision.STOP]
    # A steadily rising stage never plateaus, and passing wins at the same check.
    assert set(plateau_run([0.1 * k for k in range(1, 9)], rule)[1][:-1]) == {Decision.STAY}
    assert plateau_run([0.3, 0.3, 0.3, 0.95], rule)[1][-1] is Decision.PASSED
    # min_steps delays it; without plateau_steps nothing is tracked.
    late = AdvanceRule(threshold=0.9, window=2, plateau_steps=3_000, min_steps=6_000)
    assert plateau_run([0.3] * 6, late)[1] == [Decision.STAY] * 5 + [Decision.PLATEAUED]
    untracked, decisions = plateau_run([0.3] * 20, AdvanceRule(threshold=0.9, window=2))
    assert untracked.best_measured is None and set(decisions) == {Decision.STAY}


def test_the_plateau_best_needs_a_full_window_and_restarts_with_each_stage():
    state = CurriculumState()
    state.record("s", 1_000, [0.5], window=2, plateau_gain=0.01)
    assert state.best_measured is None  # 1 of 2 episodes
    state.record("s", 2_000, [0.7], window=2, plateau_gain=0.01)
    assert (state.best_measured, state.best_at_stage_step) == (0.6, 2_000)
    assert CurriculumState.from_json(state.to_json()) == state
    state.end_stage("s", Decision.PLATEAUED.value, wall_s=1.0)
    state.begin_next_stage()
    assert (state.best_measured, state.best_at_stage_step) == (None, 0)
    # A checkpoint written before the plateau was kept reads back untracked.
    old = {k: v for k, v in json.loads(state.to_json()).items() if not k.startswith("best_")}
    assert CurriculumState.from_json(json.dumps(old)).best_measured is None


def test_stage_without_rule_never_ends():
    assert decide(None, progress([1.0] * 100, steps=10**9)) is Decision.STAY


def test_episode_metrics():
    held = EpisodeResult(solved_steps=50, length=200, horizon=200, dropped=False, effort=0.1)
    dropped = EpisodeResult(solved_steps=30, length=40, horizon=200, dropped=True, effort=0.1)
    assert episode_metric("score", held) == 0.25 and episode_metric("score", dropped) == 0.15
    assert episode_metric("survival", held) == 1.0 and episode_metric("survival", dropped) == 0.0


def simulated_schedule(seed: int, rules: list[AdvanceRule]) -> list[tuple[int, str]]:
    """Stage transitions of a synthetic run whose episode scores improve with steps."""
    rng = np.random.default_rng(seed)
    state, schedule = CurriculumState(), []
    for step in range(0, 200_000, 1000):
        skill = min(1.0, (step - state.stage_start_step) / 50_000)
        rule = rules[state.stage_index]
        state.record(f"s{state.stage_index}", step, np.clip(rng.normal(skill * 0.8, 0.1, 3), 0, 1), rule.window)
        decision = decide(rule, state)
        if decision is not Decision.STAY:
            schedule.append((step, decision.value))
            state.end_stage(f"s{state.stage_index}", decision.value, wall_s=0.0)
            state.begin_next_stage()
            if state.stage_index == len(rules):
                break
    return schedule


def test_same_seed_same_schedule():
    rules = [AdvanceRule(threshold=0.3, window=20), AdvanceRule(threshold=0.6, window=20, max_steps=30_000),
             AdvanceRule(threshold=0.5, window=50)]
    first = simulated_schedule(7, rules)
    assert first == simulated_schedule(7, rules)
    assert [d for _, d in first] == ["passed", "timed_out", "passed"]
    assert first != simulated_schedule(8, rules)


def test_an_evaluation_metric_passes_on_the_latest_evaluation_not_the_window():
    rule = AdvanceRule(metric="eval_reward", threshold=983, window=4, max_steps=50_000)
    state = progress([0.9] * 4, steps=10_000)  # a full window far above any score threshold
    assert np.isnan(measured_value(rule, state)) and decide(rule, state) is Decision.STAY
    assert state.record_evaluation(0.7, 900.0, select="reward")
    assert decide(rule, state) is Decision.STAY
    # A later evaluation with a lower score but a higher return is the best by return ...
    state.record("s2", 12_000)
    assert state.record_evaluation(0.6, 990.0, select="reward")
    assert (state.best_evaluated, state.best_evaluated_reward, state.best_evaluated_step) == (0.6, 990.0, 12_000)
    assert measured_value(rule, state) == 990.0 and decide(rule, state) is Decision.PASSED
    # ... and the gate reads the latest one: a fall below it stays (the best is kept).
    state.record("s2", 13_000)
    assert not state.record_evaluation(0.8, 950.0, select="reward")
    assert decide(rule, state) is Decision.STAY and state.best_evaluated_reward == 990.0
    assert decide(AdvanceRule(metric="eval_score", threshold=0.8, window=4), state) is Decision.PASSED
    # Selecting by score, the 0.8 evaluation would have been the best.
    by_score = progress([0.9] * 4)
    for score, reward in ((0.7, 900.0), (0.6, 990.0), (0.8, 950.0)):
        by_score.record_evaluation(score, reward)
    assert (by_score.best_evaluated, by_score.best_evaluated_reward) == (0.8, 950.0)
    # The window still holds training scores (for display), whatever the rule's metric.
    assert rule.window_metric == "score" and AdvanceRule(metric="survival").window_metric == "survival"
    # The stage's evaluations are cleared for the next stage, and the state round-trips.
    transition = state.end_stage("s2", Decision.PASSED.value, wall_s=1.0, probe={"median_solved_steps": 42.0})
    assert transition.best_evaluated_reward == 990.0 and transition.probe == {"median_solved_steps": 42.0}
    state.begin_next_stage()
    assert state.last_evaluated_reward is None and state.best_evaluated_reward is None
    assert CurriculumState.from_json(state.to_json()) == state
