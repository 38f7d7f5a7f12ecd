"""The die reorientation task distribution: knobs, presets, task instances and reward terms.

Imports no simulator, so a curriculum can be checked before MuJoCo and torch load.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any, ClassVar

from myo_sds.envs.knobs import (
    GoalChain,
    Range,
    RecordedStart,
    TaskKnobs,
    check_complete,
    count,
    goal_chain_setting,
    optional,
    parse_range,
    ranged,
    recorded_start_setting,
    scalar,
    setting,
    to_float,
    weights,
)
from myo_sds.envs.registry import TaskSpec, solved_on_more_than

SUCCESS_STEPS = 5  # an episode succeeds when solved on more steps than this

MODEL_FILE = "myohand_die.xml"
HORIZON = 150  # control steps of 10 ms
FRAME_SKIP = 5
N_HAND_JOINTS = 23
# The official terms, then shaping terms of 2022 entries (PKU-MARL): the rotation error through a
# bounded kernel w / (d^2 + w) (1 on the goal, half at d = sqrt(w); their phase-2 work), the summed
# fingertip-to-die distance and the die's speed (both negative). ``solved`` weighted is a bonus per
# solved step; ``alive`` is 1 on every step the die is held: with negative distance terms alone,
# dropping the die ends their stream and pays (experiments/RESULTS.md, session of 2026-12-07 (II)).
# PKU-MARL's phase-1 terms (their reorient_v0.py at commit cb992b2, 2022-10-22, the policy that
# scored 71%): ``pos_kernel`` = 1 / (1 + d^2) of the position error d in m (~1 on every held step,
# so in effect an alive bonus) and ``rot_shaped`` = -0.5 r + 0.5 / (1 + r^2) of the rotation error r.
REWARD_TERMS = ("pos_dist", "rot_dist", "bonus", "act_reg", "penalty", "sparse", "solved", "done",
                "rot_kernel", "tip_dist", "die_speed", "alive", "pos_kernel", "rot_shaped")


# Features of the simulation the official observation leaves out, by name: (size, meaning); a
# critic may see them in training (policy.critic_extra).
PRIVILEGED = {
    "die_velocity": (6, "the die's linear (m/s) and angular (rad/s) joint velocities"),
    "fingertips": (15, "the five fingertips' positions relative to the die (m)"),
    "physics": (5, "the die's mass, size change and mean sliding / torsional / rolling friction"),
}


@dataclass(frozen=True)
class DieTask:
    """One task instance: the goal pose and the die's physics for the episode."""

    goal_offset: tuple[float, float, float]  # m, goal position minus its nominal position
    goal_euler: tuple[float, float, float]  # rad, intrinsic X-Y'-Z'' goal orientation
    friction: tuple[tuple[float, float, float], ...]  # per die geom (sliding, torsional, rolling)
    mass: float  # kg
    size_change: float  # m added to the die's half-sizes

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> DieTask:
        check_complete("task", values, cls.__dataclass_fields__)
        vector = lambda key: tuple(to_float(f"task.{key}[{i}]", v) for i, v in enumerate(values[key]))  # noqa: E731
        return cls(goal_offset=vector("goal_offset"), goal_euler=vector("goal_euler"),
                   friction=tuple(tuple(to_float("task.friction", v) for v in row) for row in values["friction"]),
                   mass=to_float("task.mass", values["mass"]),
                   size_change=to_float("task.size_change", values["size_change"]))

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _goal_rotation(name: str, value: Any) -> tuple[Range, Range, Range]:
    if isinstance(value, (list, tuple)) and len(value) == 3 and all(isinstance(v, (list, tuple)) for v in value):
        return tuple(parse_range(f"{name}[{i}]", v) for i, v in enumerate(value))
    return (parse_range(name, value),) * 3


def _friction_change(name: str, value: Any) -> tuple[float, float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise ValueError(f"{name}: expected 3 numbers [slide, torsion, roll], got {value!r}")
    return tuple(parse_range(f"{name}[{i}]", v, minimum=0.0).low for i, v in enumerate(value))


@dataclass(frozen=True)
class DieKnobs(TaskKnobs):
    """The task distribution and episode rules, each knob declared once."""

    KIND: ClassVar[str] = "die knob"
    PRESETS: ClassVar[Mapping[str, Mapping[str, Any]]] = {
        "p1": {},
        "p2": {"goal_position": [-0.020, 0.020], "goal_rotation": [-3.14, 3.14], "size_change": 0.007,
               "mass": [0.050, 0.250], "friction_change": [0.2, 0.001, 0.00002]},
    }

    goal_position: Range = setting(Range(-0.010, 0.010), parse=ranged(),
                                help="m, offset of the goal from its nominal position on each axis: a value or [min, max]")
    goal_rotation: tuple[Range, Range, Range] = setting(
        (Range(-1.57, 1.57),) * 3, parse=_goal_rotation,
        help="rad, goal Euler angles: [min, max] for all axes, or [[min, max] x 3] per axis")
    size_change: float = setting(0.0, parse=scalar(minimum=0.0), help="m, the die's half-sizes change by U(-value, value)")
    mass: Range = setting(Range(0.108, 0.108), parse=ranged(positive=True), help="kg, die mass: a value or [min, max]")
    friction_change: tuple[float, float, float] = setting(
        (0.0, 0.0, 0.0), parse=_friction_change, help="[slide, torsion, roll]: friction = nominal +- U(change) per geom")
    hand_noise: float = setting(0.0, parse=scalar(minimum=0.0), help="rad, uniform +- noise on the 23 hand joints at reset")
    recorded_start: RecordedStart | None = recorded_start_setting(
        "the goal is drawn as the stage's knobs say (solved_only: false records unsolved steps too)")
    goal_chain: GoalChain | None = goal_chain_setting(
        "the stage's goal_rotation; each new goal: the current orientation turned by a random rotation of "
        "U(offset) about each axis, at a new position drawn from goal_position")
    episode_steps: int | None = setting(None, parse=optional(count()),
                                        help="control steps per episode: null (the official 150) or a count, e.g. 64 "
                                             "for PKU-MARL's first stage; the score rule stays")
    rotation_kernel_width: float = setting(0.2, parse=scalar(positive=True),
                                           help="rad^2, w of the rot_kernel reward term w / (d^2 + w)")
    position_threshold: float = setting(0.025, parse=scalar(positive=True),
                                     help="m, solved when the die is closer than this to the goal ...")
    rotation_threshold: float = setting(0.262, parse=scalar(positive=True),
                                     help="rad, ... and its orientation error is below this")
    drop_threshold: float = setting(0.200, parse=scalar(positive=True),
                                 help="m, a die farther than this from the goal is dropped")
    reward_weights: Mapping[str, float] = setting(
        default_factory=lambda: {"pos_dist": 100.0, "rot_dist": 1.0, "bonus": 0.0, "act_reg": 0.0, "penalty": 0.0},
        parse=weights(REWARD_TERMS), help=f"mapping term -> weight over {', '.join(REWARD_TERMS)}")


SPEC = TaskSpec(
    name="die", knobs=DieKnobs, reward_terms=REWARD_TERMS, env_path="myo_sds.envs.die:DieEnv",
    episode_score=solved_on_more_than(SUCCESS_STEPS), gym_name="Die", privileged=PRIVILEGED,
    official_ids={"p1": "myoChallengeDieReorientP1-v0", "p2": "myoChallengeDieReorientP2-v0"},
    hand_joints=N_HAND_JOINTS,
    # The orientation error the score measures (norm of the Euler-angle differences), at the start.
    start_phase_name="the goal's angle from the die at the start")
