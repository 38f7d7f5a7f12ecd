"""MyoChallenge tasks on the ``mujoco`` bindings; importing registers the gymnasium ids."""

import os

# Headless offscreen rendering by default; mujoco reads this when it is first imported.
os.environ.setdefault("MUJOCO_GL", "egl")

from gymnasium.envs.registration import register, registry

from envs.baoding import BaodingEnv, BaodingTask
from envs.die import DieEnv, DieTask

__all__ = ["BaodingEnv", "BaodingTask", "DieEnv", "DieTask", "TASKS"]

# Task name (as written in curricula) -> env class.
TASKS = {"baoding": BaodingEnv, "die": DieEnv}

_IDS = {
    "myosds/BaodingP1-v0": ("envs.baoding:BaodingEnv", {"preset": "p1"}),
    "myosds/BaodingP2-v0": ("envs.baoding:BaodingEnv", {"preset": "p2"}),
    "myosds/Baoding-v0": ("envs.baoding:BaodingEnv", {}),
    "myosds/DieP1-v0": ("envs.die:DieEnv", {"preset": "p1"}),
    "myosds/DieP2-v0": ("envs.die:DieEnv", {"preset": "p2"}),
    "myosds/Die-v0": ("envs.die:DieEnv", {}),
}
for _id, (_entry, _kwargs) in _IDS.items():
    if _id not in registry:
        # The env truncates at its own horizon, so no TimeLimit wrapper is added.
        register(id=_id, entry_point=_entry, kwargs=_kwargs)
