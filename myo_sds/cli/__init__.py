"""The command lines (``train.py``, ``evaluate.py``; installed: ``myo-sds-train``,
``myo-sds-evaluate``). Each ``main`` sets the process environment first
(:func:`myo_sds.set_process_environment`), before NumPy, torch and MuJoCo load: the modules
import only the standard library at their top, the rest inside ``main``."""

from __future__ import annotations

import os
import shutil
import signal
import sys
from collections.abc import Iterator
from contextlib import contextmanager

# What the commands need importable: the package's mapped folders (an editable or wheel install
# maps envs/, curricula/ and configs/ into it) and the libraries.
REQUIRED = ("myo_sds.curricula", "myo_sds.envs", "numpy", "yaml", "mujoco", "gymnasium", "torch",
            "stable_baselines3", "sb3_contrib")


def missing_module() -> str | None:
    """The first of :data:`REQUIRED` this interpreter cannot import (None: all there)."""
    import importlib.util

    for name in REQUIRED:
        try:
            if importlib.util.find_spec(name) is None:
                return name
        except (ModuleNotFoundError, ValueError):
            return name
    return None


def exit_unless_installed(script: str) -> None:
    """From a checkout (``train.py``, ``evaluate.py``): if this Python lacks what the command
    needs, say in one line which Python to use or how to make it, and exit with code 2."""
    missing = missing_module()
    if missing is None:
        return
    checkout = os.path.dirname(os.path.abspath(script))
    here = lambda path: os.path.relpath(path) if not os.path.relpath(path).startswith("..") else path  # noqa: E731
    venv_python = os.path.join(checkout, ".venv", "bin", "python")
    import shlex

    command = shlex.join([here(venv_python), here(os.path.abspath(script)), *sys.argv[1:]])
    in_checkout_venv = os.path.realpath(sys.prefix) == os.path.realpath(os.path.join(checkout, ".venv"))
    if os.path.exists(venv_python) and not in_checkout_venv:
        advice = f"run it with the checkout's environment: {command}"
    else:
        advice = (f"set up the checkout's environment once with `make -C {here(checkout)} setup`, then run "
                  f"{command} (or `pip install -e {here(checkout)}` into this Python)")
    print(f"error: {sys.executable} cannot import {missing}; {advice}", file=sys.stderr)
    sys.exit(2)


def train_command() -> str:
    """How this process was started, as a command to type for the next step (a hint such as
    "continue with `... --resume RUN`"): ``myo-sds-train`` when installed, else the interpreter
    and script as run here (``.venv/bin/python train.py`` from a checkout)."""
    script = sys.argv[0] if sys.argv and sys.argv[0] else "train.py"
    if os.path.basename(script) in ("myo-sds-train", "myo-sds-evaluate"):
        return "myo-sds-train"
    if not script.endswith("train.py"):  # run as a module or from a test: the checkout's script
        script = "train.py"
    python = sys.executable
    on_path = shutil.which("python")
    if on_path and os.path.realpath(on_path) == os.path.realpath(python):
        python = "python"
    elif os.path.abspath(python).startswith(os.getcwd() + os.sep):
        python = os.path.relpath(python)
    return f"{python} {script}"


@contextmanager
def sigint_held() -> Iterator[None]:
    """Hold Ctrl-C while the compiled libraries (torch, MuJoCo) load, then act on it.

    A KeyboardInterrupt raised while a compiled module initializes surfaces as ``ImportError:
    initialization failed`` with a traceback (MuJoCo), or vanishes and the command goes on (seen
    about once in 60 signals while NumPy loads). Inside this block a SIGINT is only noted; on
    leaving, a noted one is raised as KeyboardInterrupt where Python's own handler was in place
    (a SIGINT that was ignored stays ignored)."""
    received: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if received and previous is signal.default_int_handler:
        raise KeyboardInterrupt
