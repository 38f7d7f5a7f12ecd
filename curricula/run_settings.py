"""The run config's settings: the run's top level, the policy network, PPO, observation and
reward normalization, and where rollouts run (locally or on Ray). Each field is declared once
with :func:`~myo_sds.envs.declare.setting` (default, parser, meaning); ``curricula.schema`` reads a
run config through them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import MISSING, dataclass
from pathlib import Path
from typing import Any

from myo_sds.envs.declare import boolean, integer, number, one_of, optional, parse_settings, setting, text

ACTIVATIONS = ("relu", "tanh", "elu", "leaky_relu")
VEC_ENVS = ("thread", "dummy", "subproc")
DEVICES = ("cpu", "cuda", "auto")
ROLLOUT_BACKENDS = ("local", "ray")
EXPLORATIONS = ("gaussian", "lattice")
MEMORIES = ("lstm", "none")


_positive_rate = number(low=0, strict_low=True)


@dataclass(frozen=True)
class LearningRateDecay:
    """A learning rate that falls log-linearly from ``start`` to ``end`` over ``steps`` env
    steps, then stays at ``end``. Its clock starts where it is set: the run's first step for
    the run config's ``ppo``, the stage's first step for a stage's ``ppo``.

    YAML: ``learning_rate: {start: 3.0e-3, end: 1.0e-4, steps: 1500000}``.
    """

    start: float = setting(MISSING, parse=_positive_rate, help="the rate at the clock's start")
    end: float = setting(MISSING, parse=_positive_rate, help="the rate from `steps` on")
    steps: int = setting(MISSING, parse=integer(low=1), help="env steps from start to end")

    def at(self, elapsed_steps: int) -> float:
        """The learning rate ``elapsed_steps`` env steps after the clock started."""
        fraction = min(max(elapsed_steps / self.steps, 0.0), 1.0)
        return self.start * (self.end / self.start) ** fraction


LearningRate = float | LearningRateDecay


def learning_rate(name: str, value: Any) -> LearningRate:
    """A rate (> 0) or ``{start, end, steps}``: a log-linear decay over env steps."""
    if not isinstance(value, Mapping):
        return _positive_rate(name, value)
    return parse_settings(name, value, LearningRateDecay)


def names(name: str, value: Any) -> tuple[str, ...]:
    if value is None:
        return ()
    if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) and v for v in value):
        raise ValueError(f"{name}: expected a list of names, got {value!r}")
    if len(set(value)) != len(value):
        raise ValueError(f"{name}: a name is listed twice in {list(value)!r}")
    return tuple(value)


def layers(name: str, value: Any) -> tuple[int, ...]:
    # []: the LSTMs feed the action and value heads directly (the 2022 phase-1 network).
    if not isinstance(value, (list, tuple)):
        raise ValueError(f"{name}: expected a list of layer sizes ([] for none), got {value!r}")
    return tuple(integer(low=1)(f"{name}[{i}]", v) for i, v in enumerate(value))


@dataclass(frozen=True)
class RunSettings:
    """The run config's top level (besides ``curriculum`` and the sections below)."""

    seed: int = setting(0, parse=integer(low=0), help="seeds the envs, the policy and the minibatch order")
    n_envs: int = setting(4, parse=integer(low=1), help="envs stepped in parallel")
    vec_env: str = setting("thread", parse=one_of(*VEC_ENVS),
                           help="thread (envs on a thread pool in this process) | dummy | subproc")
    env_threads: int = setting(0, parse=integer(low=0), help="threads stepping envs (vec_env: thread); 0: one per CPU")
    device: str = setting("cpu", parse=one_of(*DEVICES), help="where the policy trains")
    num_threads: int = setting(0, parse=integer(low=0), help="torch threads for updates; 0: follow the free CPUs")
    total_steps: int = setting(1_000_000, parse=integer(low=1), help="env steps of the whole run")
    checkpoint_every: int = setting(50_000, parse=integer(low=1), help="env steps between checkpoints")
    keep_checkpoints: int = setting(3, parse=integer(low=1), help="newest checkpoints kept")
    init_from: Path | None = setting(None, parse=optional(lambda name, value: Path(text(name, value))),
                                     help="a trained policy to start from (model or run folder, or a checkpoint "
                                          ".zip; relative to the file that names it): fine-tuning, as --init-from")
    output_dir: Path = setting(Path("runs"), parse=lambda name, value: Path(text(name, value)),
                               help="where new run folders are made")


