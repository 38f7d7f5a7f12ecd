"""Curriculum files and run configs: YAML in, validated typed objects out.

Every problem is reported once, before training starts, as a :class:`ConfigError` naming the
file, the key path (``stages[2].advance.threshold``), the bad value and what is allowed.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import yaml

from myo_sds.curricula.yaml_reader import ConfigError, YamlReader, load_yaml
from myo_sds.envs.knobs import TaskKnobs
from myo_sds.envs.task_specs import TASK_SPECS

METRICS = ("score", "survival")
ON_MAX_STEPS = ("advance", "stop")


@dataclass(frozen=True)
class AdvanceRule:
    """When a stage is passed: the mean ``metric`` over the last ``window`` training
    episodes of the stage reaches ``threshold``, after at least ``min_steps`` env steps.
    After ``max_steps`` the stage ends unpassed and the run advances or stops."""

    metric: str = "score"
    threshold: float = 0.5
    window: int = 100
    min_steps: int = 0
    max_steps: int | None = None
    on_max_steps: str = "advance"


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
class PpoOverrides:
    """PPO settings a stage changes at its start (None: keep the current value)."""

    learning_rate: LearningRate | None = None
    n_steps: int | None = None
    batch_size: int | None = None
    clip_range: float | None = None
    ent_coef: float | None = None

    def as_dict(self) -> dict[str, float | int]:
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}


@dataclass(frozen=True)
class Stage:
    name: str
    env: Mapping[str, Any]  # the knobs as the curriculum writes them (defaults merged in)
    distribution: TaskKnobs  # the same, checked and read once: what every env of the stage gets
    advance: AdvanceRule | None  # None: train on this stage until the step budget ends
    ppo: PpoOverrides = PpoOverrides()


@dataclass(frozen=True)
class Curriculum:
    name: str
    task: str
    stages: tuple[Stage, ...]
    path: Path | None = None

    def stage_index(self, name: str) -> int:
        for index, stage in enumerate(self.stages):
            if stage.name == name:
                return index
        raise KeyError(f"no stage named {name!r} in curriculum {self.name!r}; "
                       f"stages: {', '.join(s.name for s in self.stages)}")


@dataclass(frozen=True)
class PolicyConfig:
    lstm_hidden_size: int = 256
    enable_critic_lstm: bool = True
    net_arch: tuple[int, ...] = (256, 256)
    activation: str = "relu"
    log_std_init: float = -2.0
    ortho_init: bool = True
    # One LSTM call per sequence in updates (same function, faster); false: sb3-contrib's
    # step-by-step loop, kept to reproduce the reference setup's speed.
    fast_lstm_update: bool = True
    # Soft bound on the Gaussian's mean, bound * tanh(mean / bound) (myo_sds/policy.py);
    # 0: unbounded, as in sb3-contrib. Needs fast_lstm_update.
    action_mean_bound: float = 0.0
    # The actor's output layer learns this many times as fast as the rest (> 0; through a
    # reparametrization, myo_sds/policy.py). Needs fast_lstm_update.
    action_head_lr_scale: float = 1.0


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

    learning_rate: LearningRate = 2.56e-5
    n_steps: int = 128
    batch_size: int = 32
    n_epochs: int = 10
    gamma: float = 0.99
    gae_lambda: float = 0.9
    clip_range: float = 0.3
    ent_coef: float = 3.6e-6
    vf_coef: float = 0.84
    max_grad_norm: float = 0.7
    warmup: PpoWarmup = PpoWarmup()


@dataclass(frozen=True)
class NormalizeConfig:
    """SB3's VecNormalize: running statistics of observations and discounted returns, one
    instance for the whole run (its statistics carry across stages and are checkpointed)."""

    observations: bool = True
    rewards: bool = True
    clip_obs: float = 10.0  # normalized observations are clipped to +-this
    clip_reward: float = 10.0  # normalized rewards likewise


@dataclass(frozen=True)
class RolloutConfig:
    """Where rollouts are collected. ``local``: the envs of the training process. ``ray``:
    ``workers`` Ray actors, each stepping ``envs_per_worker`` envs with a copy of the policy
    (``n_envs`` is then workers x envs_per_worker); ``address``: the cluster to join (``auto``:
    the one started with ``ray start``; null: a cluster of this machine only)."""

    backend: str = "local"
    workers: int = 2
    envs_per_worker: int | None = None  # None: n_envs / workers
    address: str | None = None
    max_restarts: int = 3  # a worker that dies more often than this in a row stops the run


ROLLOUT_BACKENDS = ("local", "ray")


@dataclass(frozen=True)
class RunConfig:
    curriculum: Curriculum
    curriculum_path: Path
    seed: int = 0
    n_envs: int = 4
    vec_env: str = "thread"  # thread: envs stepped on a thread pool in this process
    env_threads: int = 0  # threads stepping envs (vec_env: thread); 0 = one per core
    device: str = "cpu"
    num_threads: int = 0  # torch threads for the policy; 0 = one per core
    total_steps: int = 1_000_000
    checkpoint_every: int = 50_000  # env steps
    keep_checkpoints: int = 3
    output_dir: Path = Path("runs")
    policy: PolicyConfig = PolicyConfig()
    ppo: PpoConfig = PpoConfig()
    normalize: NormalizeConfig = NormalizeConfig()
    rollout: RolloutConfig = RolloutConfig()
    source: Mapping[str, Any] = field(default_factory=dict)  # the YAML as read, for the run folder


ACTIVATIONS = ("relu", "tanh", "elu", "leaky_relu")
VEC_ENVS = ("thread", "dummy", "subproc")


def _dataclass_from(reader: YamlReader, key: str, raw: Any, cls: type, defaults: Any = None) -> Any:
    """Fill a flat dataclass of numbers/bools/strings from a mapping, checking each value."""
    base = defaults if defaults is not None else cls()
    names = tuple(f.name for f in fields(cls))
    raw = reader.mapping(key, raw, names)
    values = {}
    for name, value in raw.items():
        path, default = f"{key}.{name}", getattr(base, name)
        if name == "net_arch":
            # []: the LSTMs feed the action and value heads directly (the 2022 phase-1 network).
            if not isinstance(value, (list, tuple)):
                raise reader.error(path, f"expected a list of layer sizes ([] for none), got {value!r}")
            values[name] = tuple(reader.number(f"{path}[{i}]", v, integer=True, low=1) for i, v in enumerate(value))
        elif name == "activation":
            values[name] = reader.choice(path, value, ACTIVATIONS)
        elif isinstance(default, bool):
            values[name] = reader.boolean(path, value)
        elif name in ("gamma", "gae_lambda"):
            values[name] = reader.number(path, value, low=0, high=1)
        elif isinstance(default, int) or name in ("n_steps", "batch_size"):
            values[name] = reader.number(path, value, integer=True, low=1)
        elif name == "log_std_init":
            values[name] = reader.number(path, value)
        elif name == "learning_rate" and isinstance(value, Mapping):
            values[name] = _learning_rate_decay(reader, path, value)
        elif name == "warmup":
            values[name] = _ppo_warmup(reader, path, value)
        else:
            values[name] = reader.number(path, value, low=0, strict_low=name in (
                "learning_rate", "clip_range", "max_grad_norm", "clip_obs", "clip_reward",
                "action_head_lr_scale"))
    return type(base)(**{**{f.name: getattr(base, f.name) for f in fields(cls)}, **values})


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


# -- curriculum --------------------------------------------------------------------------

def _advance_rule(reader: YamlReader, key: str, raw: Any) -> AdvanceRule | None:
    if raw is None:
        return None
    names = tuple(f.name for f in fields(AdvanceRule))
    raw = reader.mapping(key, raw, names)
    rule = AdvanceRule()
    values: dict[str, Any] = {}
    if "metric" in raw:
        values["metric"] = reader.choice(f"{key}.metric", raw["metric"], METRICS)
    if "threshold" in raw:
        values["threshold"] = reader.number(f"{key}.threshold", raw["threshold"], low=0, high=1)
    if "window" in raw:
        values["window"] = reader.number(f"{key}.window", raw["window"], integer=True, low=1)
    if "min_steps" in raw:
        values["min_steps"] = reader.number(f"{key}.min_steps", raw["min_steps"], integer=True, low=0)
    if raw.get("max_steps") is not None:
        values["max_steps"] = reader.number(f"{key}.max_steps", raw["max_steps"], integer=True, low=1)
    if "on_max_steps" in raw:
        values["on_max_steps"] = reader.choice(f"{key}.on_max_steps", raw["on_max_steps"], ON_MAX_STEPS)
    rule = AdvanceRule(**{**rule.__dict__, **values})
    if rule.max_steps is not None and rule.max_steps < rule.min_steps:
        raise reader.error(f"{key}.max_steps", f"{rule.max_steps} is below min_steps {rule.min_steps}")
    return rule


def _stage_distribution(reader: YamlReader, key: str, task: str, knobs: Mapping[str, Any]) -> TaskKnobs:
    """A stage's merged knobs, checked against the task's declarations and read."""
    spec = TASK_SPECS[task]
    knobs = dict(knobs)
    reader.mapping(key, knobs, ("preset", *spec.knobs.help()))
    try:
        return spec.knobs.parse(**knobs)
    except ValueError as error:
        raise reader.error(key, str(error)) from None


def stage_label(index: int, name: str | None = None) -> str:
    """How errors and the console name a stage: counted from 1, with its name."""
    return f"stage {index + 1}" + (f" ({name})" if name else "")


def load_curriculum(path: str | Path) -> Curriculum:
    """Read and validate a curriculum file (see README, "Writing a curriculum").

    Raises:
        ConfigError: for a missing file, bad YAML, or any bad key or value.
    """
    path = Path(path)
    reader = YamlReader(path)
    raw = reader.mapping("", load_yaml(path, "curriculum"), ("name", "task", "defaults", "stages"))
    if not raw:
        raise reader.error("", "the curriculum file is empty")
    task = reader.choice("task", raw.get("task", "baoding"), tuple(TASK_SPECS))
    name = reader.string("name", raw.get("name", path.stem))
    defaults = reader.mapping("defaults", raw.get("defaults"), ("preset", *TASK_SPECS[task].knobs.help()))
    stages_raw = raw.get("stages")
    if not isinstance(stages_raw, list) or not stages_raw:
        raise reader.error("stages", "expected a non-empty list of stages")
    stages, seen = [], set()
    for index, stage_raw in enumerate(stages_raw):
        key = stage_label(index)  # stages count from 1, as on the console
        stage_raw = reader.mapping(key, stage_raw, ("name", "env", "advance", "ppo"))
        stage_name = reader.string(f"{key} name", stage_raw.get("name", f"stage_{index + 1}"))
        if stage_name in seen:
            raise reader.error(f"{key} name", f"duplicate stage name {stage_name!r}")
        seen.add(stage_name)
        key = stage_label(index, stage_name)
        overrides = reader.mapping(f"{key} env", stage_raw.get("env"), ("preset", *TASK_SPECS[task].knobs.help()))
        env = {**defaults, **overrides}
        distribution = _stage_distribution(reader, f"{key} env", task, env)
        advance = _advance_rule(reader, f"{key} advance", stage_raw.get("advance"))
        ppo = _dataclass_from(reader, f"{key} ppo", stage_raw.get("ppo"), PpoOverrides)
        stages.append(Stage(stage_name, env, distribution, advance, ppo))
    return Curriculum(name=name, task=task, stages=tuple(stages), path=path)


# -- run config --------------------------------------------------------------------------

RUN_KEYS = ("curriculum", "seed", "n_envs", "vec_env", "env_threads", "device", "num_threads", "total_steps", "rollout",
            "checkpoint_every", "keep_checkpoints", "output_dir", "policy", "ppo", "normalize")


def _set_key(reader: YamlReader, raw: dict[str, Any], assignment: str) -> None:
    """Apply one ``a.b=value`` override (value parsed as YAML) to the raw config."""
    if "=" not in assignment:
        raise ConfigError(f"--set {assignment}: expected key=value, e.g. ppo.learning_rate=3e-4")
    dotted, text = assignment.split("=", 1)
    keys = dotted.strip().split(".")
    reader.overrides[".".join(keys)] = assignment
    reader.mapping("", {keys[0]: None}, RUN_KEYS)
    node = raw
    for depth, key in enumerate(keys[:-1]):
        node = node.setdefault(key, {})
        if not isinstance(node, dict):
            raise ConfigError(f"--set {assignment}: {'.'.join(keys[:depth + 1])} is not a mapping")
    try:
        node[keys[-1]] = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise ConfigError(f"--set {assignment}: not a valid YAML value: {error}") from None


def _rollout(reader: YamlReader, raw: Any) -> RolloutConfig:
    names = ("backend", "workers", "envs_per_worker", "address", "max_restarts")
    raw = reader.mapping("rollout", raw, names)
    values: dict[str, Any] = {}
    if "backend" in raw:
        values["backend"] = reader.choice("rollout.backend", raw["backend"], ROLLOUT_BACKENDS)
    for key, low in (("workers", 1), ("max_restarts", 0)):
        if key in raw:
            values[key] = reader.number(f"rollout.{key}", raw[key], integer=True, low=low)
    if raw.get("envs_per_worker") is not None:
        values["envs_per_worker"] = reader.number("rollout.envs_per_worker", raw["envs_per_worker"], integer=True, low=1)
    if raw.get("address") is not None:
        values["address"] = reader.string("rollout.address", raw["address"])
    return RolloutConfig(**values)


def load_run_config(path: str | Path, overrides: tuple[str, ...] = ()) -> RunConfig:
    """Read a run config (and ``--set key=value`` overrides), including its curriculum.

    Raises:
        ConfigError: for a missing file, bad YAML, or any bad key or value.
    """
    path = Path(path)
    reader = YamlReader(path)
    raw = dict(reader.mapping("", load_yaml(path, "run config") or {}, RUN_KEYS))
    for assignment in overrides:
        _set_key(reader, raw, assignment)
    reader.mapping("", raw, RUN_KEYS)
    if "curriculum" not in raw:
        raise reader.error("curriculum", "missing: the curriculum file this run follows")
    curriculum_path = Path(reader.string("curriculum", raw["curriculum"]))
    if not curriculum_path.is_absolute():
        curriculum_path = (path.parent / curriculum_path).resolve()
    if not curriculum_path.is_file():
        raise reader.error("curriculum", f"curriculum file not found: {curriculum_path}")
    values: dict[str, Any] = {}
    integer_keys = {"seed": 0, "n_envs": 1, "env_threads": 0, "num_threads": 0, "total_steps": 1,
                    "checkpoint_every": 1, "keep_checkpoints": 1}
    for key, low in integer_keys.items():
        if key in raw:
            values[key] = reader.number(key, raw[key], integer=True, low=low)
    if "vec_env" in raw:
        values["vec_env"] = reader.choice("vec_env", raw["vec_env"], VEC_ENVS)
    if "device" in raw:
        values["device"] = reader.choice("device", raw["device"], ("cpu", "cuda", "auto"))
    if "output_dir" in raw:
        values["output_dir"] = Path(reader.string("output_dir", raw["output_dir"]))
    values["policy"] = _dataclass_from(reader, "policy", raw.get("policy"), PolicyConfig)
    for key, default in (("action_mean_bound", 0.0), ("action_head_lr_scale", 1.0)):
        if getattr(values["policy"], key) != default and not values["policy"].fast_lstm_update:
            raise reader.error(f"policy.{key}", "needs policy.fast_lstm_update: true "
                               "(it lives in the fast policy class)")
    values["ppo"] = _dataclass_from(reader, "ppo", raw.get("ppo"), PpoConfig)
    values["normalize"] = _dataclass_from(reader, "normalize", raw.get("normalize"), NormalizeConfig)
    values["rollout"] = _rollout(reader, raw.get("rollout"))
    if values["rollout"].backend == "ray":
        rollout_config = values["rollout"]
        n_envs = values.get("n_envs", RunConfig.n_envs)
        per_worker = rollout_config.envs_per_worker or n_envs // rollout_config.workers
        if per_worker < 1:
            raise reader.error("rollout.envs_per_worker", f"must be >= 1 (n_envs {n_envs} over "
                               f"{rollout_config.workers} workers gives {per_worker})")
        values["rollout"] = RolloutConfig(**{**rollout_config.__dict__, "envs_per_worker": per_worker})
        values["n_envs"] = rollout_config.workers * per_worker
    curriculum = load_curriculum(curriculum_path)
    config = RunConfig(curriculum=curriculum, curriculum_path=curriculum_path, source=raw, **values)
    rollout = config.ppo.n_steps * config.n_envs
    if config.ppo.batch_size > rollout:
        raise reader.error("ppo.batch_size", f"{config.ppo.batch_size} exceeds the rollout size "
                           f"n_steps x n_envs = {rollout}")
    warmup = config.ppo.warmup
    warmup_batch = warmup.batch_size or config.ppo.batch_size
    warmup_rollout = (warmup.n_steps or config.ppo.n_steps) * config.n_envs
    if warmup.steps and warmup_batch > warmup_rollout:
        raise reader.error("ppo.warmup.batch_size", f"{warmup_batch} exceeds the warm-up's rollout size "
                           f"n_steps x n_envs = {warmup_rollout}")
    n_steps, batch_size = config.ppo.n_steps, config.ppo.batch_size
    for index, stage in enumerate(curriculum.stages):  # overrides stay in force until changed
        n_steps = stage.ppo.n_steps or n_steps
        batch_size = stage.ppo.batch_size or batch_size
        if batch_size > n_steps * config.n_envs:
            raise ConfigError(f"{curriculum_path}: {stage_label(index, stage.name)} ppo: batch_size {batch_size} exceeds the "
                              f"rollout size n_steps x n_envs = {n_steps} x {config.n_envs} of this run ({path})")
    return config
