"""The trained policy shipped in models/: it loads outside a run folder and replays the
episodes its evaluation.json records, on our env and on MyoSuite's."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from myo_sds import evaluation as ev

MODEL = Path(__file__).resolve().parents[1] / "models" / "baoding_p1"


@pytest.mark.parametrize("official", [False, True], ids=["ours", "official"])
def test_shipped_p1_policy_replays_its_recorded_evaluation(official):
    if official:
        pytest.importorskip("myosuite")
    recorded = next(r for r in json.loads((MODEL / "evaluation.json").read_text())["reports"]
                    if r["env"] == "p1" and r["official_env"] == official)
    ref = ev.resolve_checkpoint(MODEL)
    report = ev.evaluate(ref, ev.choose_env(ref, "p1", official=official), episodes=2, seed=recorded["seed"])
    replayed = report.summary()["per_episode"]
    for now, then in zip(replayed, recorded["per_episode"][:2]):
        assert (now["solved_steps"], now["length"], now["dropped"]) == (then["solved_steps"], then["length"], then["dropped"])
        assert now["effort"] == pytest.approx(then["effort"], rel=1e-6)
    # P1 starts every episode in the same state: the deterministic policy's score is exact.
    assert report.summary()["score"] == pytest.approx(recorded["score"])
