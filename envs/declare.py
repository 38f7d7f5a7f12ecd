"""Declaring a setting once: its default, how a written value is read, and what it means.

Every configurable value of the pipeline, an env knob (``envs/knobs.py``) as much as a PPO or
Ray setting (``curricula/run_settings.py``), a stage's rule (``curricula/schema.py``) or the run
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


class _Unset:
    """The value of an override that was not written (``None`` is a written ``null``)."""

    def __repr__(self) -> str:
        return "UNSET"

    def __reduce__(self):
        return "UNSET"


UNSET = _Unset()


def overrides_of(cls: type, names: tuple[str, ...], name: str, doc: str) -> type:
    """A frozen dataclass of some of ``cls``'s settings, each declared as there (parser, meaning)
    but unset by default: what a later scope (a curriculum stage) changes of an earlier one's.
    ``as_dict()`` gives the written ones; a written ``null`` is kept (an optional setting off)."""
    from dataclasses import make_dataclass

    declared = {f.name: f for f in fields(cls)}
    unknown = [n for n in names if n not in declared]
    if unknown:
        raise TypeError(f"{cls.__name__} declares no {', '.join(unknown)}")
    spec = [(n, Any, setting(UNSET, parse=declared[n].metadata["parse"], help=declared[n].metadata["help"]))
            for n in names]

    def as_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not UNSET}

    made = make_dataclass(name, spec, frozen=True, namespace={"as_dict": as_dict, "__doc__": doc})
    made.__module__ = cls.__module__
    return made


def describe(cls: type) -> dict[str, str]:
    """Each setting's name and meaning, in declaration order."""
    return {f.name: f.metadata["help"] for f in fields(cls)}


def parse_settings(name: str, raw: Any, cls: type) -> Any:
    """A settings dataclass from a written mapping (``None``: all defaults), each value read by
    its field's parser; unknown keys, bad values and missing required ones raise ``ValueError``
    naming the key path (``name.key``). A class may check its fields together in ``__post_init__``
    (raising ``ValueError("key: what is wrong")``)."""
    declared = {f.name: f for f in fields(cls)}
    raw = {} if raw is None else raw
    check_keys(name, raw, tuple(declared))
    path = (lambda key: f"{name}.{key}") if name else (lambda key: key)
    values = {key: declared[key].metadata["parse"](path(key), value) for key, value in raw.items()}
    missing = [f.name for f in declared.values()
               if f.default is MISSING and f.default_factory is MISSING and f.name not in values]
    if missing:
        raise ValueError(f"{path(missing[0])}: missing: {declared[missing[0]].metadata['help']}")
    try:
        return cls(**values)
    except ValueError as error:
        raise ValueError(path(str(error))) from None


def nested(cls: type) -> Parser:
    """A parser of a mapping read into the settings dataclass ``cls`` (:func:`parse_settings`)."""
    return lambda name, value: parse_settings(name, value, cls)


def read_settings(reader, key: str, raw: Any, cls: type) -> Any:
    """A settings dataclass from a YAML mapping (``None``: all defaults): unknown keys and bad
    values raise the reader's ``ConfigError``, naming the file (or ``--set``) and key path."""
    try:
        return parse_settings(key, raw, cls)
    except ValueError as error:
        raise reader.error(*split_message(key, str(error))) from None


def split_message(path: str, message: str) -> tuple[str, str]:
    """(key path, message) of a parser's ``"path.to.key: message"`` (it may name a deeper key)."""
    if message.startswith(path):
        where, _, rest = message.partition(": ")
        return where, rest
    return path, message


def check_keys(name: str, written: Any, allowed: tuple[str, ...]) -> None:
    """A written mapping's keys all among ``allowed``, else ``ValueError`` naming the first other
    one, the nearest allowed name and all of them."""
    from collections.abc import Mapping

    if not isinstance(written, Mapping):
        raise ValueError(f"{name}: expected a mapping, got {type(written).__name__} {written!r}")
    for key in written:
        if key not in allowed:
            raise ValueError(f"{name + '.' if name else ''}{key}: unknown key{near_hint(key, allowed)}; "
                             f"allowed: {', '.join(allowed)}")


def near_hint(key: Any, allowed) -> str:
    """`` (did you mean 'x'?)`` for the allowed name nearest an unknown one, or nothing."""
    import difflib

    near = difflib.get_close_matches(str(key), list(allowed), n=1)
    return f" (did you mean {near[0]!r}?)" if near else ""


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
