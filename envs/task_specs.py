"""The tasks a curriculum may name: their knobs and reward terms, without the simulator.

Config validation reads these, so a bad curriculum is reported before MuJoCo and torch load;
:meth:`TaskSpec.env_class` imports the env itself when one is built.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from myo_sds.envs import baoding_task, die_task


@dataclass(frozen=True)
class TaskSpec:
    """What a curriculum needs to know of a task.

    Attributes:
        knob_help: each knob's name and meaning (the keys are the allowed knobs).
        parse_knobs: ``parse_knobs(preset="p1", **knobs)``: validated knobs, or ``ValueError``.
        reward_terms: names of the reward terms the env reports in ``info``.
        env_path: ``"module:Class"`` of the env.
    """

    knob_help: Mapping[str, str]
    parse_knobs: Callable[..., Any]
    reward_terms: tuple[str, ...]
    env_path: str

    def env_class(self) -> type:
        module, name = self.env_path.split(":")
        return getattr(importlib.import_module(module), name)


TASK_SPECS: dict[str, TaskSpec] = {
    "baoding": TaskSpec(baoding_task.KNOB_HELP, baoding_task.parse_knobs, baoding_task.REWARD_TERMS,
                        "myo_sds.envs.baoding:BaodingEnv"),
    "die": TaskSpec(die_task.KNOB_HELP, die_task.parse_knobs, die_task.REWARD_TERMS, "myo_sds.envs.die:DieEnv"),
}
