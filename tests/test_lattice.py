"""Lattice exploration (myo_sds/lattice.py) against hand-computed covariances and
log-probabilities, its samples, and a Lattice policy that trains, resumes and evaluates."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch as th

from myo_sds.lattice import LatticeNoise

REPO = Path(__file__).resolve().parents[1]


def small_distribution(full_std: bool = False, alpha: float = 1.0, std_reg: float = 0.0) -> LatticeNoise:
    """A = 2 actions, d = 2 latent features, exp (not expln) stds, known weights."""
    dist = LatticeNoise(2, full_std=full_std, use_expln=False, alpha=alpha, std_reg=std_reg)
    net, _ = dist.proba_distribution_net(latent_dim=2, log_std_init=0.0)
    with th.no_grad():
        net.weight.copy_(th.tensor([[1.0, 2.0], [0.0, 3.0]]))
        net.bias.copy_(th.tensor([0.5, -0.5]))
    return dist


def test_covariance_and_log_probability_match_the_hand_computed_ones():
    dist = small_distribution(alpha=2.0, std_reg=0.1)
    # log_std column 0: the latent matrix's std per latent feature, column 1: the action matrix's.
    log_std = th.log(th.tensor([[0.3, 0.2], [0.4, 0.5]])) + 0.5 * math.log(2)  # cancels the 1/sqrt(d) scaling
    x = th.tensor([[1.0, 2.0]])
    mean = dist.mean_actions_net(x)
    dist.proba_distribution(mean, log_std, x)
    # By hand: v_j = sum_i x_i^2 s_i^2 = 1 * 0.09 + 4 * 0.16 = 0.73 for each latent j;
    # u_k = 1 * 0.04 + 4 * 0.25 + 0.1^2 (+ 1e-6) = 1.05 for each action k.
    # Sigma = alpha^2 * 0.73 * W W^T + 1.05 I, W W^T = [[5, 6], [6, 9]].
    expected = 4 * 0.73 * np.array([[5.0, 6.0], [6.0, 9.0]]) + (1.05 + 1e-6) * np.eye(2)
    assert np.allclose(dist.distribution.covariance_matrix[0].detach().numpy(), expected, rtol=1e-6)
    assert np.allclose(mean.detach().numpy(), [[5.5, 5.5]])  # W x + b
    action = np.array([6.0, 4.0])
    diff = action - np.array([5.5, 5.5])
    by_hand = -0.5 * diff @ np.linalg.solve(expected, diff) - 0.5 * math.log(np.linalg.det(2 * math.pi * expected))
    assert dist.log_prob(th.tensor(action[None], dtype=th.float32)).item() == pytest.approx(by_hand, rel=1e-5)
    entropy = 0.5 * math.log(np.linalg.det(2 * math.pi * math.e * expected))
    assert dist.entropy().item() == pytest.approx(entropy, rel=1e-5)
    assert np.allclose(dist.mode().detach().numpy(), [[5.5, 5.5]])


def test_full_std_gives_each_matrix_entry_its_own_std():
    dist = small_distribution(full_std=True)
    s = np.array([[0.1, 0.2], [0.3, 0.4]])  # P_x entries
    t = np.array([[0.5, 0.6], [0.7, 0.8]])  # P_a entries
    log_std = th.log(th.tensor(np.hstack([s, t]), dtype=th.float32)) + 0.5 * math.log(2)
    x = th.tensor([[2.0, -1.0]])
    dist.proba_distribution(dist.mean_actions_net(x), log_std, x)
    v = 4 * s[0] ** 2 + 1 * s[1] ** 2  # per latent j
    u = 4 * t[0] ** 2 + 1 * t[1] ** 2  # per action k
    w = np.array([[1.0, 2.0], [0.0, 3.0]])
    expected = w @ np.diag(v) @ w.T + np.diag(u + 1e-6)
    assert np.allclose(dist.distribution.covariance_matrix[0].detach().numpy(), expected, rtol=1e-6)


def test_samples_have_the_distribution_s_mean_and_covariance():
    th.manual_seed(0)
    dist = small_distribution(alpha=1.0)
    log_std = th.log(th.tensor([[0.3, 0.2], [0.4, 0.5]]))
    x = th.tensor([[1.0, 2.0]]).repeat(20000, 1)
    dist.sample_weights(log_std, batch_size=len(x))  # a fresh pair of matrices for every row
    dist.proba_distribution(dist.mean_actions_net(x), log_std, x)
    samples = dist.sample().detach().numpy()
    expected = dist.distribution.covariance_matrix[0].detach().numpy()
    assert np.allclose(samples.mean(axis=0), [5.5, 5.5], atol=0.05)
    assert np.allclose(np.cov(samples.T), expected, rtol=0.05)
    # Correlated across actions: both rows of W load on the second latent feature.
    correlation = expected[0, 1] / math.sqrt(expected[0, 0] * expected[1, 1])
    assert correlation > 0.5 and np.corrcoef(samples.T)[0, 1] == pytest.approx(correlation, abs=0.02)


def test_stds_are_clipped_and_scaled_by_the_latent_size():
    dist = LatticeNoise(3, use_expln=False, std_clip=(1e-3, 2.0))
    dist.proba_distribution_net(latent_dim=4)
    latent_std, action_std = dist.get_std(th.tensor([[10.0, -20.0]] * 4))
    assert latent_std.shape == (4, 4) and action_std.shape == (4, 3)
    assert th.allclose(latent_std, th.full((4, 4), 2.0 / 2))  # clipped to 2, over sqrt(4)
    assert th.allclose(action_std, th.full((4, 3), 1e-3 / 2))


def tiny_config(folder, total: int, exploration: str = "lattice"):
    from tiny_run import write_config

    # As the recipe's network: the LSTM feeds the heads directly (a ReLU layer's all-zero latent
    # would give Lattice no noise to explore with).
    path = write_config(folder, total)
    path.write_text(path.read_text().replace("net_arch: [16], log_std_init: -1.0}",
                                             f"net_arch: [], log_std_init: 0.0, exploration: {exploration}}}"))
    return path


def test_a_lattice_policy_trains_resumes_and_evaluates(tmp_path):
    from myo_sds import evaluation as ev
    from myo_sds.policy import LatticeLstmPolicy, load_model
    from myo_sds.run_folder import RunFolder
    from myo_sds.training import CurriculumTrainer

    run = tmp_path / "run"
    trainer = CurriculumTrainer.start(tiny_config(tmp_path, 1024), run_dir=run, progress=False)
    model = trainer.model
    assert isinstance(model.policy, LatticeLstmPolicy) and model.use_sde and model.sde_sample_freq == 1
    assert model.policy.log_std.shape == (16, 2)
    before = model.policy.log_std.detach().clone()
    trainer.run()
    trainer.close()
    assert not th.equal(before, model.policy.log_std.detach())  # the noise scale is learned
    # Resumes with its distribution, and trains on.
    state = CurriculumTrainer.resume(run, progress=False, total_steps=2048).run()
    assert state.num_timesteps >= 2048
    loaded = load_model(RunFolder(run).final_model, device="cpu")
    assert isinstance(loaded.policy, LatticeLstmPolicy) and loaded.policy.lattice_alpha == 1.0
    ref = ev.resolve_checkpoint(run)
    report = ev.evaluate(ref, ev.choose_env(ref, "p1"), episodes=2)
    assert len(report.episodes) == 2
    # A Gaussian checkpoint starts Lattice with the same mean network (and Lattice's own noise).
    (tmp_path / "g").mkdir()
    CurriculumTrainer.start(tiny_config(tmp_path / "g", 256, "gaussian"), run_dir=tmp_path / "g" / "run",
                            progress=False).run()
    gaussian = ev.resolve_checkpoint(tmp_path / "g" / "run")
    started = CurriculumTrainer.start(tiny_config(tmp_path, 1024), run_dir=tmp_path / "from_gaussian",
                                      progress=False, init_from=gaussian.model)
    source = load_model(gaussian.model, device="cpu").policy.state_dict()
    for name, value in started.model.policy.state_dict().items():
        if name != "log_std":
            assert th.equal(value, source[name]), name
    started.close()


def test_the_shared_latent_variance_shortcut_computes_the_general_covariance():
    th.manual_seed(1)
    shared = LatticeNoise(5, full_std=False, alpha=0.7)
    shared.proba_distribution_net(latent_dim=8, log_std_init=-0.5)
    log_std = th.randn(8, 2) * 0.3
    x = th.randn(6, 8)
    general = LatticeNoise(5, full_std=True, alpha=0.7)
    general.proba_distribution_net(latent_dim=8)
    general.mean_actions_net = shared.mean_actions_net
    # The per-feature stds spelled out as a full matrix: each row's two values repeated.
    full = th.cat([log_std[:, :1].expand(8, 8), log_std[:, 1:].expand(8, 5)], dim=1)
    assert th.allclose(shared.covariance(log_std, x), general.covariance(full, x), atol=1e-6)


def test_log_probability_entropy_and_their_gradients_equal_torch_s_multivariate_normal():
    from torch.distributions import MultivariateNormal

    from myo_sds.lattice import _InverseAndHalfLogDet

    th.manual_seed(2)
    dist = LatticeNoise(39, alpha=1.0)
    net, log_std = dist.proba_distribution_net(latent_dim=128, log_std_init=-1.0)
    features, latent, actions = th.randn(64, 128, requires_grad=True), th.randn(64, 128), th.randn(64, 39)
    losses = []
    for reference in (False, True):
        dist.proba_distribution(net(features), log_std, latent)
        if reference:
            dist.distribution = MultivariateNormal(dist.distribution.mean, dist.distribution.covariance_matrix)
        log_prob, entropy = dist.log_prob(actions), dist.entropy()
        params = (features, log_std, net.weight, net.bias)
        grads = th.autograd.grad(log_prob.sum() + 0.01 * entropy.sum(), params)
        losses.append((log_prob, entropy, grads))
    (ours, ours_entropy, ours_grads), (torch_s, torch_entropy, torch_grads) = losses
    assert th.allclose(ours, torch_s, rtol=1e-5, atol=1e-3) and th.allclose(ours_entropy, torch_entropy, atol=1e-4)
    for mine, theirs in zip(ours_grads, torch_grads):
        assert th.allclose(mine, theirs, rtol=1e-3, atol=1e-3 * theirs.abs().max().item())
    # The closed-form backward, against finite differences in float64.
    x = th.randn(3, 5, 5, dtype=th.float64)
    sigma = (x @ x.transpose(1, 2) + th.eye(5, dtype=th.float64)).requires_grad_()
    assert th.autograd.gradcheck(lambda s: _InverseAndHalfLogDet.apply(0.5 * (s + s.transpose(1, 2))), (sigma,))


def test_an_update_that_makes_the_policy_non_finite_stops_the_run_with_the_policy_from_before(tmp_path):
    """Lattice on a small from-scratch setup (64-unit LSTM, lr 3e-4, log_std_init -1, the first
    quickstart's): the first update overflows a probability ratio (the noise is small). The run
    stops with a clear reason and a finite checkpoint instead of a Cholesky traceback; the noise
    floor the message names trains through."""
    from myo_sds.curricula.state import RunStatus
    from myo_sds.run_folder import RunFolder
    from myo_sds.training import CurriculumTrainer

    (tmp_path / "curriculum.yaml").write_text(
        "name: hold\ntask: baoding\n"
        "defaults: {preset: p1, direction: hold, period: static, start_angle: uniform, rsi_probability: 1.0,\n"
        "           reward_weights: {pos_dist_1: 1.0, pos_dist_2: 1.0, solved: 5.0, alive: 1.0}}\n"
        "stages:\n  - name: hold-wide\n    env: {solved_radius: 0.03}\n"
        "    advance: {metric: score, threshold: 0.08, window: 40, max_steps: 400000}\n")
    config = tmp_path / "small.yaml"
    config.write_text("curriculum: curriculum.yaml\nseed: 0\nn_envs: 4\n"
                      "policy: {lstm_hidden_size: 64, net_arch: [64, 64], log_std_init: -1.0}\n"
                      "ppo: {learning_rate: 3.0e-4, n_steps: 256, batch_size: 256, n_epochs: 4, clip_range: 0.2, "
                      "ent_coef: 0.0}\n")
    trainer = CurriculumTrainer.start(config, ("policy.exploration=lattice", "total_steps=3072"),
                                      run_dir=tmp_path / "bad", progress=False)
    state = trainer.run()
    trainer.close()
    assert state.status is RunStatus.DIVERGED and state.num_timesteps == 1024
    assert all(bool(p.isfinite().all()) for p in trainer.model.policy.parameters())
    assert RunFolder(tmp_path / "bad").latest_checkpoint().steps == 1024
    trainer = CurriculumTrainer.start(config, ("policy.exploration=lattice", "policy.lattice_std_reg=0.1",
                                               "total_steps=3072"), run_dir=tmp_path / "floor", progress=False)
    assert trainer.run().status is RunStatus.BUDGET_REACHED
    trainer.close()
