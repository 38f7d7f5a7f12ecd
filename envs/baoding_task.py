"""The Baoding balls task distribution: knobs, presets, task instances and reward terms.

Imports no simulator, so a curriculum can be checked before MuJoCo and torch load.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
from myo_sds.envs.knobs import (
    Range,
    check_complete,
    merge_preset,
    parse_choice,
    parse_probability,
    parse_range,
    parse_vector_range,
    parse_weights,
    to_float,
)

MODEL_FILE = "myohand_baoding.xml"
HORIZON = 200  # control steps of 25 ms: a 5 s episode
FRAME_SKIP = 10
DIRECTIONS = ("hold", "cw", "ccw")
_DIRECTION_SIGN = {"hold": 0, "cw": -1, "ccw": 1}
OFFICIAL_START_ANGLE = math.pi / 4  # myosuite 3.0.0; ball 2 starts pi behind
# The 2022 envs' start angle: each target then sits within the solved radius of its ball.
ON_BALLS_START_ANGLE = 3 * math.pi / 4
ORBIT_CENTER = (-0.0125, -0.07)  # m, in the frame of the palm body carrying the target sites
NOMINAL_FRICTION = (1.0, 0.005, 0.0001)
REWARD_TERMS = ("pos_dist_1", "pos_dist_2", "act_reg", "solved", "alive", "done", "sparse")
N_HAND_JOINTS = 23
N_WRIST_JOINTS = 3  # pro_sup, deviation, flexion; the other 20 hand joints are fingers


@dataclass(frozen=True)
class BaodingTask:
    """One task instance: everything that is drawn at reset and fixed for the episode.

    ``period`` is the time of one revolution of the targets in seconds (``math.inf``:
    the targets never move). Sizes are ball radii (m), masses kg, frictions MuJoCo's
    (sliding, torsional, rolling) coefficients.
    """

    direction: str
    period: float
    x_radius: float
    y_radius: float
    start_angle: float
    ball_size: tuple[float, float]
    ball_mass: tuple[float, float]
    ball_friction: tuple[tuple[float, float, float], tuple[float, float, float]]

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> "BaodingTask":
        """Build and check a task from a mapping with exactly this class's fields."""
        check_complete("task", values, cls.__dataclass_fields__)
        period = values["period"]
        period = math.inf if period in ("static", math.inf) else to_float("task.period", period)
        if period <= 0:
            raise ValueError(f"task.period: must be > 0 or 'static', got {period}")
        pair = lambda key: tuple(to_float(f"task.{key}[{i}]", v) for i, v in enumerate(values[key]))  # noqa: E731
        friction = tuple(
            tuple(to_float(f"task.ball_friction[{i}][{j}]", v) for j, v in enumerate(row))
            for i, row in enumerate(values["ball_friction"]))
        task = cls(
            direction=parse_choice("task.direction", values["direction"], DIRECTIONS),
            period=period,
            x_radius=to_float("task.x_radius", values["x_radius"]),
            y_radius=to_float("task.y_radius", values["y_radius"]),
            start_angle=to_float("task.start_angle", values["start_angle"]),
            ball_size=pair("ball_size"), ball_mass=pair("ball_mass"), ball_friction=friction)
        if len(task.ball_size) != 2 or len(task.ball_mass) != 2 or len(friction) != 2 or any(
                len(row) != 3 for row in friction):
            raise ValueError("task: ball_size and ball_mass take 2 values, ball_friction 2 x 3")
        return task

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly fields (a static period is written ``"static"``)."""
        values = asdict(self)
        if math.isinf(self.period):
            values["period"] = "static"
        return values


@dataclass(frozen=True)
class BaodingKnobs:
    """The task distribution and episode rules; see :data:`KNOB_HELP` for each field."""

    direction: str = "ccw"
    period: Range | None = Range(5.0, 5.0)  # None: static targets
    x_radius: Range = Range(0.025, 0.025)
    y_radius: Range = Range(0.028, 0.028)
    start_angle: str | float = "fixed"
    start_offset: Range | None = None
    rsi_probability: float = 0.0
    ball_size: Range | None = None
    ball_mass: Range | None = None
    ball_friction: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    finger_noise: float = 0.0
    palm_noise: float = 0.0
    drop_height: float = 1.25
    solved_radius: float = 0.015
    reward_weights: Mapping[str, float] = field(
        default_factory=lambda: {"pos_dist_1": 5.0, "pos_dist_2": 5.0})


KNOB_HELP = {
    "direction": "hold | cw | ccw | random (uniform over the three, as in P2)",
    "period": "seconds per revolution of the targets: a value, [min, max], or 'static'",
    "x_radius": "m, ellipse half-axis along the palm's x: a value or [min, max]",
    "y_radius": "m, ellipse half-axis along the palm's y: a value or [min, max]",
    "start_angle": "'fixed' (official pi/4), 'on_balls' (3pi/4), 'uniform', or radians",
    "start_offset": "rad added to the start angle: a value or [min, max]",
    "rsi_probability": "probability the balls start exactly on their targets (RSI)",
    "ball_size": "m, ball radius: null (model's 0.022), a value, or [min, max]",
    "ball_mass": "kg: null (model's 0.043), a value, or [min, max]",
    "ball_friction": "null (model's), [slide, torsion, roll], or [[3 lows], [3 highs]]",
    "finger_noise": "rad, uniform +- noise on the 20 finger joints at reset",
    "palm_noise": "rad, uniform +- noise on the 3 wrist joints at reset",
    "drop_height": "m, a ball below this height is dropped and ends the episode",
    "solved_radius": "m, both balls within this distance of their targets = solved",
    "reward_weights": f"mapping term -> weight over {', '.join(REWARD_TERMS)}",
}

PRESETS: dict[str, dict[str, Any]] = {
    "p1": {},
    "p2": {
        "direction": "random",
        "period": [4.0, 6.0],
        "x_radius": [0.020, 0.030],
        "y_radius": [0.022, 0.032],
        "start_angle": "uniform",
        "ball_size": [0.018, 0.024],
        "ball_mass": [0.030, 0.300],
        "ball_friction": [[n - c for n, c in zip(NOMINAL_FRICTION, (0.2, 0.001, 0.00002))],
                          [n + c for n, c in zip(NOMINAL_FRICTION, (0.2, 0.001, 0.00002))]],
    },
}


def parse_knobs(preset: str = "p1", **knobs: Any) -> BaodingKnobs:
    """Validated knobs: a preset's values with ``knobs`` overriding them.

    Raises:
        ValueError: naming an unknown preset or knob (with the allowed ones), or a bad value.
    """
    raw = merge_preset("Baoding knob", preset, PRESETS, knobs, KNOB_HELP)
    out: dict[str, Any] = {}
    optional_range = lambda key, **kw: None if raw[key] is None else parse_range(key, raw[key], **kw)  # noqa: E731
    if "direction" in raw:
        out["direction"] = parse_choice("direction", raw["direction"], (*DIRECTIONS, "random"))
    if "period" in raw:
        out["period"] = None if raw["period"] == "static" else parse_range(
            "period", raw["period"], positive=True)
    for key in ("x_radius", "y_radius"):
        if key in raw:
            out[key] = parse_range(key, raw[key], positive=True)
    if "start_angle" in raw:
        angle = raw["start_angle"]
        out["start_angle"] = angle if angle in ("fixed", "on_balls", "uniform") else to_float(
            "start_angle (or one of fixed, on_balls, uniform)", angle)
    if "start_offset" in raw:
        out["start_offset"] = optional_range("start_offset")
    if "rsi_probability" in raw:
        out["rsi_probability"] = parse_probability("rsi_probability", raw["rsi_probability"])
    for key in ("ball_size", "ball_mass"):
        if key in raw:
            out[key] = optional_range(key, positive=True)
    if "ball_friction" in raw:
        if raw["ball_friction"] is None:
            out["ball_friction"] = None
        else:
            low, high = parse_vector_range("ball_friction", raw["ball_friction"], 3)
            if np.any(low < 0):
                raise ValueError(f"ball_friction: coefficients must be >= 0, got {low.tolist()}")
            out["ball_friction"] = (tuple(low.tolist()), tuple(high.tolist()))
    for key in ("finger_noise", "palm_noise"):
        if key in raw:
            out[key] = parse_range(key, raw[key], minimum=0.0).low
    if "drop_height" in raw:
        out["drop_height"] = to_float("drop_height", raw["drop_height"])
    if "solved_radius" in raw:
        out["solved_radius"] = parse_range("solved_radius", raw["solved_radius"], positive=True).low
    if "reward_weights" in raw:
        out["reward_weights"] = parse_weights("reward_weights", raw["reward_weights"], REWARD_TERMS)
    return replace(BaodingKnobs(), **out)
