"""The learning check's comparison: scores at fixed env steps and time to the threshold."""

import importlib.util
from pathlib import Path

import pytest
from tiny_run import CURRICULUM, write_config

from myo_sds.run_folder import RunFolder

SPEC = importlib.util.spec_from_file_location(
    "learning_check", Path(__file__).resolve().parents[1] / "benchmarks" / "learning_check.py")
learning_check = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(learning_check)


def run(config: str, seed: int, steps: list[int], scores: list[float], reached: int | None = None) -> dict:
    wall = [s / 100 for s in steps]  # 100 env steps/s
    return {"config": config, "seed": seed, "threshold": 0.6, "env_steps": steps[-1], "wall_s": wall[-1],
            "steps_per_s": 100.0, "reached_at_steps": reached,
            "reached_at_wall_s": reached / 100 if reached else None,
            "curve": {"steps": steps, "wall_s": wall, "score": scores}}


def test_score_at_takes_the_last_point_at_or_before_the_step_and_none_past_the_run():
    r = run("ours.yaml", 0, [1000, 2000, 3000], [0.1, 0.2, 0.3])
    assert learning_check.score_at(r, 2500) == pytest.approx(0.2)
    assert learning_check.score_at(r, 3000) == pytest.approx(0.3)
    assert learning_check.score_at(r, 500) is None
    assert learning_check.score_at(r, 4000) is None


def test_summary_averages_seeds_and_bounds_an_unreached_threshold_from_below():
    results = [run("ours.yaml", 0, [1000, 2000, 3000], [0.1, 0.3, 0.7], reached=3000),
               run("ours.yaml", 1, [1000, 2000, 3000], [0.2, 0.5, 0.6], reached=2500),
               run("reference.yaml", 0, [1000, 2000], [0.4, 0.5])]
    text = learning_check.summarize(results, [1000, 2000, 3000])
    lines = text.splitlines()
    ours = next(line for line in lines if line.split()[0] == "ours")
    assert ours.split()[-3:] == ["0.150", "0.400", "0.650"]
    reference = next(line for line in lines if line.split()[0] == "reference")
    assert reference.split()[-3:] == ["0.400", "0.500", "-"]
    assert "ours: all seeds by 30 s" in text
    assert "reference: 0/1 seeds (seed 0: not within 2000 steps, > 20 s)" in text


def test_summary_says_over_how_many_seeds_a_mark_is_averaged_when_runs_ended_early():
    results = [run("ours.yaml", 0, [1000, 2000], [0.1, 0.7], reached=2000),
               run("ours.yaml", 1, [1000, 2000, 3000], [0.3, 0.4, 0.5])]
    text = learning_check.summarize(results, [1000, 2000, 3000])
    ours = next(line for line in text.splitlines() if line.split()[0] == "ours")
    assert ours.split()[-3:] == ["0.200", "0.550", "0.500(1)"]


def test_summary_keeps_two_setups_of_one_config_apart_by_their_setup_names():
    stock = run("reference.yaml", 0, [1000, 2000], [0.1, 0.2])
    fast = dict(run("reference.yaml", 0, [1000, 2000], [0.3, 0.4]), setup="reference_fast_update")
    text = learning_check.summarize([stock, fast], [1000, 2000])
    rows = {line.split()[0]: line.split()[-2:] for line in text.splitlines()[2:4]}
    assert rows == {"reference": ["0.100", "0.200"], "reference_fast_update": ["0.300", "0.400"]}


def test_first_reached_needs_a_full_window_and_reports_steps_and_seconds():
    window = learning_check.WINDOW
    steps = [1000 * (i + 1) for i in range(window + 3)]
    # A lucky start (1.0 over a short window) must not count; a full window at 0.5 does.
    scores = [1.0] + [0.1] * (window - 1) + [0.3, 0.5, 0.7]
    r = run("ours.yaml", 0, steps, scores)
    assert learning_check.first_reached(r, 0.5) == (steps[window + 1], steps[window + 1] / 100)
    assert learning_check.first_reached(r, 0.1) == (steps[window - 1], steps[window - 1] / 100)
    assert learning_check.first_reached(r, 0.8) is None


def test_run_folders_are_kept_and_a_second_call_continues_them(tmp_path):
    # A first stage that is never passed, so the budget and the time limit end each call.
    config = write_config(tmp_path, total=1, curriculum=CURRICULUM.replace("threshold: 0.01", "threshold: 0.99"))
    runs = tmp_path / "runs"
    runs.mkdir()
    first = learning_check.train(config, 5, 256, runs)
    assert (first["status"], first["env_steps"], first["threshold"]) == ("budget_reached", 256, 0.99)
    assert first["reached_at_steps"] is None and len(first["curve"]["steps"]) > 0
    checkpoint = RunFolder(runs / "run_s5").latest_checkpoint()
    again = learning_check.train(config, 5, 256, runs)  # already done: only read
    assert RunFolder(runs / "run_s5").latest_checkpoint() == checkpoint and again["curve"] == first["curve"]
    longer = learning_check.train(config, 5, 512, runs)
    assert longer["env_steps"] == 512 and longer["wall_s"] > first["wall_s"]
    count = len(first["curve"]["steps"])
    assert longer["curve"]["steps"][:count] == first["curve"]["steps"]
    assert len(longer["curve"]["steps"]) > count
    # A time limit counts the run's training time over all calls: once spent, nothing more runs.
    paused = learning_check.train(config, 6, 100_000, runs, max_wall_s=1e-9)
    assert (paused["status"], paused["env_steps"]) == ("time_limit", 128)
    assert learning_check.train(config, 6, 100_000, runs, max_wall_s=1e-9)["env_steps"] == 128
