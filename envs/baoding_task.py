"""The Baoding balls task distribution: knobs, presets, task instances and reward terms.

Imports no simulator, so a curriculum can be checked before MuJoCo and torch load.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any, ClassVar

import numpy as np

from myo_sds.envs.knobs import (
    GoalChain,
    Range,
    RecordedStart,
    TaskKnobs,
    check_complete,
    choice,
    count,
    goal_chain_setting,
    optional,
    parse_choice,
    parse_probability,
    parse_range,
    parse_vector_range,
    ranged,
    recorded_start_setting,
    scalar,
    setting,
    to_float,
    weights,
)
from myo_sds.envs.registry import TaskSpec, solved_fraction

MODEL_FILE = "myohand_baoding.xml"
HORIZON = 200  # control steps of 25 ms: a 5 s episode
FRAME_SKIP = 10
DIRECTIONS = ("hold", "cw", "ccw")
_DIRECTION_SIGN = {"hold": 0, "cw": -1, "ccw": 1}
OFFICIAL_START_ANGLE = math.pi / 4  # myosuite 3.0.0; ball 2 starts pi behind
# The 2022 envs' start angle: each target then sits within the solved radius of its ball.
ON_BALLS_START_ANGLE = 3 * math.pi / 4
# How an RSI start sets the balls' height; the target sites' orbit is tilted against the palm, so
# a ball at its target's height sits up to 7 mm inside the palm at some phases (experiments/RESULTS.md).
RSI_HEIGHTS = ("clear", "target", "rest")
ORBIT_CENTER = (-0.0125, -0.07)  # m, in the frame of the palm body carrying the target sites
NOMINAL_FRICTION = (1.0, 0.005, 0.0001)
REWARD_TERMS = ("pos_dist_1", "pos_dist_2", "act_reg", "solved", "alive", "done", "sparse")
N_HAND_JOINTS = 23
N_WRIST_JOINTS = 3  # pro_sup, deviation, flexion; the other 20 hand joints are fingers


# Features of the simulation the official observation leaves out, by name: (size, meaning); a
# critic may see them in training (policy.critic_extra).
PRIVILEGED = {
    "ball_spin": (6, "each ball's angular velocity (rad/s)"),
    "fingertips": (15, "the five fingertips' positions relative to the midpoint of the balls (m)"),
    "physics": (10, "each ball's radius, mass and sliding / torsional / rolling friction"),
    "goal_phase": (4, "cos and sin of the first target's orbit angle, the direction (-1, 0, 1), revolutions per s"),
}


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
    def from_mapping(cls, values: Mapping[str, Any]) -> BaodingTask:
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


def _period(name: str, value: Any) -> Range | None:
    return None if value == "static" else parse_range(name, value, positive=True)


def _start_angle(name: str, value: Any) -> str | float | tuple[float, ...]:
    if isinstance(value, (list, tuple)):
        if not value:
            raise ValueError(f"{name}: an empty list; give one or more angles in radians")
        return tuple(to_float(f"{name}[{i}]", v) for i, v in enumerate(value))
    return value if value in ("fixed", "on_balls", "uniform") else to_float(
        f"{name} (or one of fixed, on_balls, uniform, or a list of radians)", value)


def _direction(name: str, value: Any) -> str | tuple[str, ...]:
    """One direction, ``random`` (over all three), or a list of distinct directions to draw from."""
    if isinstance(value, (list, tuple)):
        if not value:
            raise ValueError(f"{name}: an empty list; give directions to draw from, e.g. [cw, ccw]")
        drawn = tuple(parse_choice(f"{name}[{i}]", v, DIRECTIONS) for i, v in enumerate(value))
        if len(set(drawn)) != len(drawn):
            raise ValueError(f"{name}: {list(value)!r} repeats a direction; each may appear once")
        return drawn
    if value not in (*DIRECTIONS, "random"):
        raise ValueError(f"{name}: {value!r} is not one of {', '.join(DIRECTIONS)}, random, "
                         f"or a list of them (e.g. [cw, ccw])")
    return value


def draw_direction(direction: str | tuple[str, ...], rng: np.random.Generator) -> str:
    """The episode's direction: ``random`` draws over all three, a list over its members (one
    draw either way), one direction is itself (no draw)."""
    options = DIRECTIONS if direction == "random" else direction if isinstance(direction, tuple) else None
    return direction if options is None else options[int(rng.choice(len(options)))]


def _friction(name: str, value: Any) -> tuple[tuple[float, ...], tuple[float, ...]]:
    low, high = parse_vector_range(name, value, 3)
    if np.any(low < 0):
        raise ValueError(f"{name}: coefficients must be >= 0, got {low.tolist()}")
    return tuple(low.tolist()), tuple(high.tolist())


@dataclass(frozen=True)
class BaodingKnobs(TaskKnobs):
    """The task distribution and episode rules, each knob declared once."""

    KIND: ClassVar[str] = "Baoding knob"
    PRESETS: ClassVar[Mapping[str, Mapping[str, Any]]] = {
        "p1": {},
        # Phase 1 as the 2022 leaderboard scored it (myosuite <= 1.2.2): the targets start on
        # the resting balls; MyoSuite 3.0.0's P1 starts them 90 degrees behind.
        "p1_2022": {"start_angle": "on_balls"},
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

    direction: str | tuple[str, ...] = setting(
        "ccw", parse=_direction,
        help="hold | cw | ccw | random (uniform over the three, as in P2) | a list to draw from uniformly, e.g. "
             "[cw, ccw] (the 2022 winner's 'random' before MyoSuite 1.2.3 added hold)")
    period: Range | None = setting(Range(5.0, 5.0), parse=_period,  # None: static targets
                                help="seconds per revolution of the targets: a value, [min, max], or 'static'")
    x_radius: Range = setting(Range(0.025, 0.025), parse=ranged(positive=True),
                           help="m, ellipse half-axis along the palm's x: a value or [min, max]")
    y_radius: Range = setting(Range(0.028, 0.028), parse=ranged(positive=True),
                           help="m, ellipse half-axis along the palm's y: a value or [min, max]")
    start_angle: str | float | tuple[float, ...] = setting(
        "fixed", parse=_start_angle,
        help="'fixed' (official pi/4), 'on_balls' (3pi/4), 'uniform', radians, or a list of radians (one drawn per reset)")
    start_offset: Range | None = setting(None, parse=optional(ranged()),
                                      help="rad added to the start angle: a value or [min, max]")
    rsi_probability: float = setting(0.0, parse=parse_probability,
                                  help="probability the balls start exactly on their targets (RSI)")
    rsi_height: str = setting("target", parse=choice(*RSI_HEIGHTS),
                           help="how an RSI start places each ball: 'clear' (on its target, then moved the least distance "
                                "out of the hand), 'target' (on its target, even inside the palm), 'rest' (the target's "
                                "x, y at the ball's resting height, as the 2022 winner's env)")
    recorded_start: RecordedStart | None = recorded_start_setting(
        "the targets are placed on the balls (plus start_offset), with the stage's direction and period")
    goal_chain: GoalChain | None = goal_chain_setting(
        "U(-0.785, 0.785) rad: the targets jump up to 45 degrees along their orbit, direction and period kept; "
        "a written offset is along the direction of travel (positive: ahead; cw flips its sign)")
    ball_size: Range | None = setting(None, parse=optional(ranged(positive=True)),
                                   help="m, ball radius: null (model's 0.022), a value, or [min, max]")
    ball_mass: Range | None = setting(None, parse=optional(ranged(positive=True)),
                                   help="kg: null (model's 0.043), a value, or [min, max]")
    ball_friction: tuple[tuple[float, ...], tuple[float, ...]] | None = setting(
        None, parse=optional(_friction), help="null (model's), [slide, torsion, roll], or [[3 lows], [3 highs]]")
    finger_noise: float = setting(0.0, parse=scalar(minimum=0.0),
                               help="rad, uniform +- noise on the 20 finger joints at reset")
    palm_noise: float = setting(0.0, parse=scalar(minimum=0.0), help="rad, uniform +- noise on the 3 wrist joints at reset")
    drop_height: float = setting(1.25, parse=to_float, help="m, a ball below this height is dropped and ends the episode")
    solved_radius: float = setting(0.015, parse=scalar(positive=True),
                                help="m, both balls within this distance of their targets = solved")
    episode_steps: int | None = setting(None, parse=optional(count()),
                                     help="control steps per episode: null (the official 200) or a count, e.g. 400 for "
                                          "two 5 s orbits; the score stays solved steps over this count")
    muscle_curve: str = setting("mujoco", parse=choice("mujoco", "2.1.0"),
                                help="'mujoco' (this MuJoCo's muscles, as MyoSuite runs them) or '2.1.0': add MuJoCo "
                                     "2.1.0's length curve, under which an over-shortened muscle pushes (the 2022 "
                                     "challenge's simulator; up to ~75 N on RI2 and RI5)")
    reward_weights: Mapping[str, float] = setting(
        default_factory=lambda: {"pos_dist_1": 5.0, "pos_dist_2": 5.0}, parse=weights(REWARD_TERMS),
        help=f"mapping term -> weight over {', '.join(REWARD_TERMS)}")


def _official_2022_start(env) -> None:
    """MyoSuite 3.0.0's P1 env with the 2022 phase-1 start (P1 keeps these through every reset)."""
    env.ball_1_starting_angle, env.ball_2_starting_angle = ON_BALLS_START_ANGLE, ON_BALLS_START_ANGLE - math.pi


SPEC = TaskSpec(
    name="baoding", knobs=BaodingKnobs, reward_terms=REWARD_TERMS, env_path="myo_sds.envs.baoding:BaodingEnv",
    episode_score=solved_fraction, gym_name="Baoding", privileged=PRIVILEGED,
    official_ids={"p1": "myoChallengeBaodingP1-v1", "p1_2022": "myoChallengeBaodingP1-v1",
                  "p2": "myoChallengeBaodingP2-v1"},
    official_setup={"p1_2022": _official_2022_start},
    preset_notes={"p1": "targets start at pi/4, 90 deg behind the balls (MyoSuite 3.0.0)",
                  "p1_2022": "targets start at 3pi/4, on the resting balls (the 2022 phase-1 leaderboard)",
                  "p2": "random start angle (P2)"},
    hand_joints=N_HAND_JOINTS, start_phase_name="the targets' start phase")
