"""The run's settings: each field of a settings dataclass declared once with its default and
its reader (how a written value is checked and read), so a config is read by one generic
function (:func:`read_settings`) and every error names the key path and what is allowed.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import MISSING, dataclass, field, fields
from typing import Any

from myo_sds.curricula.yaml_reader import YamlReader

ACTIVATIONS = ("relu", "tanh", "elu", "leaky_relu")
VEC_ENVS = ("thread", "dummy", "subproc")
ROLLOUT_BACKENDS = ("local", "ray")
EXPLORATIONS = ("gaussian", "lattice")

# -- declaring a setting: its default and how a written value is checked and read ----------

Read = Callable[[YamlReader, str, Any], Any]  # (reader, key path, value as written) -> typed value


def setting(default: Any = MISSING, read: Read | None = None, **kwargs: Any):
    """A config field with its reader (``read(reader, key, value)``), declared once."""
    return field(default=default, metadata={"read": read}, **kwargs)


def integer(low: int) -> Read:
    return lambda reader, key, value: reader.number(key, value, integer=True, low=low)


def number(low: float | None = None, high: float | None = None, strict_low: bool = False) -> Read:
    return lambda reader, key, value: reader.number(key, value, low=low, high=high, strict_low=strict_low)


def one_of(*allowed: str) -> Read:
    return lambda reader, key, value: reader.choice(key, value, allowed)


def boolean(reader: YamlReader, key: str, value: Any) -> bool:
    return reader.boolean(key, value)


def optional(read: Read) -> Read:
    """``null`` (None) or what ``read`` reads."""
    return lambda reader, key, value: None if value is None else read(reader, key, value)


def layers(reader: YamlReader, key: str, value: Any) -> tuple[int, ...]:
    # []: the LSTMs feed the action and value heads directly (the 2022 phase-1 network).
    if not isinstance(value, (list, tuple)):
        raise reader.error(key, f"expected a list of layer sizes ([] for none), got {value!r}")
    return tuple(reader.number(f"{key}[{i}]", v, integer=True, low=1) for i, v in enumerate(value))


def learning_rate(reader: YamlReader, key: str, value: Any) -> LearningRate:
    if isinstance(value, Mapping):
        return _learning_rate_decay(reader, key, value)
    return reader.number(key, value, low=0, strict_low=True)


@dataclass(frozen=True)
class LearningRateDecay:
    """A learning rate that falls log-linearly from ``start`` to ``end`` over ``steps`` env
    steps, then stays at ``end``. Its clock starts where it is set: the run's first step for
    the run config's ``ppo``, the stage's first step for a stage's ``ppo``.

    YAML: ``learning_rate: {start: 3.0e-3, end: 1.0e-4, steps: 1500000}``.
    """

    start: float
    end: float
    steps: int

    def at(self, elapsed_steps: int) -> float:
        """The learning rate ``elapsed_steps`` env steps after the clock started."""
        fraction = min(max(elapsed_steps / self.steps, 0.0), 1.0)
        return self.start * (self.end / self.start) ** fraction


LearningRate = float | LearningRateDecay


@dataclass(frozen=True)
class PolicyConfig:
    lstm_hidden_size: int = setting(256, integer(low=1))
    enable_critic_lstm: bool = setting(True, boolean)
    net_arch: tuple[int, ...] = setting((256, 256), layers)
    activation: str = setting("relu", one_of(*ACTIVATIONS))
    log_std_init: float = setting(-2.0, number())
    ortho_init: bool = setting(True, boolean)
    # One LSTM call per sequence in updates (same function, faster); false: sb3-contrib's
    # step-by-step loop, kept to reproduce the reference setup's speed.
    fast_lstm_update: bool = setting(True, boolean)
    # Soft bound on the Gaussian's mean, bound * tanh(mean / bound) (myo_sds/policy.py);
    # 0: unbounded, as in sb3-contrib. Needs fast_lstm_update.
    action_mean_bound: float = setting(0.0, number(low=0))
    # The actor's output layer learns this many times as fast as the rest (> 0; through a
    # reparametrization, myo_sds/policy.py). Needs fast_lstm_update.
    action_head_lr_scale: float = setting(1.0, number(low=0, strict_low=True))
    # gaussian: independent noise on each muscle (sb3-contrib's); lattice: noise in the latent
    # state, correlated across muscles and state-dependent (myo_sds/lattice.py). Needs fast_lstm_update.
    exploration: str = setting("gaussian", one_of(*EXPLORATIONS))
    lattice_alpha: float = setting(1.0, number(low=0))  # weight of the latent noise (0: action noise only)
    lattice_std_reg: float = setting(0.0, number(low=0))  # extra independent action std
    lattice_full_std: bool = setting(False, boolean)  # one std per noise-matrix entry, not per latent feature
    noise_resample_every: int = setting(1, integer(low=1))  # control steps between Lattice noise draws


@dataclass(frozen=True)
class PpoWarmup:
    """More gradient work per sample for the run's first ``steps`` env steps: shorter rollouts
    (more frequent updates), smaller minibatches and/or more epochs while the policy is new,
    then the run's (and stages') own settings. None: keep the value the run would otherwise use.

    YAML, under ``ppo``: ``warmup: {steps: 150000, n_steps: 16, batch_size: 128, n_epochs: 10}``.
    """

    steps: int = 0
    n_steps: int | None = None
    batch_size: int | None = None
    n_epochs: int | None = None

    def active(self, step: int) -> bool:
        return step < self.steps


@dataclass(frozen=True)
class PpoConfig:
    """sb3-contrib RecurrentPPO hyper-parameters; defaults are the 2022 Baoding winner's."""

    learning_rate: LearningRate = setting(2.56e-5, learning_rate)
    n_steps: int = setting(128, integer(low=1))
    batch_size: int = setting(32, integer(low=1))
    n_epochs: int = setting(10, integer(low=1))
    gamma: float = setting(0.99, number(low=0, high=1))
    gae_lambda: float = setting(0.9, number(low=0, high=1))
    clip_range: float = setting(0.3, number(low=0, strict_low=True))
    ent_coef: float = setting(3.6e-6, number(low=0))
    vf_coef: float = setting(0.84, number(low=0))
    max_grad_norm: float = setting(0.7, number(low=0, strict_low=True))
    # SB3's early stop: an update ends its epochs at the first minibatch whose approximate KL
    # from the rollout's policy exceeds 1.5 x this. None: all n_epochs always run.
    target_kl: float | None = setting(None, optional(number(low=0, strict_low=True)))
    warmup: PpoWarmup = setting(PpoWarmup(), lambda reader, key, value: _ppo_warmup(reader, key, value))


