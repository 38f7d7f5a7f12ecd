"""The speed-ups change nothing but speed: the whole-sequence LSTM update computes what
sb3-contrib's step-by-step loop computes, the padded rollout buffer gives sb3-contrib's
minibatches value for value, and ThreadVecEnv behaves like DummyVecEnv."""

from __future__ import annotations

import numpy as np
import pytest
import torch as th
from sb3_contrib.common.recurrent.policies import RecurrentActorCriticPolicy
from stable_baselines3.common.vec_env import DummyVecEnv

from myo_sds.envs.baoding import BaodingEnv
from myo_sds.policy import SequenceLstmPolicy
from myo_sds.vec_env import ThreadVecEnv


@pytest.mark.parametrize("starts_inside", [False, True])
def test_sequence_fast_path_matches_step_by_step(starts_inside):
    th.manual_seed(0)
    lstm = th.nn.LSTM(5, 8)
    n_seq, length = 6, 9
    features = th.randn(n_seq * length, 5)
    states = (th.randn(1, n_seq, 8), th.randn(1, n_seq, 8))
    starts = th.zeros(n_seq, length)
    starts[[0, 2, 5], 0] = 1.0  # sequences that begin an episode
    if starts_inside:
        starts[1, 4] = 1.0  # a reset mid-sequence: the fallback loop must handle it
    stock_out, stock_states = RecurrentActorCriticPolicy._process_sequence(features, states, starts.flatten(), lstm)
    fast_out, fast_states = SequenceLstmPolicy.sequence_pass(features, states, starts.flatten(), lstm)
    th.testing.assert_close(fast_out, stock_out, rtol=1e-5, atol=1e-6)
    th.testing.assert_close(fast_states[0], stock_states[0], rtol=1e-5, atol=1e-6)
    th.testing.assert_close(fast_states[1], stock_states[1], rtol=1e-5, atol=1e-6)


def test_fast_policy_gives_the_same_losses_on_a_real_rollout():
    from sb3_contrib import RecurrentPPO

    def make():
        return DummyVecEnv([lambda: BaodingEnv(rsi_probability=1.0, direction="hold", period="static")] * 2)

    kwargs = {"lstm_hidden_size": 16, "net_arch": [16]}
    stock = RecurrentPPO("MlpLstmPolicy", make(), n_steps=64, batch_size=64, seed=3, policy_kwargs=kwargs)
    fast = RecurrentPPO(SequenceLstmPolicy, make(), n_steps=64, batch_size=64, seed=3, policy_kwargs=kwargs)
    fast.policy.load_state_dict(stock.policy.state_dict())
    stock.learn(128)  # fills the buffer with sequences that start episodes
    batch = next(stock.rollout_buffer.get(128))
    assert batch.episode_starts.sum() > 2
    with th.no_grad():
        args = (batch.observations, batch.actions, batch.lstm_states, batch.episode_starts)
        fast.policy.load_state_dict(stock.policy.state_dict())
        values, log_prob, entropy = stock.policy.evaluate_actions(*args)
        f_values, f_log_prob, f_entropy = fast.policy.evaluate_actions(*args)
    th.testing.assert_close(f_values, values, rtol=1e-5, atol=1e-5)
    th.testing.assert_close(f_log_prob, log_prob, rtol=1e-5, atol=1e-5)


def test_action_mean_bound_limits_the_mean_and_survives_save_and_load(tmp_path):
    from sb3_contrib import RecurrentPPO

    env = DummyVecEnv([lambda: BaodingEnv(rsi_probability=1.0, direction="hold", period="static")])
    kwargs = {"lstm_hidden_size": 16, "net_arch": [16], "action_mean_bound": 1.5}
    model = RecurrentPPO(SequenceLstmPolicy, env, n_steps=16, batch_size=16, seed=3, policy_kwargs=kwargs)
    policy = model.policy
    obs = th.as_tensor(env.reset()).float()
    states = (th.zeros(1, 1, 16), th.zeros(1, 1, 16))

    def mean_for_bias(bias: float) -> th.Tensor:
        with th.no_grad():
            policy.action_net.weight.zero_()
            policy.action_net.bias.fill_(bias)
            distribution, _ = policy.get_distribution(obs, states, th.ones(1))
        return distribution.distribution.mean

    # 1.5 * tanh(x / 1.5): about the identity near zero, never beyond the bound.
    small = mean_for_bias(0.05)
    th.testing.assert_close(small, th.full((1, 39), 1.5 * np.tanh(0.05 / 1.5)))
    assert (small - 0.05).abs().max() < 1e-4
    th.testing.assert_close(mean_for_bias(100.0), th.full((1, 39), 1.5))
    th.testing.assert_close(mean_for_bias(-100.0), th.full((1, 39), -1.5))
    model.save(tmp_path / "model")
    loaded = RecurrentPPO.load(tmp_path / "model")
    assert isinstance(loaded.policy, SequenceLstmPolicy) and loaded.policy.action_mean_bound == 1.5