@dataclass(frozen=True)
class PolicyConfig:
    """The policy network and its exploration."""

    lstm_hidden_size: int = setting(256, parse=integer(low=1), help="units of each LSTM")
    enable_critic_lstm: bool = setting(True, parse=boolean, help="a separate LSTM for the critic")
    net_arch: tuple[int, ...] = setting((256, 256), parse=layers, help="layers after each LSTM ([]: none)")
    critic_net_arch: tuple[int, ...] | None = setting(
        None, parse=optional(layers), help="the critic's layers, where they differ from net_arch (null: net_arch)")
    memory: str = setting(
        "lstm", parse=one_of(*MEMORIES),
        help="lstm | none: no LSTM, the layers read the observation itself (a feed-forward policy and critic, "
             "as PKU-MARL's 2022 die MLP; lstm_hidden_size is then ignored; needs fast_lstm_update)")
    activation: str = setting("relu", parse=one_of(*ACTIVATIONS), help="activation of those layers")
    log_std_init: float = setting(-2.0, parse=number(), help="initial log standard deviation of the action noise")
    log_std_min: float | None = setting(
        None, parse=optional(number()),
        help="floor of the action noise's log standard deviation (null: none): Gaussian, each muscle's std never "
             "falls below exp(floor) (the parameter is held at the floor after every update, as mjrl's "
             "min_log_std); Lattice, each muscle's independent part likewise (needs fast_lstm_update)")
    ortho_init: bool = setting(True, parse=boolean, help="orthogonal initialization of the networks")
    fast_lstm_update: bool = setting(
        True, parse=boolean, help="one LSTM call per sequence in updates (same function, faster); false: "
                                  "sb3-contrib's step-by-step loop, kept to reproduce the reference setup's speed")
    action_mean_bound: float = setting(
        0.0, parse=number(low=0), help="soft bound on the Gaussian's mean, bound * tanh(mean / bound); 0: unbounded "
                                       "(needs fast_lstm_update)")
    action_head_lr_scale: float = setting(
        1.0, parse=number(low=0, strict_low=True),
        help="the actor's output layer learns this many times as fast as the rest (needs fast_lstm_update)")
    exploration: str = setting(
        "gaussian", parse=one_of(*EXPLORATIONS),
        help="gaussian: independent noise on each muscle; lattice: noise in the latent state, correlated across "
             "muscles and state-dependent (myo_sds/lattice.py; needs fast_lstm_update)")
    lattice_alpha: float = setting(1.0, parse=number(low=0), help="weight of Lattice's latent noise (0: action noise only)")
    lattice_std_reg: float = setting(0.0, parse=number(low=0), help="extra independent action std (Lattice)")
    lattice_full_std: bool = setting(False, parse=boolean,
                                     help="one std per noise-matrix entry, not per latent feature (Lattice)")
    noise_resample_every: int = setting(1, parse=integer(low=1), help="control steps between Lattice noise draws")
    critic_extra: tuple[str, ...] = setting(
        (), parse=lambda name, value: names(name, value),
        help="privileged features only the critic sees in training, by name (the task's: e.g. die_velocity, "
             "fingertips, physics); the actor, exported policies and evaluate.py see the official observation")

    def __post_init__(self) -> None:  # rules between the fields (parse_settings names the key)
        fast_only = {"action_mean_bound": 0.0, "action_head_lr_scale": 1.0, "exploration": "gaussian",
                     "critic_extra": (), "log_std_min": None, "memory": "lstm"}
        for key, default in fast_only.items():
            if getattr(self, key) != default and not self.fast_lstm_update:
                raise ValueError(f"{key}: needs policy.fast_lstm_update: true (it lives in the fast policy class)")
        if self.exploration == "lattice":
            for key in ("action_mean_bound", "action_head_lr_scale"):
                if getattr(self, key) != fast_only[key]:
                    raise ValueError(f"{key}: applies to the Gaussian policy's mean only; with exploration: lattice "
                                     "leave it at its default")
        if self.log_std_min is not None and self.log_std_init < self.log_std_min:
            raise ValueError(f"log_std_min: {self.log_std_min} is above log_std_init {self.log_std_init}; the noise "
                             "would start below its floor")
        if self.memory == "none" and self.critic_extra:
            raise ValueError("critic_extra: needs memory: lstm (the actor and critic then read different inputs)")
        if self.memory == "none" and not self.enable_critic_lstm:
            raise ValueError("enable_critic_lstm: memory: none passes the observation to the critic's layers through "
                             "the critic's own (unused) LSTM; leave it true")


