"""myo-sds: static-to-dynamic stabilization curricula for the MyoHand with recurrent PPO.

The package's parts, along the data path:

- ``myo_sds.curricula``: curriculum and run-config files (YAML in, typed objects out), the
  stage advancement rule, the PPO schedule, and the bundled curricula;
- ``myo_sds.envs``: the tasks (Baoding balls, die), their knobs, rewards and official metrics;
- ``myo_sds.training``: the trainer (env and model construction, rollout collection, callbacks,
  the curriculum loop);
- ``myo_sds.run_folder``: the run folder's files and formats;
- ``myo_sds.evaluation``: official metrics, plots and videos of checkpoints;
- ``myo_sds.cli``: the ``myo-sds-train`` and ``myo-sds-evaluate`` commands.

``envs/``, ``curricula/`` and ``configs/`` sit at the top of the repository, beside this folder,
where users find and edit them; ``pyproject.toml`` declares them as the subpackages
``myo_sds.envs``, ``myo_sds.curricula`` and ``myo_sds.configs`` (a top-level ``envs`` would clash
with other projects' in site-packages), so an installed wheel has them inside the package and an
editable install (``pip install -e .``) maps the names to the folders.

Importing any module of the package sets no environment variable: the command lines call
:func:`set_process_environment` first thing, before NumPy, torch and MuJoCo load.
"""

import os as _os
from pathlib import Path as _Path

_PACKAGE = _Path(__file__).resolve().parent


def process_environment() -> dict[str, str]:
    """The environment variables a process that trains or evaluates sets before NumPy, torch
    and MuJoCo load: their AVX2 kernels (the same results on every AVX2 CPU,
    ``myo_sds/numerics.py``) and a short OpenMP spin (``myo_sds/threads.py``). A variable the
    user set is left as it is. Rendering is headless (EGL), as MuJoCo reads ``MUJOCO_GL`` when it
    is first imported."""
    from myo_sds.numerics import KERNEL_PINS
    from myo_sds.threads import OPENMP_SPIN

    return {**KERNEL_PINS, **OPENMP_SPIN, "MUJOCO_GL": "egl"}


def set_process_environment() -> None:
    """Set :func:`process_environment` (a user's own setting wins). The command lines and the
    Ray workers do it first thing; a script that imports the package does it before importing
    NumPy or torch to replay this project's numbers bit for bit."""
    for name, value in process_environment().items():
        _os.environ.setdefault(name, value)


def bundled_dir(kind: str) -> _Path:
    """The folder of the bundled ``configs`` or ``curricula`` (inside a wheel, or a checkout's top)."""
    return _PACKAGE / kind if (_PACKAGE / kind).is_dir() else _PACKAGE.parent / kind


def bundled_path(kind: str, name: str) -> _Path | None:
    """The bundled ``configs`` or ``curricula`` YAML called ``name`` (with or without .yaml)."""
    path = bundled_dir(kind) / (name if name.endswith((".yaml", ".yml")) else f"{name}.yaml")
    return path if path.is_file() else None