def test_action_head_lr_scale_keeps_the_initial_policy_and_scales_only_the_heads_step(tmp_path):
    from stable_baselines3.common.utils import ConstantSchedule

    env = BaodingEnv(rsi_probability=1.0, direction="hold", period="static")
    obs = th.as_tensor(env.reset(seed=0)[0]).float().unsqueeze(0)
    actions = th.full((1, 39), 0.3)
    states = (th.zeros(1, 1, 16), th.zeros(1, 1, 16))

    def new_policy(scale: float) -> SequenceLstmPolicy:
        th.manual_seed(0)
        return SequenceLstmPolicy(env.observation_space, env.action_space, ConstantSchedule(1e-3),
                                  lstm_hidden_size=16, net_arch=[16], action_head_lr_scale=scale)

    def mean_of(policy: SequenceLstmPolicy) -> th.Tensor:
        with th.no_grad():
            return policy.get_distribution(obs, states, th.ones(1))[0].distribution.mean

    # saved and loaded, a model keeps the scale and acts the same (no second division)
    from sb3_contrib import RecurrentPPO

    model = RecurrentPPO(SequenceLstmPolicy, DummyVecEnv([lambda: env]), n_steps=16, batch_size=16, seed=3,
                         policy_kwargs={"lstm_hidden_size": 16, "net_arch": [16], "action_head_lr_scale": 0.1})
    model.save(tmp_path / "model")
    loaded = RecurrentPPO.load(tmp_path / "model")
    assert loaded.policy.action_head_lr_scale == 0.1
    th.testing.assert_close(mean_of(loaded.policy), mean_of(model.policy))

    def one_adam_step(scale: float) -> tuple[th.Tensor, th.Tensor, dict[str, th.Tensor]]:
        policy = new_policy(scale)
        before = {name: p.detach().clone() for name, p in policy.named_parameters()}
        distribution, _ = policy.get_distribution(obs, states, th.ones(1))
        mean = distribution.distribution.mean.detach()
        (-distribution.log_prob(actions).sum()).backward()
        head_gradient = policy.action_net.weight.grad.clone()
        policy.optimizer.step()
        # the head's weights as they act on the mean: scale * stored weights
        steps = {name: (p.detach() - before[name]) * (scale if name == "action_net.weight" else 1.0)
                 for name, p in policy.named_parameters()}
        return mean, head_gradient, steps

    mean, gradient, steps = one_adam_step(1.0)
    scaled_mean, _, scaled_steps = one_adam_step(0.1)
    th.testing.assert_close(scaled_mean, mean)  # the same policy before training
    # Adam's first step moves each weight by the learning rate whatever its gradient's size,
    # so the head's effective step shrinks by the scale; the layers below see the same gradient.
    clear = gradient.abs() > 1e-3
    assert clear.sum() > 100
    th.testing.assert_close(scaled_steps["action_net.weight"][clear], 0.1 * steps["action_net.weight"][clear])
    assert steps["action_net.weight"][clear].abs().min() > 0.9e-3
    th.testing.assert_close(scaled_steps["lstm_actor.weight_hh_l0"], steps["lstm_actor.weight_hh_l0"])


