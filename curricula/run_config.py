"""Run config files (YAML in, a typed :class:`RunConfig` out): the run's settings
(``myo_sds.curricula.run_settings``), the curriculum it follows (``myo_sds.curricula.schema``),
and which bundled run config a curriculum file runs with when ``--config`` names a curriculum.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from myo_sds.curricula.run_settings import (
    NormalizeConfig,
    PolicyConfig,
    PpoConfig,
    RolloutConfig,
    RunSettings,
)
from myo_sds.curricula.schema import (
    CURRICULUM_KEYS,
    CURRICULUM_SET_KEYS,
    Curriculum,
    _flat_keys,
    load_curriculum,
    stage_label,
)
from myo_sds.curricula.yaml_reader import PATH_KEYS, ConfigError, YamlReader, load_yaml, merge_bases, resolve_base
from myo_sds.envs.declare import read_settings, text
from myo_sds.envs.task_specs import TASK_SPECS


@dataclass(frozen=True)
class RunConfig:
    curriculum: Curriculum
    curriculum_path: Path
    # The top level's values (myo_sds.curricula.run_settings.RunSettings, where each is declared).
    seed: int = RunSettings.seed
    n_envs: int = RunSettings.n_envs
    vec_env: str = RunSettings.vec_env
    env_threads: int = RunSettings.env_threads
    device: str = RunSettings.device
    num_threads: int = RunSettings.num_threads
    total_steps: int = RunSettings.total_steps
    init_from: Path | None = RunSettings.init_from
    checkpoint_every: int = RunSettings.checkpoint_every
    keep_checkpoints: int = RunSettings.keep_checkpoints
    output_dir: Path = RunSettings.output_dir
    policy: PolicyConfig = PolicyConfig()
    ppo: PpoConfig = PpoConfig()
    normalize: NormalizeConfig = NormalizeConfig()
    rollout: RolloutConfig = RolloutConfig()
    source: Mapping[str, Any] = field(default_factory=dict)  # the YAML as read, for the run folder
    origins: Mapping[str, str] = field(default_factory=dict)  # dotted key -> its file or --set


# -- run config --------------------------------------------------------------------------

RUN_KEYS = ("curriculum", *(f.name for f in fields(RunSettings)), "policy", "ppo", "normalize", "rollout")


def load_run_config(path: str | Path, overrides: tuple[str, ...] = ()) -> RunConfig:
    """Read a run config (and ``--set key=value`` overrides), including its curriculum.

    ``path`` may also be a curriculum file: it then runs with the bundled run config of the
    bundled curriculum it is (or is based on), e.g. a variant of ``curricula/quickstart.yaml``
    with ``configs/quickstart.yaml`` (:func:`run_config_for_curriculum`). A path given with
    ``--set`` (``curriculum``, ``init_from``) is relative to the working folder; one written in a
    file, to that file.

    Raises:
        ConfigError: for a missing file, bad YAML, or any bad key or value.
    """
    path = Path(path)
    curriculum_file = None
    if _is_curriculum_file(path):
        curriculum_file, path = path.resolve(), run_config_for_curriculum(path)
    reader = YamlReader(path)
    raw = dict(reader.mapping("", reader.read_with_bases("run config"), RUN_KEYS))
    if curriculum_file is not None:
        raw["curriculum"] = str(curriculum_file)
        reader.origins["curriculum"] = curriculum_file
    curriculum_overrides = tuple(a for a in overrides if a.split(".", 1)[0].split("=", 1)[0] in CURRICULUM_SET_KEYS)
    for assignment in overrides:
        if assignment not in curriculum_overrides:
            reader.set_value(raw, assignment, RUN_KEYS + CURRICULUM_SET_KEYS)
            key = assignment.split("=", 1)[0].strip()
            if key in PATH_KEYS and isinstance(raw.get(key), str):  # from the working folder, as a shell path
                raw[key] = str(Path(raw[key]).resolve())
    reader.mapping("", raw, RUN_KEYS)
    if "curriculum" not in raw:
        raise reader.error("curriculum", "missing: the curriculum file this run follows")
    curriculum_path = Path(reader.read("curriculum", raw["curriculum"], text))
    if not curriculum_path.is_absolute():
        curriculum_path = (path.parent / curriculum_path).resolve()
    if not curriculum_path.is_file():
        raise reader.error("curriculum", f"curriculum file not found: {curriculum_path}")
    values = _run_settings(reader, raw, path)
    curriculum = load_curriculum(curriculum_path, curriculum_overrides)
    privileged = TASK_SPECS[curriculum.task].privileged
    for name in values["policy"].critic_extra:
        if name not in privileged:
            raise reader.error("policy.critic_extra", f"{name!r} is not a privileged feature of the {curriculum.task} "
                               f"task; allowed: {', '.join(privileged)}")
    origins = {dotted: reader.origin(dotted) for dotted in _flat_keys(raw)}
    config = RunConfig(curriculum=curriculum, curriculum_path=curriculum_path, source=raw, origins=origins, **values)
    _check_batch_sizes(reader, config, path)
    cut = config.ppo.sequence_length or any(stage.ppo.as_dict().get("sequence_length") for stage in curriculum.stages)
    if cut and not config.policy.fast_lstm_update:
        raise reader.error("ppo.sequence_length", "needs policy.fast_lstm_update: true (the fast update's buffer cuts them)")
    return config


def _is_curriculum_file(path: Path, _seen: frozenset[Path] = frozenset()) -> bool:
    """Whether ``path`` is a curriculum rather than a run config, by its own keys (or, a file of
    only ``base:``, by what its base is; a cycle of bases is reported when read as a run config)."""
    try:
        raw = load_yaml(path, "config")
    except ConfigError:  # a missing or broken file: reading it as a run config says what is wrong
        return False
    if not isinstance(raw, Mapping):
        return False
    keys = set(raw) - {"base", "replace_stages"}
    if keys:
        return "curriculum" not in keys and bool(keys & set(CURRICULUM_KEYS))
    base = raw.get("base")
    if not isinstance(base, str):
        return False
    as_curriculum = resolve_base(path, base, "curriculum")
    seen = _seen | {path.resolve()}
    return as_curriculum.is_file() and as_curriculum not in seen and _is_curriculum_file(as_curriculum, seen)


def run_config_for_curriculum(path: Path) -> Path:
    """The bundled run config a curriculum file runs with: the first file of its ``base:`` chain
    (itself first) that a bundled config names as its curriculum (the config of the same name
    preferred), else a ``ConfigError`` saying how to give it one."""
    from myo_sds import bundled_dir

    configs = sorted(bundled_dir("configs").glob("*.yaml"))
    following: dict[Path, list[Path]] = {}
    for config in configs:
        merged, _ = merge_bases(config, "run config")
        if isinstance(merged.get("curriculum"), str):
            named = Path(merged["curriculum"])
            named = named if named.is_absolute() else (config.parent / named)
            following.setdefault(named.resolve(), []).append(config)
    chain, current = [], path.resolve()
    while current is not None and current not in chain:
        chain.append(current)
        base = (load_yaml(current, "curriculum") or {}).get("base")
        current = resolve_base(current, base, "curriculum") if isinstance(base, str) else None
    for file in chain:
        if file in following:
            return next((c for c in following[file] if c.stem == file.stem), following[file][0])
    raise ConfigError(f"{path}: a curriculum that no bundled run config follows (nor any of its bases); give it "
                      f"one: --config baoding_sds --set curriculum={path.resolve()} (a bundled config by name, or "
                      f"your own run config's path)")


def _run_settings(reader: YamlReader, raw: Mapping[str, Any], path: Path) -> dict[str, Any]:
    """The top level and each section, read through their declarations; paths made absolute
    and a Ray run's env count made whole."""
    sections = {"policy": PolicyConfig, "ppo": PpoConfig, "normalize": NormalizeConfig, "rollout": RolloutConfig}
    top = read_settings(reader, "", {k: v for k, v in raw.items() if k not in (*sections, "curriculum")}, RunSettings)
    values: dict[str, Any] = {f.name: getattr(top, f.name) for f in fields(RunSettings)}
    if values["init_from"] is not None and not values["init_from"].is_absolute():
        values["init_from"] = (path.parent / values["init_from"]).resolve()
    for key, cls in sections.items():
        values[key] = read_settings(reader, key, raw.get(key), cls)
    rollout = values["rollout"]
    if rollout.backend == "ray":
        per_worker = rollout.envs_per_worker or values["n_envs"] // rollout.workers
        if per_worker < 1:
            raise reader.error("rollout.envs_per_worker", f"must be >= 1 (n_envs {values['n_envs']} over "
                               f"{rollout.workers} workers gives {per_worker})")
        values["rollout"] = RolloutConfig(**{**rollout.__dict__, "envs_per_worker": per_worker})
        values["n_envs"] = rollout.workers * per_worker
    return values


