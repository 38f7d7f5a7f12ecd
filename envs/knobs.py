"""Parsing and checking of env knobs: scalars, ranges and choices.

Knob values come from Python callers and from YAML curricula, so every parser takes the
knob's name and says exactly what is wrong and what is allowed. PyYAML reads ``1e-3`` as a
string; numbers given as strings are accepted when they parse as floats.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import MISSING, dataclass, fields
from typing import Any, ClassVar

import numpy as np

from myo_sds.envs.declare import (  # noqa: F401  (the knobs' helpers)
    Parser,
    boolean,
    describe,
    near_hint,
    number,
    one_of,
    optional,
    parse_settings,
    setting,
)

# A finite float from a number or numeric string, else ``ValueError`` naming the knob.
to_float: Parser = number()


@dataclass(frozen=True)
class Range:
    """A closed interval sampled uniformly; ``low == high`` is a fixed value."""

    low: float
    high: float

    def sample(self, rng: np.random.Generator) -> float:
        """One uniform draw (always consumes one draw, even for a fixed value)."""
        return float(rng.uniform(low=self.low, high=self.high))

    @property
    def is_fixed(self) -> bool:
        return self.low == self.high



def parse_range(name: str, value: Any, *, minimum: float | None = None,
                positive: bool = False) -> Range:
    """A :class:`Range` from a number (fixed value) or a ``[low, high]`` pair.

    Raises:
        ValueError: for a non-number, a pair that is not two numbers, an empty or
            reversed range, or a value below ``minimum`` / not above 0 when ``positive``.
    """
    if isinstance(value, Range):
        low, high = value.low, value.high
    elif isinstance(value, (list, tuple)):
        if len(value) != 2:
            raise ValueError(f"{name}: a range is [low, high], got {list(value)!r}")
        low, high = to_float(f"{name}[0]", value[0]), to_float(f"{name}[1]", value[1])
        if low > high:
            raise ValueError(f"{name}: range [{low}, {high}] is reversed (low > high)")
    else:
        low = high = to_float(name, value)
    if positive and low <= 0:
        raise ValueError(f"{name}: must be > 0, got {low}")
    if minimum is not None and low < minimum:
        raise ValueError(f"{name}: must be >= {minimum}, got {low}")
    return Range(low, high)


def parse_vector_range(name: str, value: Any, size: int) -> tuple[np.ndarray, np.ndarray]:
    """``(low, high)`` arrays from a fixed ``size``-vector or a ``[low_vector, high_vector]`` pair."""
    array = np.asarray(value, dtype=object)
    try:
        if array.shape == (size,):
            low = high = np.array([to_float(f"{name}[{i}]", v) for i, v in enumerate(value)])
        elif array.shape == (2, size):
            low = np.array([to_float(f"{name}[0][{i}]", v) for i, v in enumerate(value[0])])
            high = np.array([to_float(f"{name}[1][{i}]", v) for i, v in enumerate(value[1])])
        else:
            raise ValueError
    except (ValueError, TypeError) as error:
        if str(error):
            raise
        raise ValueError(
            f"{name}: expected {size} numbers or a pair [[{size} lows], [{size} highs]], "
            f"got {value!r}") from None
    if np.any(low > high):
        raise ValueError(f"{name}: range low {low.tolist()} exceeds high {high.tolist()}")
    return low, high


def parse_choice(name: str, value: Any, allowed: Iterable[str]) -> str:
    """``value`` if it is one of ``allowed``, else ``ValueError`` listing them."""
    allowed = tuple(allowed)
    if value not in allowed:
        raise ValueError(f"{name}: {value!r} is not one of {', '.join(allowed)}")
    return value


def parse_probability(name: str, value: Any) -> float:
    number = to_float(name, value)
    if not 0.0 <= number <= 1.0:
        raise ValueError(f"{name}: a probability must be in [0, 1], got {number}")
    return number


def check_known(kind: str, given: Mapping[str, Any], allowed: Iterable[str]) -> None:
    """Raise ``ValueError`` naming every unknown key, the nearest allowed one and all allowed
    (for keyword arguments; a written mapping is checked by ``declare.check_keys``)."""
    allowed = sorted(allowed)
    unknown = [key for key in given if key not in allowed]
    if unknown:
        hints = [f"{key!r}{near_hint(key, allowed)}" for key in unknown]
        raise ValueError(f"unknown {kind} {', '.join(hints)}; allowed: {', '.join(allowed)}")


def check_complete(kind: str, given: Mapping[str, Any], names: Iterable[str]) -> None:
    """Every field of a ``kind`` record (e.g. a task instance) given, and nothing else."""
    names = list(names)
    check_known(f"{kind} field", given, names)
    missing = [name for name in names if name not in given]
    if missing:
        raise ValueError(f"{kind}: missing field(s) {', '.join(missing)}")


def merge_preset(kind: str, preset: str, presets: Mapping[str, Mapping[str, Any]],
                 knobs: Mapping[str, Any], allowed: Iterable[str]) -> dict[str, Any]:
    """A preset's raw knob values with ``knobs`` over them, after checking both names."""
    parse_choice("preset", preset, presets)
    check_known(kind, knobs, allowed)
    return {**presets[preset], **knobs}


def parse_weights(name: str, weights: Mapping[str, Any], terms: Iterable[str]) -> dict[str, float]:
    """Reward weights keyed by term name; unknown terms are an error."""
    if not isinstance(weights, Mapping):
        raise ValueError(f"{name}: expected a mapping of term -> weight, got {weights!r}")
    check_known(f"reward term in {name}", weights, terms)
    return {term: to_float(f"{name}.{term}", weight) for term, weight in weights.items()}


