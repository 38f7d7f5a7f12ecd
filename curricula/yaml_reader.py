"""Reading values out of YAML files with errors that say where: the file (or the ``--set``
override) and the key path, the bad value, and what is allowed.

PyYAML reads ``1e-3`` as a string and ``yes`` as a boolean, so numbers and booleans are
checked and converted here, never assumed.
"""

from __future__ import annotations

import difflib
import math
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

    def error(self, key: str, message: str) -> ConfigError:
        for dotted, assignment in self.overrides.items():
            if key and (key == dotted or key.startswith(dotted + ".") or dotted.startswith(key + ".")):
                return ConfigError(f"--set {assignment}: {key}: {message}")
        where = f"{self.path}: {key}: " if key else f"{self.path}: "
        return ConfigError(where + message)

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

    def number(self, key: str, value: Any, *, integer: bool = False, low: float | None = None,
               high: float | None = None, strict_low: bool = False) -> float | int:
        kind = "an integer" if integer else "a number"
        if isinstance(value, bool):
            raise self.error(key, f"expected {kind}, got the boolean {value!r}")
        try:
            number = float(value)  # PyYAML reads 3e-4 as a string
        except (TypeError, ValueError):
            raise self.error(key, f"expected {kind}, got {value!r}") from None
        if not math.isfinite(number):
            raise self.error(key, f"expected a finite number, got {value!r}")
        if integer:
            if number != int(number):
                raise self.error(key, f"expected an integer, got {value!r}")
            number = int(number)
        if low is not None and (number <= low if strict_low else number < low):
            raise self.error(key, f"must be {'>' if strict_low else '>='} {low}, got {value!r}")
        if high is not None and number > high:
            raise self.error(key, f"must be <= {high}, got {value!r}")
        return number

    def boolean(self, key: str, value: Any) -> bool:
        if not isinstance(value, bool):
            raise self.error(key, f"expected true or false, got {value!r}")
        return value

    def choice(self, key: str, value: Any, allowed: tuple[str, ...]) -> str:
        if value not in allowed:
            raise self.error(key, f"{value!r} is not one of {', '.join(allowed)}")
        return value

    def string(self, key: str, value: Any) -> str:
        if not isinstance(value, str) or not value:
            raise self.error(key, f"expected a non-empty string, got {value!r}")
        return value


def load_yaml(path: Path, what: str) -> Any:
    if not path.is_file():
        raise ConfigError(f"{path}: {what} file not found")
    try:
        with path.open() as file:
            return yaml.safe_load(file)
    except yaml.YAMLError as error:
        raise ConfigError(f"{path}: not valid YAML: {error}") from None
