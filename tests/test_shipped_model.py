"""The trained policy shipped in models/: it loads outside a run folder, behaves the same on our
env and on MyoSuite's, and replays the episodes its evaluation.json records wherever the
numerics are the same (myo_sds/numerics.py)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from myo_sds import evaluation as ev
from myo_sds import numerics

MODEL = Path(__file__).resolve().parents[1] / "models" / "baoding_p1"


def _recorded() -> dict:
    return json.loads((MODEL / "evaluation.json").read_text())


def _episodes(official: bool, episodes: int, seed: int = 0) -> list[dict]:
    ref = ev.resolve_checkpoint(MODEL)
    return ev.evaluate(ref, ev.choose_env(ref, "p1", official=official), episodes=episodes, seed=seed).summary()[
        "per_episode"]


def test_shipped_p1_policy_plays_the_same_episode_on_our_env_and_myosuites():
    pytest.importorskip("myosuite")
    ours, theirs = _episodes(False, 1)[0], _episodes(True, 1)[0]
    assert (ours["solved_steps"], ours["length"], ours["dropped"]) == (
        theirs["solved_steps"], theirs["length"], theirs["dropped"])
    assert ours["effort"] == pytest.approx(theirs["effort"], rel=1e-6)


@pytest.mark.parametrize("official", [False, True], ids=["ours", "official"])
def test_shipped_p1_policy_replays_its_recorded_evaluation(official):
    if official:
        pytest.importorskip("myosuite")
    recorded = _recorded()
    here = numerics.fingerprint()
    if recorded["numerics"]["fingerprint"] != here:
        pytest.skip(f"evaluation.json was taken with numerics {recorded['numerics']['fingerprint']} "
                    f"({recorded['numerics']['cpu']}), this machine's are {here} ({numerics.cpu_name()})")
    report = next(r for r in recorded["reports"] if r["env"] == "p1" and r["official_env"] == official)
    replayed = _episodes(official, 2, seed=report["seed"])
    for now, then in zip(replayed, report["per_episode"][:2]):
        assert (now["solved_steps"], now["length"], now["dropped"]) == (then["solved_steps"], then["length"], then["dropped"])
        assert now["effort"] == pytest.approx(then["effort"], rel=1e-6)
    # P1 starts every episode in the same state: the deterministic policy's score is exact.
    assert sum(e["score"] for e in replayed) / len(replayed) == pytest.approx(report["score"])
