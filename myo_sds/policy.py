"""RecurrentPPO's LSTM policy with a whole-sequence LSTM pass during updates.

sb3-contrib runs the LSTM one time step at a time in Python whenever a sequence of a
minibatch contains an episode start (sb3-contrib issue #113), which is almost always, since
its rollout buffer cuts sequences at episode starts. A start can then only be a sequence's
first step: resetting those sequences' initial states and running the LSTM once over the whole
sequence computes the same function, several times faster. Anything else falls back to the
step-by-step loop.

``action_mean_bound`` (off by default, as in sb3-contrib) replaces the Gaussian's mean by
``bound * tanh(mean / bound)``, so it stays within +-bound. The action space is [-1, 1] and the env clips actions, so a
mean beyond the bounds gets no gradient from the returns and can drift: trained policies reach
means of 100+ on a few muscles, where a small relative change is a huge step in log-probability
(PPO's approximate KL reads 1e4-1e6). Near zero the map is the identity, so a new policy acts
as before.

``action_head_lr_scale`` (1 by default) computes the mean as ``scale * action_net(latent)``
with ``action_net``'s initial parameters divided by ``scale``: the same initial policy, but
since Adam moves each parameter by about the learning rate whatever its gradient's size, the
output layer of the actor learns ``scale`` times as fast as the rest.

``log_std_min`` (none by default) is a floor on the Gaussian's log standard deviation, as mjrl's
``min_log_std`` (PKU-MARL's 2022 die policy never explored with a std below 0.37): the
distribution reads ``max(log_std, floor)``, and after every optimizer step the parameter is set
back to the floor where it fell below, so that a gradient toward more noise acts at once. With
Lattice the floor bounds each muscle's independent variance (:class:`~myo_sds.lattice.LatticeNoise`).

``memory: "none"`` makes the LSTMs pass the observation through unchanged (their states stay
zero and their parameters unused), so the layers after them read the observation itself: a
feed-forward actor and critic in the same training and evaluation code.
"""

from __future__ import annotations

import json
import math
import zipfile
from pathlib import Path
from typing import Any

import torch as th
from sb3_contrib.common.recurrent.policies import RecurrentActorCriticPolicy


class SequenceLstmPolicy(RecurrentActorCriticPolicy):
    """``MlpLstmPolicy`` (same networks, same parameters) with the whole-sequence fast path,
    an optional soft bound on the action mean and an optional learning-rate scale for the
    actor's output layer."""

    def __init__(self, *args, action_mean_bound: float = 0.0, action_head_lr_scale: float = 1.0,
                 actor_observation_size: int | None = None, log_std_min: float | None = None,
                 memory: str = "lstm", **kwargs):
        if memory not in ("lstm", "none"):
            raise ValueError(f"memory: {memory!r} is not one of lstm, none")
        self.action_mean_bound = action_mean_bound
        self.action_head_lr_scale = action_head_lr_scale
        self.actor_observation_size = actor_observation_size
        self.log_std_min = log_std_min
        self.memory = memory
        super().__init__(*args, **kwargs)
        if memory == "none" and self.lstm_output_dim != self.features_dim:
            raise ValueError(f"memory: none passes the observation through: lstm_hidden_size must be its size "
                             f"{self.features_dim}, got {self.lstm_output_dim}")
        with th.no_grad():  # the same initial function as without the scale
            self.action_net.weight.div_(action_head_lr_scale)
            self.action_net.bias.div_(action_head_lr_scale)
        if actor_observation_size is not None and actor_observation_size != self.features_dim:
            # A privileged critic: the actor's LSTM reads the official observation (the first
            # ``actor_observation_size`` values), the critic all of it.
            if self.shared_lstm or self.features_dim < actor_observation_size:
                raise ValueError(f"actor_observation_size {actor_observation_size} needs separate LSTMs and at "
                                 f"most the observation's {self.features_dim} values")
            lstm = self.lstm_actor
            self.lstm_actor = th.nn.LSTM(actor_observation_size, lstm.hidden_size, num_layers=lstm.num_layers,
                                         **self.lstm_kwargs)
            self.optimizer = self.optimizer_class(self.parameters(), lr=self.optimizer.defaults["lr"],
                                                  **self.optimizer_kwargs)
        self._hold_noise_floor()

    def _hold_noise_floor(self) -> None:
        """With a Gaussian floor: the parameter at or above it now and after every optimizer step."""
        if self.log_std_min is None or self.use_sde:
            return
        self._floor_log_std()
        self.optimizer.register_step_post_hook(self._floor_log_std)

    def _floor_log_std(self, *_hook_args) -> None:
        with th.no_grad():
            self.log_std.clamp_(min=self.log_std_min)

    def load_state_dict(self, state_dict, strict: bool = True, assign: bool = False):
        result = super().load_state_dict(state_dict, strict=strict, assign=assign)
        if self.log_std_min is not None and not self.use_sde:
            self._floor_log_std()  # a policy trained without the floor starts at it
        return result

    def _get_constructor_parameters(self) -> dict:
        return {**super()._get_constructor_parameters(), "action_mean_bound": self.action_mean_bound,
                "action_head_lr_scale": self.action_head_lr_scale,
                "actor_observation_size": self.actor_observation_size, "log_std_min": self.log_std_min,
                "memory": self.memory}

    def _get_action_dist_from_latent(self, latent_pi: th.Tensor):
        gaussian_floor = self.log_std_min is not None and not self.use_sde
        if not self.action_mean_bound and self.action_head_lr_scale == 1.0 and not gaussian_floor:
            return super()._get_action_dist_from_latent(latent_pi)
        mean_actions = self.action_net(latent_pi) * self.action_head_lr_scale
        if self.action_mean_bound:
            bound = self.action_mean_bound
            mean_actions = bound * th.tanh(mean_actions / bound)
        log_std = self.log_std.clamp(min=self.log_std_min) if gaussian_floor else self.log_std
        return self.action_dist.proba_distribution(mean_actions, log_std)

    def _process_sequence(self, features: th.Tensor, lstm_states: tuple[th.Tensor, th.Tensor],
                          episode_starts: th.Tensor, lstm: th.nn.LSTM) -> tuple[th.Tensor, th.Tensor]:
        if features.shape[-1] != lstm.input_size:  # the actor of a privileged critic: the official part
            features = features[..., :lstm.input_size]
        if self.memory == "none":
            return features, lstm_states
        return self.sequence_pass(features, lstm_states, episode_starts, lstm)

    @staticmethod
    def sequence_pass(features: th.Tensor, lstm_states: tuple[th.Tensor, th.Tensor],
                      episode_starts: th.Tensor, lstm: th.nn.LSTM) -> tuple[th.Tensor, th.Tensor]:
        """sb3-contrib's ``_process_sequence``, over the whole sequence at once where it can."""
        n_seq = lstm_states[0].shape[1]
        starts = episode_starts.reshape((n_seq, -1)).swapaxes(0, 1)  # (length, n_seq)
        if not th.all(starts[1:] == 0.0):
            return RecurrentActorCriticPolicy._process_sequence(features, lstm_states, episode_starts, lstm)
        features_sequence = features.reshape((n_seq, -1, lstm.input_size)).swapaxes(0, 1)
        keep = (1.0 - starts[0]).view(1, n_seq, 1)
        output, lstm_states = lstm(features_sequence, (keep * lstm_states[0], keep * lstm_states[1]))
        return th.flatten(output.transpose(0, 1), start_dim=0, end_dim=1), lstm_states


