"""A third task, declared outside the package in one module, for the registration test: hold
the wrist's flexion joint at a target angle. It reuses the Baoding model (the balls just rest)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from myo_sds.envs.hand_env import MuscleHandEnv
from myo_sds.envs.knobs import Range, TaskKnobs, check_complete, ranged, scalar, setting, weights
from myo_sds.envs.registry import TaskSpec, solved_fraction

REWARD_TERMS = ("angle_dist", "act_reg", "solved", "done")
FLEXION = 2  # the wrist flexion joint's index in qpos


@dataclass(frozen=True)
class WristTask:
    target: float

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> WristTask:
        check_complete("task", values, ("target",))
        return cls(float(values["target"]))


@dataclass(frozen=True)
class WristKnobs(TaskKnobs):
    KIND: ClassVar[str] = "wrist knob"
    PRESETS: ClassVar[Mapping[str, Mapping[str, Any]]] = {"p1": {}, "wide": {"target": [-0.6, 0.6]}}

    target: Range = setting(Range(0.3, 0.3), parse=ranged(), help="rad, the flexion angle to hold")
    tolerance: float = setting(0.1, parse=scalar(positive=True), help="rad, solved within this of the target")
    reward_weights: Mapping[str, float] = setting(default_factory=lambda: {"angle_dist": 1.0, "solved": 1.0},
                                               parse=weights(REWARD_TERMS), help="term -> weight")


class WristEnv(MuscleHandEnv):
    MODEL_FILE = "myohand_baoding.xml"
    FRAME_SKIP = 10
    HORIZON = 20
    OBS_SIZE = 23 + 1 + 39
    TASK_NAME = "wrist"
    TASK_CLASS = WristTask
    KNOBS_CLASS = WristKnobs
    REWARD_TERMS = REWARD_TERMS

    def sample_task(self, rng: np.random.Generator) -> WristTask:
        return WristTask(self.knobs.target.sample(rng))

    def _start_episode(self, task, rng, state) -> None:
        self.data.qpos[0] = -1.57

    def _observe(self) -> np.ndarray:
        return np.concatenate([self.data.qpos[:23], [self.task.target], self.data.act])

    def _reward_terms(self) -> dict[str, float]:
        distance = abs(float(self.data.qpos[FLEXION]) - self.task.target)
        return {"angle_dist": -distance, "act_reg": -float(np.linalg.norm(self.data.act)) / self.model.na,
                "solved": float(distance < self.knobs.tolerance), "done": 0.0}


SPEC = TaskSpec(name="wrist", knobs=WristKnobs, reward_terms=REWARD_TERMS, env_path="toy_task:WristEnv",
                episode_score=solved_fraction, gym_name="ToyWrist")
