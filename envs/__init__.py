"""MyoChallenge tasks on the ``mujoco`` bindings; importing registers the gymnasium ids.

The env classes (and MuJoCo) load on first use, so the task knobs (``envs.task_specs``) can be
read without them.
"""

import os

# Headless offscreen rendering by default; mujoco reads this when it is first imported.
os.environ.setdefault("MUJOCO_GL", "egl")

from gymnasium.envs.registration import register, registry  # noqa: E402

__all__ = ["BaodingEnv", "BaodingTask", "DieEnv", "DieTask", "TASKS"]

_LAZY = {"BaodingEnv": "myo_sds.envs.baoding", "BaodingTask": "myo_sds.envs.baoding_task", "DieEnv": "myo_sds.envs.die",
         "DieTask": "myo_sds.envs.die_task"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    if name == "TASKS":  # task name (as written in curricula) -> env class
        from myo_sds.envs.task_specs import TASK_SPECS

        return {task: spec.env_class() for task, spec in TASK_SPECS.items()}
    raise AttributeError(f"module 'envs' has no attribute {name!r}")


_IDS = {
    "myosds/BaodingP1-v0": ("myo_sds.envs.baoding:BaodingEnv", {"preset": "p1"}),
    "myosds/BaodingP2-v0": ("myo_sds.envs.baoding:BaodingEnv", {"preset": "p2"}),
    "myosds/Baoding-v0": ("myo_sds.envs.baoding:BaodingEnv", {}),
    "myosds/DieP1-v0": ("myo_sds.envs.die:DieEnv", {"preset": "p1"}),
    "myosds/DieP2-v0": ("myo_sds.envs.die:DieEnv", {"preset": "p2"}),
    "myosds/Die-v0": ("myo_sds.envs.die:DieEnv", {}),
}
for _id, (_entry, _kwargs) in _IDS.items():
    if _id not in registry:
        # The env truncates at its own horizon, so no TimeLimit wrapper is added.
        register(id=_id, entry_point=_entry, kwargs=_kwargs)
