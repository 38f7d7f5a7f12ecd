"""``train.py --config X --print-config``: every value a run would use, and where it came from
(the file that wrote it, a ``base:`` it inherits, a ``--set``, the stage's ``defaults``, its
preset, or the declared default)."""

from __future__ import annotations

from dataclasses import fields, is_dataclass
from typing import Any

from myo_sds.curricula.run_config import RunConfig
from myo_sds.envs.declare import UNSET
from myo_sds.envs.task_specs import TASK_SPECS


def _text(value: Any) -> str:
    """A value as a person would write it in the YAML."""
    if value is None:
        return "null"
    if hasattr(value, "low") and hasattr(value, "high"):  # an env knob's range
        return f"{value.low:g}" if value.low == value.high else f"[{value.low:g}, {value.high:g}]"
    if is_dataclass(value) and not isinstance(value, type):
        return "{" + ", ".join(f"{f.name}: {_text(getattr(value, f.name))}" for f in fields(value)) + "}"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_text(v)}" for k, v in value.items()) + "}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_text(v) for v in value) + "]"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _origin(key: str, origins: dict[str, str]) -> str | None:
    """Where ``key`` came from; a mapping merged from several files (e.g. reward weights a
    variant changes one of) names each of them, in the order they were read."""
    if key in origins:
        return origins[key]
    parts = list(dict.fromkeys(o for k, o in origins.items() if k.startswith(key + ".")))
    return " + ".join(parts) if parts else None


def _rows(prefix: str, settings: Any, origins: dict[str, str], fallback: str = "default") -> list[tuple[str, str, str]]:
    rows = []
    for f in fields(settings):
        value = getattr(settings, f.name)
        key = f"{prefix}{f.name}"
        if value is UNSET:
            continue
        origin = _origin(key, origins) or fallback
        rows.append((key, _text(value), origin))
    return rows


def config_rows(config: RunConfig) -> list[tuple[str, str, str]]:
    """(key, value, origin) of every setting of the run and of each stage of its curriculum."""
    origins = dict(config.origins)
    rows = [("curriculum", str(config.curriculum_path), origins.get("curriculum", "default"))]
    for f in fields(config):
        if f.name in ("curriculum", "curriculum_path", "source", "origins"):
            continue
        value = getattr(config, f.name)
        if is_dataclass(value):
            rows += _rows(f"{f.name}.", value, origins)
        else:
            rows.append((f.name, _text(value), origins.get(f.name, "default")))
    curriculum = config.curriculum
    c_origins = dict(curriculum.origins)
    knobs_class = TASK_SPECS[curriculum.task].knobs
    # The stage order, resolved (a variant's changes and its bases merged): what the run goes through.
    stage_origins = " + ".join(dict.fromkeys(o for k, o in c_origins.items() if k.startswith("stages.")))
    rows.append(("stages", ", ".join(stage.name for stage in curriculum.stages), stage_origins or str(curriculum.path)))
    if curriculum.probe is not None:
        rows += _rows("probe.", curriculum.probe, c_origins)
    for stage in curriculum.stages:
        prefix = f"stages.{stage.name}."
        preset = stage.env.get("preset", "p1")
        for f in fields(stage.distribution):
            own, shared = f"{prefix}env.{f.name}", f"defaults.{f.name}"
            own_origin, shared_origin = _origin(own, c_origins), _origin(shared, c_origins)
            if own_origin:
                origin = own_origin
            elif shared_origin:
                origin = "defaults: " + shared_origin
            elif f.name in knobs_class.PRESETS.get(preset, {}):
                origin = f"preset {preset}"
            else:
                origin = "default"
            rows.append((f"{prefix}env.{f.name}", _text(getattr(stage.distribution, f.name)), origin))
        for part in ("advance", "evaluate"):
            settings = getattr(stage, part)
            if settings is None:
                rows.append((f"{prefix}{part}", "null", "not set"))
            else:
                rows += _rows(f"{prefix}{part}.", settings, c_origins)
        rows += _rows(f"{prefix}ppo.", stage.ppo, c_origins)
    return rows


def _short(origin: str) -> str:
    """Files under the working folder by their relative paths (each of a `` + `` list)."""
    from pathlib import Path

    prefix = "defaults: " if origin.startswith("defaults: ") else ""
    parts = []
    for part in origin[len(prefix):].split(" + "):
        path = Path(part)
        if path.is_absolute() and path.is_relative_to(Path.cwd()):
            part = str(path.relative_to(Path.cwd()))
        parts.append(part)
    return prefix + " + ".join(parts)


def format_config(config: RunConfig) -> str:
    rows = [(key, value, _short(origin)) for key, value, origin in config_rows(config)]
    key_width = min(max(len(k) for k, _, _ in rows), 48)
    value_width = min(max(len(v) for _, v, _ in rows), 40)
    lines = [f"{key:<{key_width}}  {value:<{value_width}}  {origin}" for key, value, origin in rows]
    return "\n".join(["# every setting of the run: key, value, where it came from "
                      "(unset stage ppo settings keep the run's)", *lines])
