"""Reading values out of YAML files with errors that say where: the file (or the ``--set``
override) and the key path, the bad value, and what is allowed.

PyYAML reads ``1e-3`` as a string and ``yes`` as a boolean, so numbers and booleans are
checked and converted here, never assumed.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml


class ConfigError(ValueError):
    """A curriculum or run config that cannot be used; the message says where and why."""


class YamlReader:
    """Reads values out of one YAML file, raising errors that name the file and key path, or
    the ``--set`` override a bad value came from."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.overrides: dict[str, str] = {}  # dotted key -> the --set assignment that set it
        self.origins: dict[str, Path] = {}  # dotted key -> the ``base:`` file its value came from

    def error(self, key: str, message: str) -> ConfigError:
        for dotted, assignment in self.overrides.items():
            if key and _related(key, dotted):
                return ConfigError(f"--set {assignment}: {key}: {message}")
        path = next((origin for dotted, origin in self.origins.items() if key and _related(key, dotted)), self.path)
        where = f"{path}: {key}: " if key else f"{path}: "
        return ConfigError(where + message)

    def read_with_bases(self, what: str) -> dict[str, Any]:
        """The file's mapping with its ``base:`` chain merged under it (see :func:`merge_bases`)."""
        merged, self.origins = merge_bases(self.path, what)
        return merged

    def mapping(self, key: str, value: Any, allowed: Mapping[str, Any] | tuple[str, ...]) -> Mapping[str, Any]:
        if value is None:
            return {}
        if not isinstance(value, Mapping):
            raise self.error(key, f"expected a mapping, got {type(value).__name__} {value!r}")
        allowed = tuple(allowed)
        for name in value:
            if name not in allowed:
                near = difflib.get_close_matches(str(name), allowed, n=1)
                hint = f" (did you mean {near[0]!r}?)" if near else ""
                prefix = f"{key}." if key else ""
                raise self.error(f"{prefix}{name}", f"unknown key{hint}; allowed: {', '.join(allowed)}")
        return value

    def read(self, key: str, value: Any, parse) -> Any:
        """``parse(key, value)`` (a :mod:`myo_sds.declare` parser), its ``ValueError`` turned into
        this file's ``ConfigError`` at the key it names."""
        from myo_sds.declare import split_message

        try:
            return parse(key, value)
        except ValueError as error:
            raise self.error(*split_message(key, str(error))) from None


def _related(key: str, dotted: str) -> bool:
    return key == dotted or key.startswith(dotted + ".") or dotted.startswith(key + ".")


def _leaves(mapping: Mapping[str, Any], prefix: str = "") -> list[str]:
    keys = []
    for name, value in mapping.items():
        dotted = f"{prefix}{name}"
        keys += _leaves(value, dotted + ".") if isinstance(value, Mapping) and value else [dotted]
    return keys


def _deep_merge(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    merged = dict(base)
    for name, value in over.items():
        if isinstance(value, Mapping) and isinstance(merged.get(name), Mapping):
            merged[name] = _deep_merge(merged[name], value)
        else:
            merged[name] = value
    return merged


def merge_bases(path: Path, what: str, _seen: tuple[Path, ...] = ()) -> tuple[dict[str, Any], dict[str, Path]]:
    """A YAML mapping with ``base: OTHER.yaml`` (relative to the file) read first and this file's
    keys merged over it, mapping by mapping (a value that is not a mapping replaces the base's);
    bases may have bases. A relative ``curriculum`` path stays relative to the file that wrote it.
    Also returns, for each dotted key whose value came from a base, that base's path."""
    path = Path(path).resolve()
    raw = load_yaml(path, what)
    if raw is None:
        raw = {}
    if not isinstance(raw, Mapping):
        raise ConfigError(f"{path}: expected a mapping of settings, got {type(raw).__name__}")
    raw = dict(raw)
    if "curriculum" in raw and isinstance(raw["curriculum"], str) and not Path(raw["curriculum"]).is_absolute():
        raw["curriculum"] = str((path.parent / raw["curriculum"]).resolve()) if _seen else raw["curriculum"]
    base = raw.pop("base", None)
    if base is None:
        return raw, {}
    if not isinstance(base, str) or not base:
        raise ConfigError(f"{path}: base: expected the path of another {what} file, got {base!r}")
    base_path = (path.parent / base).resolve()
    if base_path in (*_seen, path):
        raise ConfigError(f"{path}: base: {base} leads back to {base_path} (a cycle of bases)")
    if not base_path.is_file():
        raise ConfigError(f"{path}: base: {what} file not found: {base_path}")
    parent, parent_origins = merge_bases(base_path, what, (*_seen, path))
    own = set(_leaves(raw))
    origins = {key: parent_origins.get(key, base_path) for key in _leaves(parent)
               if not any(_related(key, mine) for mine in own)}
    return _deep_merge(parent, raw), origins


def load_yaml(path: Path, what: str) -> Any:
    if not path.is_file():
        raise ConfigError(f"{path}: {what} file not found")
    try:
        with path.open() as file:
            return yaml.safe_load(file)
    except yaml.YAMLError as error:
        raise ConfigError(f"{path}: not valid YAML: {error}") from None
