"""Curriculum files and run configs: YAML in, validated typed objects out.

Every problem is reported once, before training starts, as a :class:`ConfigError` naming the
file, the key path (``stages[2].advance.threshold``), the bad value and what is allowed.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import MISSING, dataclass, field
from pathlib import Path
from typing import Any

import yaml

from myo_sds.curricula.run_settings import (
    STAGE_PPO_SETTINGS,
    PpoConfig,
)
from myo_sds.curricula.yaml_reader import ConfigError, YamlReader
from myo_sds.envs.declare import integer, number, one_of, optional, overrides_of, read_settings, setting, text
from myo_sds.envs.knobs import TaskKnobs
from myo_sds.envs.task_specs import TASK_SPECS

# score and survival: the mean over the stage's last `window` training episodes; eval_score and
# eval_reward: the stage's latest periodic evaluation (its `evaluate`), mean official score or return.
METRICS = ("score", "survival", "eval_score", "eval_reward")
EVALUATION_METRICS = ("eval_score", "eval_reward")
ON_MAX_STEPS = ("advance", "stop")

@dataclass(frozen=True)
class AdvanceRule:
    """When a stage is passed: the mean ``metric`` over the last ``window`` training
    episodes of the stage reaches ``threshold``, after at least ``min_steps`` env steps.
    After ``max_steps``, or once the mean has not risen ``plateau_gain`` above its best for
    ``plateau_steps`` env steps (with a full window, after ``min_steps``), the stage ends
    unpassed and the run advances or stops (``on_max_steps``)."""

    metric: str = setting("score", parse=one_of(*METRICS),
                          help="score (official) | survival over the window; eval_score | eval_reward of the "
                               "latest stage evaluation")
    threshold: float = setting(0.5, parse=number(), help="the value that passes the stage (in [0, 1] but for eval_reward)")
    window: int = setting(100, parse=integer(low=1), help="the stage's last training episodes averaged")
    min_steps: int = setting(0, parse=integer(low=0), help="env steps in the stage before it may pass")
    max_steps: int | None = setting(None, parse=optional(integer(low=1)), help="then the stage ends unpassed")
    on_max_steps: str = setting("advance", parse=one_of(*ON_MAX_STEPS),
                                help="after an unpassed end: advance to the next stage, or stop the run")
    plateau_steps: int | None = setting(None, parse=optional(integer(low=1)),
                                        help="also end unpassed when the mean has not risen plateau_gain for this long")
    plateau_gain: float = setting(0.01, parse=number(low=0), help="the rise that counts for plateau_steps")

    @property
    def window_metric(self) -> str:
        """What each training episode adds to the window (an evaluation metric's stage: its score)."""
        return "score" if self.metric in EVALUATION_METRICS else self.metric

    @property
    def tracked_gain(self) -> float | None:
        """The gain the curriculum state tracks the stage's best by (None: no plateau rule)."""
        return self.plateau_gain if self.plateau_steps is not None else None


HAND_OFFS = ("best", "last")
SELECTIONS = ("score", "reward")
EVALUATION_SEEDS = ("fresh", "fixed")


@dataclass(frozen=True)
class StageEvaluation:
    """Deterministic episodes every ``every`` env steps of the stage, as the 2022 winner's
    EvalCallback: ``episodes`` episodes (``seeds: fresh``: new ones at every evaluation, seeds
    from the env step, as their EvalCallback drew new episodes of the training envs; ``fixed``:
    seeds 0 .. episodes-1 every time) on ``env`` (``stage``: the stage's own task; ``stage:NAME``: another stage's, e.g. the task a
    practice stage is for; or a preset, e.g. ``p1_2022``), each hand joint moved
    by U(-``start_noise``, ``start_noise``) at reset. The policy of the best mean score (or return,
    ``select: reward``, as the winner's EvalCallback chose) is kept; with ``hand_off: best`` the next
    stage starts from it (weights, optimizer and normalization statistics of that step), with
    ``last`` from the stage's last policy."""

    every: int = setting(MISSING, parse=integer(low=1), help="env steps between evaluations, e.g. 250000")
    episodes: int = setting(10, parse=integer(low=1), help="deterministic episodes per evaluation")
    env: str = setting("stage", parse=text,
                       help="stage (the stage's own task), stage:NAME (another stage's) or a preset, e.g. p1_2022")
    start_noise: float = setting(0.0, parse=number(low=0), help="rad: each hand joint moved by up to this at reset")
    hand_off: str = setting("best", parse=one_of(*HAND_OFFS), help="best | last: the policy the next stage starts from")
    seeds: str = setting("fresh", parse=one_of(*EVALUATION_SEEDS),
                         help="fresh (new episodes at every evaluation: the best is not chosen on the same few "
                              "instances) | fixed (seeds 0 .. episodes-1 every time)")
    select: str = setting("score", parse=one_of(*SELECTIONS),
                          help="score | reward: what makes an evaluation the best (reward: the mean return under "
                               "the stage's reward weights)")


@dataclass(frozen=True)
class StageEndProbe:
    """At each stage's end, ``episodes`` deterministic episodes of the policy handed on, on ``env``
    (``stage:NAME``: that stage's task, e.g. the fixed start from rest; or a preset): whether the
    policy can already do what a later stage asks, before it trains on it."""

    env: str = setting(MISSING, parse=text, help="stage:NAME (a stage of this curriculum) or a preset, e.g. p1_2022")
    episodes: int = setting(20, parse=integer(low=1), help="deterministic episodes (seeds 0 .. episodes-1)")
    start_noise: float = setting(0.0, parse=number(low=0), help="rad: each hand joint moved by up to this at reset")


PpoOverrides = overrides_of(
    PpoConfig, STAGE_PPO_SETTINGS, "PpoOverrides",
    """PPO settings a stage changes at its start (unset: keep the current value; ``null`` turns an
    optional one off, e.g. ``target_kl``), each read as the run config's ``ppo`` reads it.""")


@dataclass(frozen=True)
class Stage:
    name: str
    env: Mapping[str, Any]  # the knobs as the curriculum writes them (defaults merged in)
    distribution: TaskKnobs  # the same, checked and read once: what every env of the stage gets
    advance: AdvanceRule | None  # None: train on this stage until the step budget ends
    ppo: PpoOverrides = PpoOverrides()  # type: ignore[valid-type]
    evaluate: StageEvaluation | None = None  # periodic deterministic evaluation and best-model hand-off


@dataclass(frozen=True)
class Curriculum:
    name: str
    task: str
    stages: tuple[Stage, ...]
    path: Path | None = None
    probe: StageEndProbe | None = None  # evaluated at each stage's end
    # The mapping read, when it differs from the file (bases merged, --set applied); None: the file.
    resolved: Mapping[str, Any] | None = None
    # Where each value came from (dotted key -> a file or a --set), for --print-config.
    origins: Mapping[str, str] = field(default_factory=dict)

    def file_text(self) -> str:
        """The curriculum as one self-contained file, for a run folder's own copy: the file as
        written (comments kept), or, when it inherits with ``base:`` or a ``--set`` changed it,
        the resolved mapping."""
        if self.resolved is None:
            return self.path.read_text()
        return (f"# {self.path.name} resolved (its base files merged, --set applied): the curriculum this run follows\n"
                + yaml.safe_dump(dict(self.resolved), sort_keys=False))

    def stage_index(self, name: str) -> int:
        for index, stage in enumerate(self.stages):
            if stage.name == name:
                return index
        raise KeyError(f"no stage named {name!r} in curriculum {self.name!r}; "
                       f"stages: {', '.join(s.name for s in self.stages)}")


# -- curriculum --------------------------------------------------------------------------

def _advance_rule(reader: YamlReader, key: str, raw: Any) -> AdvanceRule | None:
    if raw is None:
        return None
    rule = read_settings(reader, key, raw, AdvanceRule)
    if rule.max_steps is not None and rule.max_steps < rule.min_steps:
        raise reader.error(f"{key}.max_steps", f"{rule.max_steps} is below min_steps {rule.min_steps}")
    if rule.metric != "eval_reward" and not 0 <= rule.threshold <= 1:
        raise reader.error(f"{key}.threshold", f"must be in [0, 1] for {rule.metric}, got {rule.threshold:g}")
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


def _stage_evaluation(reader: YamlReader, key: str, task: str, raw: Any) -> StageEvaluation | None:
    if raw is None:
        return None
    evaluation = read_settings(reader, key, raw, StageEvaluation)
    if evaluation.start_noise and not TASK_SPECS[task].hand_joints:
        raise reader.error(f"{key}.start_noise", f"the {task} task declares no hand joints to move")
    return evaluation


def stage_label(index: int, name: str | None = None) -> str:
    """How errors and the console name a stage: counted from 1, with its name."""
    return f"stage {index + 1}" + (f" ({name})" if name else "")


CURRICULUM_KEYS = ("name", "task", "defaults", "probe", "stages")


def _probe(reader: YamlReader, task: str, raw: Any, stage_names: tuple[str, ...]) -> StageEndProbe | None:
    if raw is None:
        return None
    probe = read_settings(reader, "probe", raw, StageEndProbe)
    _check_evaluation_env(reader, "probe.env", probe.env, task, stage_names, own_stage=False)
    if probe.start_noise and not TASK_SPECS[task].hand_joints:
        raise reader.error("probe.start_noise", f"the {task} task declares no hand joints to move")
    return probe


def _check_evaluation_env(reader: YamlReader, key: str, env: str, task: str, stage_names: tuple[str, ...],
                          *, own_stage: bool) -> None:
    """An evaluation's env: ``stage:NAME`` (a stage of this curriculum), a preset, or ``stage`` (``own_stage``)."""
    if env.startswith("stage:") and env[len("stage:"):] not in stage_names:
        raise reader.error(key, f"no stage named {env[len('stage:'):]!r}; stages: {', '.join(stage_names)}")
    presets = tuple(TASK_SPECS[task].knobs.PRESETS)
    if not env.startswith("stage:") and env not in presets and not (own_stage and env == "stage"):
        allowed = ("stage", "stage:NAME") if own_stage else ("stage:NAME",)
        raise reader.error(key, f"{env!r} is not one of {', '.join(allowed + presets)}")


CURRICULUM_SET_KEYS = ("defaults", "probe", "stages")  # what --set may change in a curriculum
STAGE_KEYS = ("name", "env", "advance", "ppo", "evaluate")


def load_curriculum(path: str | Path, overrides: tuple[str, ...] = ()) -> Curriculum:
    """Read and validate a curriculum file (see README, "Writing a curriculum"), with ``--set``
    overrides such as ``stages.hold-rsi.advance.threshold=0.7`` or ``defaults.drop_height=1.3``.

    Raises:
        ConfigError: for a missing file, bad YAML, or any bad key or value.
    """
    path = Path(path)
    reader = YamlReader(path)
    raw = dict(reader.mapping("", reader.read_with_bases("curriculum"), CURRICULUM_KEYS))
    for assignment in overrides:
        reader.set_value(raw, assignment, CURRICULUM_SET_KEYS)
    if not raw:
        raise reader.error("", "the curriculum file is empty")
    task = reader.read("task", raw.get("task", "baoding"), one_of(*TASK_SPECS))
    # A variant is named by its own file, not by the base it inherits from.
    name = reader.read("name", raw["name"] if "name" in raw and "name" not in reader.origins else path.stem, text)
    defaults = reader.mapping("defaults", raw.get("defaults"), ("preset", *TASK_SPECS[task].knobs.help()))
    stages_raw = raw.get("stages")
    if not isinstance(stages_raw, list) or not stages_raw:
        raise reader.error("stages", "expected a non-empty list of stages")
    stages, seen, stage_keys = [], set(), []
    for index, stage_raw in enumerate(stages_raw):
        key = stage_label(index)  # stages count from 1, as on the console
        stage_raw = reader.mapping(key, stage_raw, STAGE_KEYS)
        stage_name = reader.read(f"{key} name", stage_raw.get("name", f"stage_{index + 1}"), text)
        if stage_name in seen:
            raise reader.error(f"{key} name", f"duplicate stage name {stage_name!r}")
        seen.add(stage_name)
        key = stage_label(index, stage_name)
        # An error in a stage names the file that last wrote it (a base's, when inherited).
        stage_reader = reader.stage_reader(stage_name, key)
        stages.append(_stage(stage_reader, key, task, stage_name, stage_raw, defaults, reader))
        stage_keys.append((stage_reader, key))
    stage_names = tuple(s.name for s in stages)
    for stage, (stage_reader, key) in zip(stages, stage_keys):  # once every stage's name is known
        if stage.evaluate is not None:
            _check_evaluation_env(stage_reader, f"{key} evaluate.env", stage.evaluate.env, task, stage_names, own_stage=True)
    probe = _probe(reader, task, raw.get("probe"), stage_names)
    changed = bool(reader.origins or reader.overrides)
    if changed:
        raw["name"] = name
    origins = {dotted: reader.origin(dotted) for dotted in _flat_keys(raw)}
    return Curriculum(name=name, task=task, stages=tuple(stages), path=path, probe=probe,
                      resolved={k: raw[k] for k in CURRICULUM_KEYS if k in raw} if changed else None, origins=origins)


def _stage(reader: YamlReader, key: str, task: str, name: str, raw: Mapping[str, Any],
           defaults: Mapping[str, Any], curriculum_reader: YamlReader) -> Stage:
    overrides = reader.mapping(f"{key} env", raw.get("env"), ("preset", *TASK_SPECS[task].knobs.help()))
    env = {**defaults, **overrides}
    try:
        distribution = _stage_distribution(reader, f"{key} env", task, env)
    except ConfigError as error:
        # A bad value the stage inherits from ``defaults`` is named where ``defaults`` set it.
        knob_path, _, message = str(error).partition(f"{key} env: ")[2].partition(": ")
        if message and knob_path.split(".")[0] in defaults and knob_path.split(".")[0] not in overrides:
            raise curriculum_reader.error(f"defaults.{knob_path}", f"{message} (in {key})") from None
        raise
    advance = _advance_rule(reader, f"{key} advance", raw.get("advance"))
    ppo = read_settings(reader, f"{key} ppo", raw.get("ppo"), PpoOverrides)
    evaluation = _stage_evaluation(reader, f"{key} evaluate", task, raw.get("evaluate"))
    if advance is not None and advance.metric in EVALUATION_METRICS and evaluation is None:
        raise reader.error(f"{key} advance.metric", f"{advance.metric} needs the stage's evaluate (none is set)")
    return Stage(name, env, distribution, advance, ppo, evaluation)


def _flat_keys(mapping: Mapping[str, Any], prefix: str = "") -> list[str]:
    """Dotted keys of a resolved mapping's leaves, a curriculum's stages as ``stages.NAME.key``."""
    keys = []
    for name, value in mapping.items():
        dotted = f"{prefix}{name}"
        if not prefix and name == "stages" and isinstance(value, list):
            value = {stage.get("name"): {k: v for k, v in stage.items() if k != "name"} for stage in value}
        keys += _flat_keys(value, dotted + ".") if isinstance(value, Mapping) and value else [dotted]
    return keys
