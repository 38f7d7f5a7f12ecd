"""The same floating-point results on every x86-64 CPU with AVX2, and a fingerprint that tells.

A Baoding episode is chaotic: a last-bit difference in one matrix product grows, over 200
closed-loop steps, into a different episode. The libraries pick their kernels by the CPU they
find: MKL (torch's matrix products) has its own code paths per CPU maker and vector width,
torch and NumPy dispatch to AVX-512 where the CPU has it. Measured on one policy and one
start (``experiments/RESULTS.md``, "Scores that depend on the CPU"): the shipped P1 policy
solved 139 of 200 steps on an Intel Xeon and 61 on an AMD EPYC with the same software;
setting MKL's reproducibility branch alone moved the EPYC's episode to 123.

:data:`KERNEL_PINS` ask every library for its AVX2 path; the command lines set them before any
of the libraries loads (``myo_sds.set_process_environment``; a variable set by the user wins), so that evaluations and runs repeat across
machines. :func:`fingerprint` hashes a few computations through those kernels (an LSTM,
transcendental functions, MuJoCo steps of the hand): two machines with the same fingerprint
replay each other's episodes bit for bit. Evaluations record it.
"""

from __future__ import annotations

import hashlib
import os
import platform
from typing import Any

# Each library's switch for the AVX2 code path, set before it loads.
KERNEL_PINS: dict[str, str] = {
    "MKL_CBWR": "AVX2",  # MKL's conditional numerical reproducibility branch
    "ATEN_CPU_CAPABILITY": "avx2",  # torch's own vectorized kernels
    "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR",  # NumPy's AVX-512 loops
}


def cpu_name() -> str:
    try:
        with open("/proc/cpuinfo") as cpuinfo:
            for line in cpuinfo:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def fingerprint() -> str:
    """12 hex digits of a hash over an LSTM pass, linear layers on 20 rows and on one,
    NumPy's transcendental functions and 20 MuJoCo steps of the MyoHand with the balls, all
    from fixed inputs."""
    import mujoco
    import numpy as np
    import torch

    from myo_sds.envs.assets import load_hand_model
    from myo_sds.envs.baoding_task import MODEL_FILE

    digest = hashlib.sha256()
    rng = np.random.default_rng(0)
    with torch.no_grad():
        torch.manual_seed(0)
        lstm, head = torch.nn.LSTM(86, 128), torch.nn.Linear(128, 39)
        inputs = torch.as_tensor(rng.standard_normal((20, 1, 86)), dtype=torch.float32)
        outputs, _ = lstm(inputs)
        digest.update(torch.tanh(head(outputs)).numpy().tobytes())
        # One row at a time, as a policy acts (MKL's matrix-vector kernel differs by CPU).
        digest.update(head(outputs[-1]).numpy().tobytes())
    angles = rng.uniform(-10.0, 10.0, 4096)
    digest.update(np.sin(angles).tobytes() + np.cos(angles).tobytes() + np.exp(angles / 4).tobytes())
    model, _ = load_hand_model(MODEL_FILE)
    data = mujoco.MjData(model)
    for _ in range(20):
        data.ctrl[:] = rng.uniform(0.0, 1.0, model.nu)
        mujoco.mj_step(model, data)
    digest.update(data.qpos.tobytes() + data.qvel.tobytes())
    return digest.hexdigest()[:12]


def describe() -> dict[str, Any]:
    """What an evaluation records of the machine's numerics."""
    return {"fingerprint": fingerprint(), "cpu": cpu_name(),
            "pins": {name: os.environ.get(name, "") for name in KERNEL_PINS}}


def package_versions() -> dict[str, str]:
    """Versions of Python, the platform and the libraries a run depends on (its ``versions.json``)."""
    import platform
    from importlib import metadata

    versions = {"python": platform.python_version(), "platform": platform.platform()}
    for name in ("mujoco", "gymnasium", "stable-baselines3", "sb3-contrib", "torch", "numpy", "myosuite"):
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions
