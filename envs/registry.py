"""What the pipeline knows of a task (:class:`TaskSpec`) and the registry of tasks.

A task module declares its ``TaskSpec``; :mod:`myo_sds.envs.task_specs` registers the bundled
ones, and :func:`register_task` registers any other before a curriculum names it. Imports no
simulator and no task.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from myo_sds.envs.knobs import TaskKnobs


def solved_fraction(solved_steps: int, horizon: int) -> float:
    """Baoding's official episode score: solved steps over the horizon (steps lost to an early
    drop count as unsolved)."""
    return solved_steps / horizon


def solved_on_more_than(steps: int) -> Callable[[int, int], float]:
    """An official episode score of 1 when the episode was solved on more than ``steps`` steps,
    else 0 (die reorientation: 5)."""
    return lambda solved_steps, horizon: float(solved_steps > steps)


@dataclass(frozen=True)
class TaskSpec:
    """What the pipeline needs to know of a task.

    Attributes:
        name: as written in curricula (``task: baoding``).
        knobs: the task's knob dataclass: ``knobs.help()`` names and explains each knob,
            ``knobs.parse(preset, **written)`` checks and reads them; ``knobs.PRESETS`` the presets.
        reward_terms: names of the reward terms the env reports in ``info``.
        env_path: ``"module:Class"`` of the env.
        episode_score: (solved steps, horizon) -> the official score of one episode.
        gym_name: registered as gymnasium ids ``myosds/<gym_name>-v0`` and, per preset,
            ``myosds/<gym_name><PRESET>-v0``.
        official_ids: preset -> myosuite's own env id (``evaluate.py --official``).
        official_setup: preset -> a function that sets up the official env (its unwrapped env)
            before its first reset, for a preset that differs from the id's defaults.
        preset_notes: preset -> what an evaluation report says of it (e.g. where episodes start).
        hand_joints: how many of the first ``qpos`` entries are the hand's joint angles (on our env
            and the official one alike), which ``evaluate.py --start-noise`` moves at reset; 0 for a
            task without them.
        start_phase_name: what an episode's ``start_phase`` (rad) measures, as reports name it.
        privileged: features the official observation leaves out, by name: (size, meaning); a
            critic may see them in training (``policy.critic_extra``).
    """

    name: str
    knobs: type[TaskKnobs]
    reward_terms: tuple[str, ...]
    env_path: str
    episode_score: Callable[[int, int], float]
    gym_name: str
    official_ids: Mapping[str, str] = field(default_factory=dict)
    official_setup: Mapping[str, Callable[[Any], None]] = field(default_factory=dict)
    preset_notes: Mapping[str, str] = field(default_factory=dict)
    privileged: Mapping[str, tuple[int, str]] = field(default_factory=dict)
    hand_joints: int = 0
    start_phase_name: str = "the start phase"

    def env_class(self) -> type:
        module, name = self.env_path.split(":")
        return getattr(importlib.import_module(module), name)

    def gym_ids(self) -> dict[str, dict[str, str]]:
        """Gymnasium id -> the env's keyword arguments (its preset)."""
        ids = {f"myosds/{self.gym_name}-v0": {}}
        ids.update({f"myosds/{self.gym_name}{preset.upper()}-v0": {"preset": preset} for preset in self.knobs.PRESETS})
        return ids


TASK_SPECS: dict[str, TaskSpec] = {}


def register_task(spec: TaskSpec) -> TaskSpec:
    """Make a task known to curricula, training and evaluation, and register its gymnasium ids."""
    from gymnasium.envs.registration import register, registry

    if spec.name in TASK_SPECS and TASK_SPECS[spec.name] != spec:
        raise ValueError(f"task {spec.name!r} is already registered")
    TASK_SPECS[spec.name] = spec
    for gym_id, kwargs in spec.gym_ids().items():
        if gym_id not in registry:
            # The env truncates at its own horizon, so no TimeLimit wrapper is added.
            register(id=gym_id, entry_point=spec.env_path, kwargs=kwargs)
    return spec
