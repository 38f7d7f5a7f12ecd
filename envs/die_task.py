"""The die reorientation task distribution: knobs, presets, task instances and reward terms.

Imports no simulator, so a curriculum can be checked before MuJoCo and torch load.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from typing import Any

from myo_sds.envs.knobs import (
    Range,
    check_complete,
    merge_preset,
    parse_range,
    parse_weights,
    to_float,
)

MODEL_FILE = "myohand_die.xml"
HORIZON = 150  # control steps of 10 ms
FRAME_SKIP = 5
N_HAND_JOINTS = 23
REWARD_TERMS = ("pos_dist", "rot_dist", "bonus", "act_reg", "penalty", "sparse", "solved", "done")


@dataclass(frozen=True)
class DieTask:
    """One task instance: the goal pose and the die's physics for the episode."""

    goal_offset: tuple[float, float, float]  # m, goal position minus its nominal position
    goal_euler: tuple[float, float, float]  # rad, intrinsic X-Y'-Z'' goal orientation
    friction: tuple[tuple[float, float, float], ...]  # per die geom (sliding, torsional, rolling)
    mass: float  # kg
    size_change: float  # m added to the die's half-sizes

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> "DieTask":
        check_complete("task", values, cls.__dataclass_fields__)
        vector = lambda key: tuple(to_float(f"task.{key}[{i}]", v) for i, v in enumerate(values[key]))  # noqa: E731
        return cls(goal_offset=vector("goal_offset"), goal_euler=vector("goal_euler"),
                   friction=tuple(tuple(to_float("task.friction", v) for v in row) for row in values["friction"]),
                   mass=to_float("task.mass", values["mass"]),
                   size_change=to_float("task.size_change", values["size_change"]))

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class DieKnobs:
    """The task distribution and episode rules; see :data:`KNOB_HELP`."""

    goal_position: Range = Range(-0.010, 0.010)
    goal_rotation: tuple[Range, Range, Range] = (Range(-1.57, 1.57),) * 3
    size_change: float = 0.0
    mass: Range = Range(0.108, 0.108)
    friction_change: tuple[float, float, float] = (0.0, 0.0, 0.0)
    hand_noise: float = 0.0
    position_threshold: float = 0.025
    rotation_threshold: float = 0.262
    drop_threshold: float = 0.200
    reward_weights: Mapping[str, float] = field(default_factory=lambda: {
        "pos_dist": 100.0, "rot_dist": 1.0, "bonus": 0.0, "act_reg": 0.0, "penalty": 0.0})


KNOB_HELP = {
    "goal_position": "m, offset of the goal from its nominal position on each axis: a value or [min, max]",
    "goal_rotation": "rad, goal Euler angles: [min, max] for all axes, or [[min, max] x 3] per axis",
    "size_change": "m, the die's half-sizes change by U(-value, value)",
    "mass": "kg, die mass: a value or [min, max]",
    "friction_change": "[slide, torsion, roll]: friction = nominal +- U(change) per geom",
    "hand_noise": "rad, uniform +- noise on the 23 hand joints at reset",
    "position_threshold": "m, solved when the die is closer than this to the goal ...",
    "rotation_threshold": "rad, ... and its orientation error is below this",
    "drop_threshold": "m, a die farther than this from the goal is dropped",
    "reward_weights": f"mapping term -> weight over {', '.join(REWARD_TERMS)}",
}

PRESETS: dict[str, dict[str, Any]] = {
    "p1": {},
    "p2": {"goal_position": [-0.020, 0.020], "goal_rotation": [-3.14, 3.14], "size_change": 0.007,
           "mass": [0.050, 0.250], "friction_change": [0.2, 0.001, 0.00002]},
}


def parse_knobs(preset: str = "p1", **knobs: Any) -> DieKnobs:
    """Validated knobs: a preset's values with ``knobs`` overriding them.

    Raises:
        ValueError: naming an unknown preset or knob (with the allowed ones), or a bad value.
    """
    raw = merge_preset("die knob", preset, PRESETS, knobs, KNOB_HELP)
    out: dict[str, Any] = {}
    if "goal_position" in raw:
        out["goal_position"] = parse_range("goal_position", raw["goal_position"])
    if "goal_rotation" in raw:
        value = raw["goal_rotation"]
        if isinstance(value, (list, tuple)) and len(value) == 3 and all(isinstance(v, (list, tuple)) for v in value):
            out["goal_rotation"] = tuple(parse_range(f"goal_rotation[{i}]", v) for i, v in enumerate(value))
        else:
            out["goal_rotation"] = (parse_range("goal_rotation", value),) * 3
    if "size_change" in raw:
        out["size_change"] = parse_range("size_change", raw["size_change"], minimum=0.0).low
    if "mass" in raw:
        out["mass"] = parse_range("mass", raw["mass"], positive=True)
    if "friction_change" in raw:
        value = raw["friction_change"]
        if not isinstance(value, (list, tuple)) or len(value) != 3:
            raise ValueError(f"friction_change: expected 3 numbers [slide, torsion, roll], got {value!r}")
        out["friction_change"] = tuple(parse_range(f"friction_change[{i}]", v, minimum=0.0).low
                                       for i, v in enumerate(value))
    if "hand_noise" in raw:
        out["hand_noise"] = parse_range("hand_noise", raw["hand_noise"], minimum=0.0).low
    for key in ("position_threshold", "rotation_threshold", "drop_threshold"):
        if key in raw:
            out[key] = parse_range(key, raw[key], positive=True).low
    if "reward_weights" in raw:
        out["reward_weights"] = parse_weights("reward_weights", raw["reward_weights"], REWARD_TERMS)
    return replace(DieKnobs(), **out)