def _check_batch_sizes(reader: YamlReader, config: RunConfig, path: Path) -> None:
    """A minibatch never larger than its rollout: the run's, the warm-up's, each stage's."""
    rollout = config.ppo.n_steps * config.n_envs
    # Either side may be the one just changed: say where each came from.
    sources = f"(n_steps from {reader.origin('ppo.n_steps')}, n_envs from {reader.origin('n_envs')})"
    if config.ppo.batch_size > rollout:
        raise reader.error("ppo.batch_size", f"{config.ppo.batch_size} exceeds the rollout size "
                           f"n_steps x n_envs = {config.ppo.n_steps} x {config.n_envs} = {rollout} {sources}")
    warmup = config.ppo.warmup
    warmup_batch = warmup.batch_size or config.ppo.batch_size
    warmup_rollout = (warmup.n_steps or config.ppo.n_steps) * config.n_envs
    if warmup.steps and warmup_batch > warmup_rollout:
        raise reader.error("ppo.warmup.batch_size", f"{warmup_batch} exceeds the warm-up's rollout size "
                           f"n_steps x n_envs = {warmup_rollout}")
    n_steps, batch_size = config.ppo.n_steps, config.ppo.batch_size
    for index, stage in enumerate(config.curriculum.stages):  # overrides stay in force until changed
        n_steps = stage.ppo.as_dict().get("n_steps", n_steps)
        batch_size = stage.ppo.as_dict().get("batch_size", batch_size)
        if batch_size > n_steps * config.n_envs:
            raise ConfigError(f"{config.curriculum_path}: {stage_label(index, stage.name)} ppo: batch_size {batch_size} "
                              f"exceeds the rollout size n_steps x n_envs = {n_steps} x {config.n_envs} of this run "
                              f"({path})")
