"""Every use of a private stable-baselines3 / sb3-contrib member, in one place.

The trainer drives RecurrentPPO one rollout and one update at a time (curriculum stages change
the envs and PPO settings between them), which SB3's public ``learn()`` does not allow. What it
needs of SB3's internals is here, each behind a small function, and :data:`PRIVATE_METHODS` and
:data:`PRIVATE_ATTRIBUTES` name every private member used here or overridden by
:mod:`myo_sds.policy`, so
``tests/test_sb3_internals.py`` fails by name when an upgrade renames or removes one. The
versions these were checked against are pinned in ``pyproject.toml``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

# (module, class) -> private methods called on it or overridden.
PRIVATE_METHODS: dict[tuple[str, str], tuple[str, ...]] = {
    ("sb3_contrib", "RecurrentPPO"): ("_setup_learn",),
    # Called by myo_sds.vec_env.ThreadVecEnv, which steps DummyVecEnv's envs on threads.
    ("stable_baselines3.common.vec_env", "DummyVecEnv"): ("_reset_seeds", "_save_obs", "_obs_from_buf"),
    # Overridden by myo_sds.policy.SequenceLstmPolicy (the whole-sequence LSTM pass, the bounded mean);
    # _build is called again by LatticeLstmPolicy once its distribution replaces the Gaussian.
    ("sb3_contrib.common.recurrent.policies", "RecurrentActorCriticPolicy"): (
        "_process_sequence", "_get_action_dist_from_latent", "_get_constructor_parameters", "_build"),
    # Overridden by myo_sds.rollout_buffer.PaddedRolloutBuffer (the same minibatches, padded in one gather).
    ("sb3_contrib.common.recurrent.buffers", "RecurrentRolloutBuffer"): ("_get_samples",),
    # The hooks SB3 documents for a callback to override (myo_sds.training.callbacks, rollout_worker).
    ("stable_baselines3.common.callbacks", "BaseCallback"): ("_on_step", "_on_rollout_start", "_on_rollout_end"),
}
# (module, class) -> private attributes set or read on its instances.
PRIVATE_ATTRIBUTES: dict[tuple[str, str], tuple[str, ...]] = {
    # _last_lstm_states and _last_original_obs: left out of a gym-era archive's load (myo_sds.published).
    ("sb3_contrib", "RecurrentPPO"): ("_last_obs", "_last_episode_starts", "_n_updates", "_last_lstm_states",
                                      "_last_original_obs"),
    ("stable_baselines3.common.logger", "TensorBoardOutputFormat"): ("_is_closed",),
}


def declared_private_names() -> set[str]:
    """Every private SB3 member named above: the only ones code outside this module may use."""
    return {name for names in (*PRIVATE_METHODS.values(), *PRIVATE_ATTRIBUTES.values()) for name in names}


def updates_done(model) -> int:
    """How many gradient epochs the model has run (SB3 counts an early-stopped one too)."""
    return model._n_updates


def start_training(model, total_steps: int, callback) -> Any:
    """SB3's set-up for training, as ``learn()`` does it before its loop: the callback (wrapped
    as SB3 wraps it), the first reset or a loaded model's LSTM states, the step budget; then the
    callback's ``on_training_start``. Returns SB3's callback."""
    _, sb3_callback = model._setup_learn(total_steps, callback, reset_num_timesteps=False)
    sb3_callback.on_training_start(locals(), globals())
    return sb3_callback


def prepare_rollout(model, steps: int, callback) -> None:
    """The set-up SB3 does before one ``collect_rollouts`` call (a Ray worker's rollout)."""
    model._setup_learn(steps, callback, reset_num_timesteps=False)


def set_last_observation(model, obs: np.ndarray) -> None:
    """The observation the next rollout starts from, every env at an episode start."""
    model._last_obs = obs
    model._last_episode_starts = np.ones(len(obs), dtype=bool)


def tensorboard_output(folder: str, purge_step: int | None = None):
    """SB3's TensorBoard writer; with ``purge_step``, TensorBoard hides the events at or after
    that step from earlier event files (those a killed run logged after the checkpoint it is
    resumed from). SB3's constructor takes no ``purge_step``, so the writer is set up here."""
    from stable_baselines3.common.logger import TensorBoardOutputFormat
    from torch.utils.tensorboard import SummaryWriter

    if purge_step is None:
        return TensorBoardOutputFormat(folder)
    output = TensorBoardOutputFormat.__new__(TensorBoardOutputFormat)
    output.writer = SummaryWriter(log_dir=folder, purge_step=purge_step)
    output._is_closed = False
    return output


def drop_queued_seeds(vec_env) -> None:
    """Forget the seeds SB3 queued for the envs' next reset (``VecEnv.seed``, and a model's
    load), so the envs continue their own restored generators."""
    vec_env._reset_seeds()


def resize_rollout_buffer(model, n_steps: int, buffer_class: type | None = None) -> None:
    """A new rollout buffer of ``n_steps`` per env (RecurrentPPO sizes it once, at set-up), of
    ``buffer_class`` (default: the model's current buffer's class)."""
    model.n_steps = n_steps
    buffer, lstm = model.rollout_buffer, model.policy.lstm_actor
    model.rollout_buffer = (buffer_class or type(buffer))(
        n_steps, model.observation_space, model.action_space,
        (n_steps, lstm.num_layers, model.n_envs, lstm.hidden_size), model.device,
        gamma=model.gamma, gae_lambda=model.gae_lambda, n_envs=model.n_envs)
