"""The tasks a curriculum may name: their knobs and reward terms, without the simulator.

Config validation reads these, so a bad curriculum is reported before MuJoCo and torch load;
:meth:`TaskSpec.env_class` imports the env itself when one is built.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

from myo_sds.envs import baoding_task, die_task
from myo_sds.envs.knobs import TaskKnobs


@dataclass(frozen=True)
class TaskSpec:
    """What a curriculum needs to know of a task.

    Attributes:
        knobs: the task's knob dataclass: ``knobs.help()`` names and explains each knob,
            ``knobs.parse(preset, **written)`` checks and reads them.
        reward_terms: names of the reward terms the env reports in ``info``.
        env_path: ``"module:Class"`` of the env.
    """

    knobs: type[TaskKnobs]
    reward_terms: tuple[str, ...]
    env_path: str

    def env_class(self) -> type:
        module, name = self.env_path.split(":")
        return getattr(importlib.import_module(module), name)


TASK_SPECS: dict[str, TaskSpec] = {
    "baoding": TaskSpec(baoding_task.BaodingKnobs, baoding_task.REWARD_TERMS, "myo_sds.envs.baoding:BaodingEnv"),
    "die": TaskSpec(die_task.DieKnobs, die_task.REWARD_TERMS, "myo_sds.envs.die:DieEnv"),
}
