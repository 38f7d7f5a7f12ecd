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

In a source checkout ``envs/``, ``curricula/`` and ``configs/`` sit at the top of the repository,
beside this folder; an installed wheel has them inside the package. Either way they are
imported as ``myo_sds.envs`` and ``myo_sds.curricula`` (a top-level ``envs`` would clash with
other projects' in site-packages).
"""

import os as _os
from pathlib import Path as _Path

_PACKAGE = _Path(__file__).resolve().parent
if not (_PACKAGE / "envs").is_dir():  # a source checkout: the subpackages are at the top
    __path__.append(str(_PACKAGE.parent))  # noqa: F821  (the package's own search path)


def process_environment() -> dict[str, str]:
    """The environment variables a process that trains or evaluates sets before NumPy, torch
    and MuJoCo load: their AVX2 kernels (the same results on every AVX2 CPU,
    ``myo_sds/numerics.py``) and a short OpenMP spin (``myo_sds/threads.py``). A variable the
    user set is left as it is."""
    from myo_sds.numerics import KERNEL_PINS
    from myo_sds.threads import OPENMP_SPIN

    return {**KERNEL_PINS, **OPENMP_SPIN}


def set_process_environment() -> None:
    """Set :func:`process_environment` (a user's own setting wins). The command lines and the
    Ray workers do it first thing; a script that imports the package does it before importing
    NumPy or torch to replay this project's numbers bit for bit."""
    for name, value in process_environment().items():
        _os.environ.setdefault(name, value)


def bundled_path(kind: str, name: str) -> _Path | None:
    """The bundled ``configs`` or ``curricula`` YAML called ``name`` (with or without .yaml)."""
    base = _PACKAGE / kind if (_PACKAGE / kind).is_dir() else _PACKAGE.parent / kind
    path = base / (name if name.endswith((".yaml", ".yml")) else f"{name}.yaml")
    return path if path.is_file() else None
