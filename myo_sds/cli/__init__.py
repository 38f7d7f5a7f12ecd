"""The command lines (``train.py``, ``evaluate.py``; installed: ``myo-sds-train``,
``myo-sds-evaluate``). Each ``main`` sets the process environment first
(:func:`myo_sds.set_process_environment`), before NumPy, torch and MuJoCo load: the modules
import only the standard library at their top, the rest inside ``main``."""

from __future__ import annotations

import signal
from collections.abc import Iterator
from contextlib import contextmanager


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
