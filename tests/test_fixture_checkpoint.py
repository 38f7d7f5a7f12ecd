"""A checkpoint written before the code moved still evaluates to the same episodes and resumes."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from myo_sds import evaluation as ev
from myo_sds.training import CurriculumTrainer

FIXTURE = Path(__file__).resolve().parent / "fixtures" / "run_before_restructure"


@pytest.fixture
def old_run(tmp_path) -> Path:
    run = tmp_path / "run"
    shutil.copytree(FIXTURE, run)
    return run


def test_old_checkpoint_evaluates_to_the_same_episodes(old_run):
    expected = json.loads((old_run / "expected_evaluation.json").read_text())
    ref = ev.resolve_checkpoint(old_run)
    assert ref.model.name == "rl_model_256_steps.zip"
    for env_name, episodes in expected.items():
        report = ev.evaluate(ref, ev.choose_env(ref, env_name), episodes=len(episodes), seed=0)
        got = [e.to_dict() for e in report.episodes]
        for old, new in zip(episodes, got, strict=True):
            # Fields added since (counts by target phase) are not in the fixture.
            assert {k: new[k] for k in old if k != "effort"} == {k: v for k, v in old.items() if k != "effort"}
            assert new["effort"] == pytest.approx(old["effort"], rel=1e-9)


def test_old_run_resumes_in_its_stage(old_run):
    state = CurriculumTrainer.resume(old_run, progress=False, total_steps=384).run()
    assert state.status == "budget_reached" and state.num_timesteps == 384
    assert state.stage_index == 1 and state.history[0].at_step == 256


def test_old_run_exports_with_each_stage_wall_time_from_its_episode_log(old_run, tmp_path):
    # Its transition predates the wall time kept in the state: the export takes it from the log.
    rows = [line.split(",") for line in (old_run / "episodes.csv").read_text().splitlines()[1:]]
    stage_1_end = [float(row[1]) for row in rows if int(row[0]) <= 256][-1]
    assert json.loads((old_run / "curriculum_state.json").read_text())["history"][0].get("wall_s") is None
    from myo_sds.run_folder import RunFolder

    RunFolder(old_run).export_model(tmp_path / "model")
    exported = ev.summarize(tmp_path / "model")
    assert exported.stages[0].wall_s == pytest.approx(stage_1_end) and stage_1_end > 0
    assert exported.stages[1].wall_s == pytest.approx(exported.wall_s - stage_1_end)
