"""A policy as its authors published it: the 2022 Baoding winner's phase-1 policy (SB3 1.6 zip,
gym 0.13 VecNormalize pickle), vendored in models/reference/. It loads without gym, scores on
the 2022 phase-1 start as on MyoSuite's own env, and starts a new run (--init-from)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch
from tiny_run import write_config

from myo_sds import evaluation as ev
from myo_sds.published import load_statistics, published_files
from myo_sds.training import CurriculumTrainer

WINNER = Path(__file__).resolve().parents[1] / "models" / "reference" / "stiff_fingers_2022_p1"


def test_published_folder_and_its_gym_era_statistics_load():
    model, statistics = published_files(WINNER)
    assert (model.name, statistics.name) == ("phase1_final.zip", "normalized_env_phase1_final.pkl")
    normalizer = load_statistics(statistics)
    # The values the winner's README records for this pickle.
    assert normalizer.obs_rms.mean.shape == (86,) and normalizer.obs_rms.count == pytest.approx(27.35e6, rel=1e-3)
    assert (normalizer.clip_obs, normalizer.epsilon) == (10.0, 1e-8)
    obs = np.linspace(-1.0, 1.0, 86)[None]
    expected = np.clip((obs - normalizer.obs_rms.mean) / np.sqrt(normalizer.obs_rms.var + 1e-8), -10, 10)
    normalizer.training = False
    assert np.allclose(normalizer.normalize_obs(obs), expected)
    policy = ev.load_policy(ev.resolve_checkpoint(WINNER), "baoding").model.policy
    # 128-unit actor and critic LSTMs feeding the heads directly: 226,383 parameters; std 0.116.
    assert sum(p.numel() for p in policy.parameters()) == 226_383
    assert float(policy.log_std.detach().exp().mean()) == pytest.approx(0.116, abs=5e-4)


def test_a_folder_that_is_neither_a_run_nor_a_published_policy_is_one_clear_error(tmp_path):
    (tmp_path / "a.zip").write_bytes(b"")
    with pytest.raises(ev.EvaluationError, match=r"nor a published policy .*found 1 .zip and 0 .pkl"):
        ev.resolve_checkpoint(tmp_path)


@pytest.mark.parametrize("preset", ["p1_2022", "p1"])
def test_winners_policy_scores_the_same_on_our_env_and_myosuites(preset):
    """A 200-step closed loop of our env against a policy nobody here trained: the same
    solved steps, length, drop and effort as on myoChallengeBaodingP1-v1."""
    pytest.importorskip("myosuite")
    ref = ev.resolve_checkpoint(WINNER)
    assert ref.run_dir is None and ev.run_task(ref) == "baoding"
    ours = ev.evaluate(ref, ev.choose_env(ref, preset), episodes=1, seed=0).summary()
    official = ev.evaluate(ref, ev.choose_env(ref, preset, official=True), episodes=1, seed=0).summary()
    (mine,), (theirs,) = ours["per_episode"], official["per_episode"]
    assert (mine["solved_steps"], mine["length"], mine["dropped"]) == (
        theirs["solved_steps"], theirs["length"], theirs["dropped"])
    assert mine["effort"] == pytest.approx(theirs["effort"], rel=1e-6)
    if preset == "p1":
        # MyoSuite 3.0.0's start (targets 90 degrees behind the balls): it drops both balls.
        assert ours["score"] == 0.0 and mine["dropped"] and mine["length"] < 60
    else:
        # The start it was trained on: it turns the balls a whole orbit without a drop. (On
        # MuJoCo 4.0.0, 179 of 200 steps solved; the count moves by a few steps between MuJoCo
        # releases: 174 on 3.3.7, 170 on 3.14.0.)
        assert not mine["dropped"] and mine["length"] == 200 and ours["score"] >= 0.8
    assert "2022" in ours["start"] if preset == "p1_2022" else "MyoSuite 3.0.0" in ours["start"]


def test_the_2022_start_puts_the_targets_on_the_resting_balls():
    from myo_sds.envs import BaodingEnv

    env = BaodingEnv("p1_2022")
    obs, _ = env.reset(seed=0)
    assert env.task.start_angle == pytest.approx(3 * math.pi / 4)
    # target - ball for each ball: within the 1.5 cm solved radius at reset (the official P1
    # start leaves them 2.5 and 3.7 cm apart).
    assert np.linalg.norm(obs[41:44]) < 0.015 and np.linalg.norm(obs[44:47]) < 0.015
    obs, _ = BaodingEnv("p1").reset(seed=0)
    assert np.linalg.norm(obs[41:44]) > 0.02 and np.linalg.norm(obs[44:47]) > 0.02


def test_a_new_run_starts_from_the_published_policy(tmp_path):
    config = write_config(tmp_path, total=64)
    text = config.read_text().replace(
        "policy: {lstm_hidden_size: 16, net_arch: [16], log_std_init: -1.0}",
        "policy: {lstm_hidden_size: 128, net_arch: [], log_std_init: 0.0, ortho_init: false}").replace(
        "n_steps: 64, batch_size: 64", "n_steps: 32, batch_size: 64")
    config.write_text(text)
    trainer = CurriculumTrainer.start(config, run_dir=tmp_path / "tuned", progress=False, init_from=WINNER)
    published = ev.load_policy(ev.resolve_checkpoint(WINNER), "baoding")
    for (name, mine), theirs in zip(trainer.model.policy.state_dict().items(),
                                    published.model.policy.state_dict().values()):
        assert torch.equal(mine, theirs), name
    assert np.array_equal(trainer.venv.obs_rms.mean, published.normalizer.obs_rms.mean)
    state = trainer.run()
    trainer.close()
    assert state.num_timesteps == 64