@dataclass(frozen=True)
class PpoWarmup:
    """More gradient work per sample for the run's first ``steps`` env steps: shorter rollouts
    (more frequent updates), smaller minibatches and/or more epochs while the policy is new,
    then the run's (and stages') own settings. None: keep the value the run would otherwise use.

    YAML, under ``ppo``: ``warmup: {steps: 150000, n_steps: 16, batch_size: 128, n_epochs: 10}``.
    """

    steps: int = setting(0, parse=integer(low=0), help="how many env steps from the run's start it lasts")
    n_steps: int | None = setting(None, parse=optional(integer(low=1)), help="rollout steps per env meanwhile")
    batch_size: int | None = setting(None, parse=optional(integer(low=1)), help="samples per minibatch meanwhile")
    n_epochs: int | None = setting(None, parse=optional(integer(low=1)), help="passes over each rollout meanwhile")

    def active(self, step: int) -> bool:
        return step < self.steps


def ppo_warmup(name: str, value: Any) -> PpoWarmup:
    if value is None or value == {}:
        return PpoWarmup()
    if isinstance(value, Mapping) and "steps" not in value:
        raise ValueError(f"{name}: a warm-up needs steps: how many env steps from the run's start it lasts")
    return parse_settings(name, value, PpoWarmup)


@dataclass(frozen=True)
class PpoConfig:
    """sb3-contrib RecurrentPPO hyper-parameters; defaults are the 2022 Baoding winner's."""

    learning_rate: LearningRate = setting(2.56e-5, parse=learning_rate, help="a rate, or {start, end, steps}")
    n_steps: int = setting(128, parse=integer(low=1), help="rollout steps per env between updates")
    batch_size: int = setting(32, parse=integer(low=1), help="samples per minibatch")
    n_epochs: int = setting(10, parse=integer(low=1), help="passes over each rollout")
    gamma: float = setting(0.99, parse=number(low=0, high=1), help="discount")
    gae_lambda: float = setting(0.9, parse=number(low=0, high=1), help="GAE's lambda")
    clip_range: float = setting(0.3, parse=number(low=0, strict_low=True), help="PPO's clip range")
    ent_coef: float = setting(3.6e-6, parse=number(low=0), help="entropy bonus")
    vf_coef: float = setting(0.84, parse=number(low=0), help="value loss weight")
    max_grad_norm: float = setting(0.7, parse=number(low=0, strict_low=True), help="gradient norm clip")
    target_kl: float | None = setting(
        None, parse=optional(number(low=0, strict_low=True)),
        help="SB3's early stop: an update ends its epochs at the first minibatch whose approximate KL from the "
             "rollout's policy exceeds 1.5 x this; null: all n_epochs always run")
    sequence_length: int | None = setting(
        None, parse=optional(integer(low=1)),
        help="null: the update's LSTM sequences run to an episode's or minibatch's end (sb3-contrib's); N: they "
             "are also cut every N steps, each piece starting from the LSTM state the rollout had there (the same "
             "values, gradients truncated at the cuts; far less padding where episode lengths differ; needs "
             "fast_lstm_update)")
    warmup: PpoWarmup = setting(PpoWarmup(), parse=ppo_warmup, help="{steps, n_steps, batch_size, n_epochs}")


# The PPO settings a curriculum stage may change (from its start until a later stage changes them).
STAGE_PPO_SETTINGS = ("learning_rate", "n_steps", "batch_size", "n_epochs", "clip_range", "ent_coef", "target_kl",
                      "sequence_length")


@dataclass(frozen=True)
class NormalizeConfig:
    """SB3's VecNormalize: running statistics of observations and discounted returns, one
    instance for the whole run (its statistics carry across stages and are checkpointed)."""

    observations: bool = setting(True, parse=boolean, help="normalize observations")
    rewards: bool = setting(True, parse=boolean, help="normalize rewards by the discounted return's scale")
    clip_obs: float = setting(10.0, parse=number(low=0, strict_low=True), help="normalized observations clipped to +-this")
    clip_reward: float = setting(10.0, parse=number(low=0, strict_low=True), help="normalized rewards likewise")


@dataclass(frozen=True)
class RolloutConfig:
    """Where rollouts are collected. ``local``: the envs of the training process. ``ray``:
    ``workers`` Ray actors, each stepping ``envs_per_worker`` envs with a copy of the policy
    (``n_envs`` is then workers x envs_per_worker); ``address``: the cluster to join (``auto``:
    the one started with ``ray start``; null: a cluster of this machine only)."""

    backend: str = setting("local", parse=one_of(*ROLLOUT_BACKENDS), help="local | ray")
    workers: int = setting(2, parse=integer(low=1), help="Ray workers (one CPU each)")
    envs_per_worker: int | None = setting(None, parse=optional(integer(low=1)), help="null: n_envs / workers")
    address: str | None = setting(None, parse=optional(text), help="the Ray cluster: auto, an address, or null")
    max_restarts: int = setting(3, parse=integer(low=0),
                                help="a worker that dies more often than this in a row stops the run")