class LatticeLstmPolicy(SequenceLstmPolicy):
    """:class:`SequenceLstmPolicy` exploring with Lattice (:mod:`myo_sds.lattice`): the same
    networks, with the action distribution and its ``log_std`` replaced. Built with
    ``use_sde=True`` (RecurrentPPO then redraws the noise matrices every ``sde_sample_freq``
    steps); the mean is ``action_net(latent)`` as for the Gaussian policy."""

    def __init__(self, observation_space, action_space, lr_schedule, *args, lattice_alpha: float = 1.0,
                 lattice_std_reg: float = 0.0, lattice_std_clip: tuple[float, float] = (1e-3, 10.0), **kwargs):
        from stable_baselines3.common.preprocessing import get_action_dim

        from myo_sds.lattice import LatticeNoise

        self.lattice_alpha, self.lattice_std_reg = lattice_alpha, lattice_std_reg
        self.lattice_std_clip = tuple(lattice_std_clip)
        kwargs.setdefault("use_expln", True)
        kwargs.setdefault("full_std", False)
        super().__init__(observation_space, action_space, lr_schedule, *args, **kwargs)
        if not self.use_sde:
            raise ValueError("LatticeLstmPolicy needs use_sde=True (RecurrentPPO(..., use_sde=True))")
        self.action_dist = LatticeNoise(get_action_dim(action_space), full_std=self.dist_kwargs["full_std"],
                                        use_expln=self.dist_kwargs["use_expln"], alpha=lattice_alpha,
                                        std_clip=self.lattice_std_clip, std_reg=lattice_std_reg,
                                        min_action_std=None if self.log_std_min is None else math.exp(self.log_std_min))
        self._build(lr_schedule)  # the action layer and log_std of the Lattice distribution, a new optimizer

    def _get_constructor_parameters(self) -> dict:
        return {**super()._get_constructor_parameters(), "lattice_alpha": self.lattice_alpha,
                "lattice_std_reg": self.lattice_std_reg, "lattice_std_clip": self.lattice_std_clip}


# Module paths the policy class was saved under: checkpoints pickle it by reference.
POLICY_MODULES = ("myo_sds.policy", "curricula.policy")


def load_model(path: str | Path, **kwargs: Any):
    """``RecurrentPPO.load`` that also reads checkpoints saved before the policy class moved:
    where the archive names :class:`SequenceLstmPolicy` under an older module path, the class
    is handed to SB3 instead of unpickled. An archive saved by SB3 1.x under gym (a published
    2022 policy) loads as a :class:`SequenceLstmPolicy` of the same parameters."""
    from sb3_contrib import RecurrentPPO

    from myo_sds.published import load_gym_era_model, saved_with_gym

    if saved_with_gym(Path(path)):
        return load_gym_era_model(Path(path), SequenceLstmPolicy, device=kwargs.get("device", "cpu"))

    custom_objects = dict(kwargs.pop("custom_objects", None) or {})
    try:
        with zipfile.ZipFile(path) as archive:
            saved = json.loads(archive.read("data")).get("policy_class", {})
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        saved = {}  # RecurrentPPO.load reports an unreadable archive itself
    if isinstance(saved, dict) and saved.get("__module__") in POLICY_MODULES:
        lattice = "Lattice" in str(saved.get("__init__", "")) or "Lattice" in str(saved.get(":serialized:", ""))
        custom_objects.setdefault("policy_class", LatticeLstmPolicy if lattice else SequenceLstmPolicy)
    return RecurrentPPO.load(path, custom_objects=custom_objects, **kwargs)