@dataclass(frozen=True)
class RecordedStart:
    """Starts from simulator states the env recorded in its own earlier episodes.

    Every ``every`` control steps of an episode (only solved steps when ``solved_only``), the
    whole state (joint angles, velocities, muscle activations) is offered to a bank of at most
    ``capacity`` states (reservoir sampling: each offered state equally likely to be kept); at a
    reset, with ``probability``, a random banked state replaces the stage's start and the task
    places its goal relative to it. The bank lives in the env: it is empty after a restart
    (``--resume``) and refills as the episodes go on.
    """

    probability: float = setting(MISSING, parse=lambda name, value: parse_probability(name, value),
                                 help="the share of resets from a recorded state")
    capacity: int = setting(1000, parse=lambda name, value: count()(name, value), help="states kept per env")
    every: int = setting(4, parse=lambda name, value: count()(name, value), help="control steps between offers")
    solved_only: bool = setting(True, parse=boolean, help="offer solved steps only")

    def __post_init__(self) -> None:
        if self.probability == 0:
            raise ValueError("probability: must be > 0 (write null to turn recorded starts off)")


def recorded_start_setting(what: str):
    """The ``recorded_start`` knob of a task; ``what`` says how its goal is placed on a recorded start."""
    return setting(None, parse=optional(parse_recorded_start),
                   help="null, or {probability, capacity: 1000, every: 4, solved_only: true}: a share of resets starts "
                        "from a whole state (joints, velocities, activations) recorded in this env's own earlier "
                        f"episodes; {what}; the bank is per env, bounded, and refills after --resume")


def parse_recorded_start(name: str, value: Any) -> RecordedStart:
    """A :class:`RecordedStart` from ``{probability: p, capacity: n, every: k, solved_only: bool}``
    (only ``probability`` required)."""
    if isinstance(value, RecordedStart):
        return value
    if not isinstance(value, Mapping):
        raise ValueError(f"{name}: expected a mapping like {{probability: 0.5, capacity: 1000, every: 4}}, "
                         f"got {value!r}")
    return parse_settings(name, value, RecordedStart)


@dataclass(frozen=True)
class GoalChain:
    """Goals chained inside an episode: after ``after_solved`` solved steps (counted since the
    current goal was set, not necessarily in a row) the episode goes on with a new goal, drawn
    relative to the current one (each task says how: ``offset``). The episode's horizon and
    score rule stay; its result counts the goals reached. PKU-MARL chained die goals this way
    in 2022 (after 5 solved steps); AL4Muscles re-drew Baoding targets at new phases."""

    after_solved: int = setting(5, parse=lambda name, value: count()(name, value),
                                help="solved steps on a goal before the next one is drawn")
    offset: Range | None = setting(None, parse=lambda name, value: None if value is None else parse_range(name, value),
                                   help="the new goal relative to the current one (Baoding: rad added to the "
                                        "targets' phase; the die: rad of the random rotation about each axis "
                                        "composed onto the goal's orientation); null: the task's default")


def goal_chain_setting(default_offset: str):
    """The ``goal_chain`` knob of a task; ``default_offset`` says what a null ``offset`` means."""
    return setting(None, parse=optional(lambda name, value: parse_settings(name, value, GoalChain)),
                   help="null, or {after_solved: 5, offset: [low, high]}: after that many solved steps the episode "
                        f"goes on with a new goal; offset null: {default_offset}")


# -- declaring a task's knobs --------------------------------------------------------------

DEFAULT_PRESET = "p1"


class TaskKnobs:
    """Base of a task's knob dataclass (``@dataclass(frozen=True)`` subclasses whose fields are
    :func:`~myo_sds.envs.declare.setting` declarations). ``parse`` turns a preset and written values into an instance."""

    KIND: ClassVar[str]  # "Baoding knob", in error messages
    PRESETS: ClassVar[Mapping[str, Mapping[str, Any]]]  # preset name -> written values

    @classmethod
    def help(cls) -> dict[str, str]:
        """Each knob's name and meaning, in declaration order."""
        return describe(cls)

    @classmethod
    def parse(cls, preset: str = DEFAULT_PRESET, **written: Any):
        """The knobs of ``preset`` with ``written`` values over them, each checked.

        Raises:
            ValueError: naming an unknown preset or knob (with the allowed ones), or a bad value.
        """
        merged = merge_preset(cls.KIND, preset, cls.PRESETS, written, cls.help())
        parsers = {f.name: f.metadata["parse"] for f in fields(cls)}
        return cls(**{name: parsers[name](name, value) for name, value in merged.items()})


def ranged(*, positive: bool = False, minimum: float | None = None) -> Parser:
    """A :class:`Range` knob (a value or ``[low, high]``)."""
    return lambda name, value: parse_range(name, value, positive=positive, minimum=minimum)


def scalar(*, positive: bool = False, minimum: float | None = None) -> Parser:
    """A single number, with the same checks as a range."""
    return lambda name, value: parse_range(name, value, positive=positive, minimum=minimum).low


def count() -> Parser:
    """A whole number above 0 (``400``; ``4e2`` and ``400.0`` too, as YAML may write them)."""
    def parse(name: str, value: Any) -> int:
        number = to_float(name, value) if not isinstance(value, bool) else math.nan
        if not (number >= 1 and number == int(number)):
            raise ValueError(f"{name}: expected a whole number >= 1, got {value!r}")
        return int(number)
    return parse


def choice(*allowed: str) -> Parser:
    return one_of(*allowed)


def weights(terms: Iterable[str]) -> Parser:
    terms = tuple(terms)
    return lambda name, value: parse_weights(name, value, terms)
