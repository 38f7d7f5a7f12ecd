"""A floor on the action noise (``policy.log_std_min``) and the feed-forward policy
(``policy.memory: none``): the std never falls below the floor, for Gaussian and Lattice
exploration, through training, saving and resuming."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch as th
from tiny_run import write_config

from myo_sds.lattice import LatticeNoise
from myo_sds.run_folder import RunFolder
from myo_sds.training import CurriculumTrainer

FLOOR = -1.0  # PKU-MARL's min_log_std: the std never below 0.37


def floored_config(folder, total: int, extra: str = "") -> object:
    path = write_config(folder, total)
    path.write_text(path.read_text().replace(
        "log_std_init: -1.0}", f"log_std_init: -0.9, log_std_min: {FLOOR}{extra}}}").replace(
        # A rate at which the std would fall well below the floor within a few updates.
        "learning_rate: 3.0e-4", "learning_rate: 0.05"))
    return path


def test_the_gaussian_std_is_held_at_its_floor_through_updates_and_a_resume(tmp_path):
    run = tmp_path / "run"
    trainer = CurriculumTrainer.start(floored_config(tmp_path, 512), run_dir=run, progress=False)
    policy = trainer.model.policy
    assert policy.log_std_min == FLOOR
    # An update that only pushes the noise down: without the floor one step of Adam at 0.05 moves
    # log_std from -0.9 to -0.95, twenty steps to ~-1.9.
    for _ in range(20):
        policy.optimizer.zero_grad()
        policy.log_std.sum().backward()
        policy.optimizer.step()
    assert float(policy.log_std.detach().min()) == FLOOR  # held at the floor, not below
    assert th.all(policy.log_std == FLOOR)
    obs = th.zeros((1, *trainer.model.observation_space.shape))
    lstm = (th.zeros(1, 1, policy.lstm_output_dim),) * 2
    dist, _ = policy.get_distribution(obs, lstm, th.ones(1))
    assert th.allclose(dist.distribution.stddev, th.full((1, 39), math.exp(FLOOR)))
    # A real training run with the same rate keeps it too, and the floor is saved with the model.
    state = trainer.run()
    assert state.num_timesteps >= 512
    assert float(trainer.model.policy.log_std.detach().min()) >= FLOOR
    trainer.close()
    resumed = CurriculumTrainer.resume(run, progress=False, total_steps=1024)
    assert resumed.model.policy.log_std_min == FLOOR
    resumed.run()
    assert float(resumed.model.policy.log_std.detach().min()) >= FLOOR
    resumed.close()
    from myo_sds.policy import load_model

    saved = load_model(RunFolder(run).final_model)
    assert saved.policy.log_std_min == FLOOR and float(saved.policy.log_std.detach().min()) >= FLOOR


def test_a_policy_without_the_floor_starts_at_it_when_loaded_into_one(tmp_path):
    from myo_sds.policy import SequenceLstmPolicy

    trainer = CurriculumTrainer.start(floored_config(tmp_path, 512), run_dir=tmp_path / "run", progress=False)
    policy: SequenceLstmPolicy = trainer.model.policy
    weights = {k: v.clone() for k, v in policy.state_dict().items()}
    weights["log_std"].fill_(-3.0)  # as a policy trained without a floor may have it
    policy.load_state_dict(weights)
    assert th.all(policy.log_std == FLOOR)
    trainer.close()


def test_lattice_keeps_each_muscle_s_independent_noise_at_the_floor():
    th.manual_seed(0)
    floor_std = 0.4
    dist = LatticeNoise(2, use_expln=False, min_action_std=floor_std)
    net, _ = dist.proba_distribution_net(latent_dim=2, log_std_init=0.0)
    with th.no_grad():
        net.weight.copy_(th.tensor([[1.0, 2.0], [0.0, 3.0]]))
        net.bias.zero_()
    # Tiny learned stds: without the floor the covariance would be ~1e-6 I.
    log_std = th.full((2, 2), math.log(1e-3))
    x = th.tensor([[1.0, 2.0]]).repeat(20000, 1)
    dist.sample_weights(log_std, batch_size=len(x))
    dist.proba_distribution(dist.mean_actions_net(x), log_std, x)
    covariance = dist.distribution.covariance_matrix[0].detach().numpy()
    assert np.all(np.diag(covariance) >= floor_std**2 - 1e-9)
    assert np.diag(covariance) == pytest.approx([floor_std**2] * 2, rel=1e-3)  # the floor dominates
    samples = dist.sample().detach().numpy()
    assert np.cov(samples.T) == pytest.approx(covariance, rel=0.05, abs=2e-3)  # samples follow it


def test_a_lattice_policy_with_a_floor_trains(tmp_path):
    path = floored_config(tmp_path, 256, ", exploration: lattice, net_arch: []")
    path.write_text(path.read_text().replace("net_arch: [16], ", ""))
    trainer = CurriculumTrainer.start(path, run_dir=tmp_path / "run", progress=False)
    assert trainer.model.policy.action_dist.min_action_variance == pytest.approx(math.exp(2 * FLOOR))
    trainer.run()
    trainer.close()


def test_the_floor_is_checked_when_read(tmp_path):
    from myo_sds.curricula.schema import ConfigError

    path = write_config(tmp_path, 256)
    path.write_text(path.read_text().replace("log_std_init: -1.0}", "log_std_init: -2.0, log_std_min: -1.0}"))
    with pytest.raises(ConfigError, match="log_std_min: -1.0 is above log_std_init -2.0"):
        CurriculumTrainer.start(path, run_dir=tmp_path / "bad", progress=False)
    path.write_text(path.read_text().replace("log_std_min: -1.0}", "log_std_min: -3.0, fast_lstm_update: false}"))
    with pytest.raises(ConfigError, match="log_std_min: needs policy.fast_lstm_update: true"):
        CurriculumTrainer.start(path, run_dir=tmp_path / "bad", progress=False)


def test_a_feed_forward_policy_reads_the_observation_and_carries_no_memory(tmp_path):
    """memory: none: the layers read the observation itself, so the action does not depend on
    what came before (the LSTM states stay as they were given)."""
    path = write_config(tmp_path, 256)
    path.write_text(path.read_text().replace(
        "net_arch: [16], log_std_init: -1.0}", "net_arch: [8, 8], critic_net_arch: [12], activation: tanh, "
                                               "memory: none, log_std_init: -1.0}"))
    trainer = CurriculumTrainer.start(path, run_dir=tmp_path / "run", progress=False)
    policy = trainer.model.policy
    n_obs = trainer.model.observation_space.shape[0]
    assert policy.memory == "none" and policy.lstm_output_dim == n_obs
    assert [m.out_features for m in policy.mlp_extractor.policy_net if isinstance(m, th.nn.Linear)] == [8, 8]
    assert [m.out_features for m in policy.mlp_extractor.value_net if isinstance(m, th.nn.Linear)] == [12]
    obs = th.randn(3, n_obs)
    states = (th.randn(1, 3, n_obs), th.randn(1, 3, n_obs))
    from sb3_contrib.common.recurrent.type_aliases import RNNStates

    with th.no_grad():
        actions, values, _, new_states = policy(obs, RNNStates(states, states), th.zeros(3), deterministic=True)
        # The same function of the observation alone: the first layer on the raw (normalized) input.
        by_hand = policy.action_net(policy.mlp_extractor.forward_actor(obs))
    assert th.allclose(actions, by_hand)
    assert th.equal(new_states.pi[0], states[0]) and th.equal(new_states.vf[1], states[1])
    trainer.run()  # trains end to end
    trainer.close()