def test_thread_vec_env_equals_dummy_vec_env():
    factories = [lambda: BaodingEnv("p2") for _ in range(5)]
    threaded, dummy = ThreadVecEnv(factories, n_threads=2), DummyVecEnv(factories)
    for venv in (threaded, dummy):
        venv.seed(11)
    np.testing.assert_array_equal(threaded.reset(), dummy.reset())
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(60):
        actions = rng.uniform(-1, 1, (5, 39)).astype(np.float32)
        t_obs, t_rew, t_done, t_info = threaded.step(actions)
        d_obs, d_rew, d_done, d_info = dummy.step(actions)
        np.testing.assert_array_equal(t_obs, d_obs)
        np.testing.assert_array_equal(t_rew, d_rew)
        np.testing.assert_array_equal(t_done, d_done)
        for a, b, done in zip(t_info, d_info, t_done):
            assert a["TimeLimit.truncated"] == b["TimeLimit.truncated"]
            if done:
                ends += 1
                np.testing.assert_array_equal(a["terminal_observation"], b["terminal_observation"])
                assert a["episode_result"] == b["episode_result"]
    assert ends >= 5  # auto-reset was exercised
    threaded.close()


def _filled(buffer_class, episode_start_rate: float):
    from gymnasium import spaces
    from sb3_contrib.common.recurrent.type_aliases import RNNStates

    rng = np.random.default_rng(0)
    buffer = buffer_class(32, spaces.Box(-np.inf, np.inf, (5,), np.float32), spaces.Box(-1, 1, (3,), np.float32),
                          (32, 1, 4, 6), n_envs=4)
    for _ in range(32):
        hidden = th.tensor(rng.normal(size=(1, 4, 6)), dtype=th.float32)
        buffer.add(rng.normal(size=(4, 5)).astype(np.float32), rng.normal(size=(4, 3)).astype(np.float32),
                   rng.normal(size=4), (rng.uniform(size=4) < episode_start_rate).astype(np.float32),
                   th.tensor(rng.normal(size=4)), th.tensor(rng.normal(size=4)),
                   lstm_states=RNNStates((hidden, hidden + 1), (hidden + 2, hidden + 3)))
    buffer.compute_returns_and_advantage(th.tensor(rng.normal(size=4)), np.zeros(4))
    return buffer


@pytest.mark.parametrize("batch_size", [7, 32, 128])
@pytest.mark.parametrize("episode_start_rate", [0.0, 0.1, 0.5])
def test_the_padded_buffer_gives_sb3_contribs_minibatches(batch_size, episode_start_rate):
    from sb3_contrib.common.recurrent.buffers import RecurrentRolloutBuffer

    from myo_sds.rollout_buffer import PaddedRolloutBuffer

    stock, padded = _filled(RecurrentRolloutBuffer, episode_start_rate), _filled(PaddedRolloutBuffer, episode_start_rate)
    np.random.seed(3)
    expected = list(stock.get(batch_size))
    np.random.seed(3)
    got = list(padded.get(batch_size))
    assert len(got) == len(expected) == -(-128 // batch_size)
    for mine, theirs in zip(got, expected):
        for name in theirs._fields:
            if name == "lstm_states":
                for a, b in zip(mine.lstm_states, theirs.lstm_states):
                    assert all(th.equal(x, y) for x, y in zip(a, b))
            else:
                assert th.equal(getattr(mine, name), getattr(theirs, name)), name


def test_sequences_cut_every_n_steps_start_where_the_rollout_was():
    """ppo.sequence_length: by hand, a minibatch of 10 steps with an episode start at step 6, cut
    every 4 steps: sequences [0-3], [4-5], [6-9] (the third cut at 6 + 4 = 10 is past the end)."""
    from myo_sds.rollout_buffer import padded_layout

    starts = np.zeros(10, bool)
    starts[6] = True
    first, index, real = padded_layout(starts, np.zeros(10, bool), max_length=4)
    assert first.tolist() == [0, 4, 6]
    assert index.tolist() == [[0, 1, 2, 3], [4, 5, 0, 0], [6, 7, 8, 9]]
    assert real.sum() == 10 and real.tolist()[1] == [True, True, False, False]
    first, index, _ = padded_layout(starts, np.zeros(10, bool))  # uncut: two sequences, padded to 6
    assert first.tolist() == [0, 6] and index.shape == (2, 6)
