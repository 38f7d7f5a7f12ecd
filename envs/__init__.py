"""MyoChallenge tasks on the ``mujoco`` bindings; importing registers the gymnasium ids of every
bundled task (``myosds/BaodingP1-v0``, ...; :mod:`myo_sds.envs.task_specs`).

The env classes (and MuJoCo) load on first use, so the task knobs can be read without them.
Rendering offscreen needs an OpenGL backend chosen before MuJoCo loads, e.g. ``MUJOCO_GL=egl``
(the command lines set it: :func:`myo_sds.set_process_environment`).
"""

from myo_sds.envs.task_specs import TASK_SPECS  # registers the gymnasium ids

# Each bundled task's env class by its name (BaodingEnv, DieEnv), imported on first use.
_LAZY = {spec.env_path.split(":")[1]: spec.env_path for spec in TASK_SPECS.values()}
__all__ = [*_LAZY, "TASKS"]


def __getattr__(name: str):
    if name in _LAZY:
        module, attribute = _LAZY[name].split(":")
        import importlib

        return getattr(importlib.import_module(module), attribute)
    if name == "TASKS":  # task name (as written in curricula) -> env class
        return {task: spec.env_class() for task, spec in TASK_SPECS.items()}
    raise AttributeError(f"module 'envs' has no attribute {name!r}")
