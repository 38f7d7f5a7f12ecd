"""The tasks a curriculum may name: the bundled ones, each registered once with everything the
pipeline needs to know of it (:class:`~myo_sds.envs.registry.TaskSpec`: knobs and presets,
reward terms, env class, official score rule, official env ids). Imports no simulator: config
validation reads these before MuJoCo and torch load.

Adding a task is one module declaring its ``TaskSpec`` (its knobs, task instance and env, as
``baoding_task.py`` and ``baoding.py`` do) and one line: its spec in ``BUNDLED`` below, or a
:func:`register_task` call of one's own before the curriculum is read.
"""

from __future__ import annotations

from myo_sds.envs import baoding_task, die_task
from myo_sds.envs.registry import TASK_SPECS, TaskSpec, register_task

BUNDLED = (baoding_task.SPEC, die_task.SPEC)
for _spec in BUNDLED:
    register_task(_spec)

__all__ = ["BUNDLED", "TASK_SPECS", "TaskSpec", "register_task"]