@dataclass(frozen=True)
class NormalizeConfig:
    """SB3's VecNormalize: running statistics of observations and discounted returns, one
    instance for the whole run (its statistics carry across stages and are checkpointed)."""

    observations: bool = setting(True, boolean)
    rewards: bool = setting(True, boolean)
    clip_obs: float = setting(10.0, number(low=0, strict_low=True))  # normalized observations are clipped to +-this
    clip_reward: float = setting(10.0, number(low=0, strict_low=True))  # normalized rewards likewise


@dataclass(frozen=True)
class RolloutConfig:
    """Where rollouts are collected. ``local``: the envs of the training process. ``ray``:
    ``workers`` Ray actors, each stepping ``envs_per_worker`` envs with a copy of the policy
    (``n_envs`` is then workers x envs_per_worker); ``address``: the cluster to join (``auto``:
    the one started with ``ray start``; null: a cluster of this machine only)."""

    backend: str = setting("local", one_of(*ROLLOUT_BACKENDS))
    workers: int = setting(2, integer(low=1))
    envs_per_worker: int | None = setting(None, optional(integer(low=1)))  # None: n_envs / workers
    address: str | None = setting(None, optional(lambda reader, key, value: reader.string(key, value)))
    max_restarts: int = setting(3, integer(low=0))  # a worker that dies more often than this in a row stops the run


def read_settings(reader: YamlReader, key: str, raw: Any, cls: type) -> Any:
    """A settings dataclass from a mapping: each written value read by its field's reader, the
    others at their defaults."""
    declared = {f.name: f for f in fields(cls)}
    raw = reader.mapping(key, raw, tuple(declared))
    return cls(**{name: declared[name].metadata["read"](reader, f"{key}.{name}", value) for name, value in raw.items()})


def _learning_rate_decay(reader: YamlReader, key: str, raw: Mapping[str, Any]) -> LearningRateDecay:
    names = tuple(f.name for f in fields(LearningRateDecay))
    reader.mapping(key, raw, names)
    missing = [name for name in names if name not in raw]
    if missing:
        raise reader.error(key, f"a learning-rate decay needs {', '.join(names)}; missing: {', '.join(missing)}")
    return LearningRateDecay(
        start=reader.number(f"{key}.start", raw["start"], low=0, strict_low=True),
        end=reader.number(f"{key}.end", raw["end"], low=0, strict_low=True),
        steps=reader.number(f"{key}.steps", raw["steps"], integer=True, low=1))


def _ppo_warmup(reader: YamlReader, key: str, raw: Any) -> PpoWarmup:
    names = tuple(f.name for f in fields(PpoWarmup))
    raw = reader.mapping(key, raw, names)
    if not raw:
        return PpoWarmup()
    if "steps" not in raw:
        raise reader.error(key, "a warm-up needs steps: how many env steps from the run's start it lasts")
    values = {name: reader.number(f"{key}.{name}", raw[name], integer=True, low=0 if name == "steps" else 1)
              for name in names if raw.get(name) is not None}
    return PpoWarmup(**values)
