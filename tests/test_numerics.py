"""The command lines pin MKL, torch and NumPy to their AVX2 kernels before they load (importing
the library changes no environment), and the numerics fingerprint sees the kernel a policy's
single-row products go through."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from myo_sds.numerics import KERNEL_PINS


def _run(code: str, **env: str) -> str:
    clean = {k: v for k, v in os.environ.items() if k not in KERNEL_PINS}
    return subprocess.run([sys.executable, "-c", code], env={**clean, **env}, check=True,
                          capture_output=True, text=True).stdout.strip()


CLI = ("import os, sys\nfrom myo_sds.cli.{name} import main\n"
       "assert 'torch' not in sys.modules and 'numpy' not in sys.modules  # the command imports them in main\n"
       "main({argv})\n")


@pytest.mark.skipif(os.uname().machine != "x86_64", reason="the pins name x86-64 kernels")
def test_the_command_lines_pin_the_kernels_before_torch_loads():
    for name, argv in (("train", ["--status", "/nonexistent"]), ("evaluate", ["/nonexistent"])):
        out = _run(CLI.format(name=name, argv=argv) +
                   "import torch; print(os.environ['MKL_CBWR'], torch.backends.cpu.get_cpu_capability(), "
                   "os.environ['GOMP_SPINCOUNT'], os.environ['MUJOCO_GL'])")
        assert out.split()[-4:] == ["AVX2", "AVX2", "10000", "egl"]


def test_importing_the_library_changes_no_environment():
    code = "import os; before = dict(os.environ); import myo_sds.training, myo_sds.evaluation; print(dict(os.environ) == before)"
    assert _run(code) == "True"


def test_a_user_setting_wins_over_the_pin():
    code = "import os, myo_sds; myo_sds.set_process_environment(); print(os.environ['MKL_CBWR'])"
    assert _run(code, MKL_CBWR="COMPATIBLE") == "COMPATIBLE"


@pytest.mark.skipif(os.uname().machine != "x86_64", reason="the pins name x86-64 kernels")
def test_the_fingerprint_repeats_and_follows_the_matrix_kernel():
    code = "import myo_sds; myo_sds.set_process_environment(); import myo_sds.numerics as n; print(n.fingerprint())"
    pinned = _run(code)
    assert pinned == _run(code) == _run(code, MKL_CBWR="AVX2")
    assert len(pinned) == 12 and int(pinned, 16) >= 0
    # MKL's compatible branch (no FMA) rounds a matrix-vector product differently.
    assert _run(code, MKL_CBWR="COMPATIBLE") != pinned
