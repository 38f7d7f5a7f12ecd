"""Declaring a setting once: its default, how a written value is read, and what it means.

Every configurable value of the pipeline, an env knob (``envs/knobs.py``) as much as a PPO or
Ray setting (``myo_sds/run_settings.py``), a stage's rule (``curricula/schema.py``) or the run
config's top level, is a field of a frozen dataclass declared with :func:`setting`. A parser is
``parse(name, value) -> typed value`` and raises ``ValueError("name: what is wrong")``; reading
a YAML mapping (:func:`read_settings`) turns that into a ``ConfigError`` naming the file and
the key path. Imports nothing heavy: configs are checked before MuJoCo and torch load.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import MISSING, field, fields
from typing import Any

Parser = Callable[[str, Any], Any]  # (key path, value as written) -> typed value, or ValueError


def setting(default: Any = MISSING, *, parse: Parser, help: str, default_factory: Callable[[], Any] | Any = MISSING):
    """A setting, declared once as a dataclass field: its type (the annotation), its default,
    how a written value is checked and read, and what it means (for errors and references)."""
    return field(default=default, default_factory=default_factory, metadata={"parse": parse, "help": help})


def describe(cls: type) -> dict[str, str]:
    """Each setting's name and meaning, in declaration order."""
    return {f.name: f.metadata["help"] for f in fields(cls)}


def read_settings(reader, key: str, raw: Any, cls: type) -> Any:
    """A settings dataclass from a YAML mapping (``None``: all defaults): unknown keys and bad
    values raise the reader's ``ConfigError``, naming the file (or ``--set``) and key path."""
    declared = {f.name: f for f in fields(cls)}
    raw = reader.mapping(key, raw, tuple(declared))
    values = {}
    for name, value in raw.items():
        path = f"{key}.{name}" if key else name
        try:
            values[name] = declared[name].metadata["parse"](path, value)
        except ValueError as error:
            raise reader.error(*split_message(path, str(error))) from None
    missing = [f.name for f in declared.values()
               if f.default is MISSING and f.default_factory is MISSING and f.name not in values]
    if missing:
        path = f"{key}.{missing[0]}" if key else missing[0]
        raise reader.error(path, f"missing: {declared[missing[0]].metadata['help']}")
    return cls(**values)


def split_message(path: str, message: str) -> tuple[str, str]:
    """(key path, message) of a parser's ``"path.to.key: message"`` (it may name a deeper key)."""
    if message.startswith(path):
        where, _, rest = message.partition(": ")
        return where, rest
    return path, message


def check_keys(name: str, written: Any, allowed: tuple[str, ...]) -> None:
    """A written mapping's keys all among ``allowed``, else ``ValueError`` naming the first other
    one, the nearest allowed name and all of them."""
    import difflib
    from collections.abc import Mapping

    if not isinstance(written, Mapping):
        raise ValueError(f"{name}: expected a mapping, got {type(written).__name__} {written!r}")
    for key in written:
        if key not in allowed:
            near = difflib.get_close_matches(str(key), allowed, n=1)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise ValueError(f"{name}.{key}: unknown key{hint}; allowed: {', '.join(allowed)}")


# -- parsers -----------------------------------------------------------------------------

def number(low: float | None = None, high: float | None = None, strict_low: bool = False,
           integer: bool = False) -> Parser:
    """A finite number (numeric strings too: PyYAML reads ``1e-3`` as one) within the bounds."""
    kind = "an integer" if integer else "a number"

    def parse(name: str, value: Any):
        if isinstance(value, bool):
            raise ValueError(f"{name}: expected {kind}, got the boolean {value!r}")
        try:
            result = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{name}: expected {kind}, got {value!r}") from None
        if not math.isfinite(result):
            raise ValueError(f"{name}: expected a finite number, got {value!r}")
        if integer:
            if result != int(result):
                raise ValueError(f"{name}: expected an integer, got {value!r}")
            result = int(result)
        if low is not None and (result <= low if strict_low else result < low):
            raise ValueError(f"{name}: must be {'>' if strict_low else '>='} {low}, got {value!r}")
        if high is not None and result > high:
            raise ValueError(f"{name}: must be <= {high}, got {value!r}")
        return result
    return parse


def integer(low: int) -> Parser:
    return number(low=low, integer=True)


def boolean(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{name}: expected true or false, got {value!r}")
    return value


def one_of(*allowed: str) -> Parser:
    def parse(name: str, value: Any) -> str:
        if value not in allowed:
            raise ValueError(f"{name}: {value!r} is not one of {', '.join(allowed)}")
        return value
    return parse


def text(name: str, value: Any) -> str:
    if not isinstance(value, str) or not value:
        raise ValueError(f"{name}: expected a non-empty string, got {value!r}")
    return value


def optional(parse: Parser) -> Parser:
    """``null`` (None) or what ``parse`` reads."""
    return lambda name, value: None if value is None else parse(name, value)
