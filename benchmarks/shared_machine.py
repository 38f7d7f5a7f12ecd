"""Training throughput when the CPUs are shared: alone, two side by side, beside a stress process.

    python benchmarks/shared_machine.py [--config configs/quickstart.yaml] [--steps 40000]
                                        [--set num_threads=2 ...] [--env NAME=VALUE ...] [--json FILE]

Runs ``train.py`` in separate processes, as a user would:
- solo: one training on an otherwise idle machine;
- pair: two identical trainings started together (a user training two seeds at once);
- stress: one training beside one CPU-bound process (any other job on the workstation);
- idle stress: the same CPU-bound process at idle priority (Linux SCHED_IDLE);
- background: one training beside a second one started with ``--background`` (which runs on,
  three times as long, and is stopped when the first ends).

Each training's env steps/s is its step count over its own training wall time (from its run
folder, so process start-up is not counted), reported against the solo figure. ``--set`` passes
config overrides and ``--env`` environment variables to every training:
``--set num_threads=2 --env GOMP_SPINCOUNT=300000`` is the setting before the update's threads
followed the other processes (two torch threads, libgomp's default spin count).
"""

from __future__ import annotations

from myo_sds import set_process_environment

set_process_environment()  # before NumPy, torch and MuJoCo load: pinned kernels, short OpenMP spins

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

STRESS = "while True: pass"
IDLE_STRESS = "import os\nos.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))\nwhile True: pass"


def _train(config: Path, steps: int, overrides: list[str], env: dict[str, str], run_dir: Path,
           background: bool = False) -> subprocess.Popen:
    command = [sys.executable, str(REPO / "train.py"), "--config", str(config), "--run-dir", str(run_dir),
               "--total-steps", str(steps), "--no-progress"] + (["--background"] if background else [])
    for override in overrides:
        command += ["--set", override]
    return subprocess.Popen(command, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, **env})


def _throughput(process: subprocess.Popen, run_dir: Path) -> float:
    from myo_sds.run_folder import RunFolder

    _, stderr = process.communicate()
    if process.returncode != 0:
        raise RuntimeError(f"training in {run_dir} failed ({process.returncode}):\n{stderr[-2000:]}")
    state = RunFolder(run_dir).read_state()
    return state.num_timesteps / state.wall_s


def run_scenario(name: str, trainings: int, stress: str | None, background: bool, config: Path, steps: int,
                 overrides: list[str], env: dict[str, str], folder: Path) -> list[float]:
    """Env steps/s of each training of one scenario (not of the background one)."""
    stressor = None
    if stress is not None:
        stressor = subprocess.Popen([sys.executable, "-c", IDLE_STRESS if stress == "idle" else STRESS])
    extra = _train(config, 3 * steps, overrides, env, folder / f"{name}-background", background=True) \
        if background else None
    try:
        if stressor is not None or extra is not None:
            time.sleep(1.0)  # let it take its core
        runs = [folder / f"{name}-{index}" for index in range(trainings)]
        processes = [_train(config, steps, overrides, env, run) for run in runs]
        return [_throughput(process, run) for process, run in zip(processes, runs)]
    finally:
        for process in (stressor, extra):
            if process is not None:
                process.kill()
                process.wait()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", type=Path, default=REPO / "configs" / "quickstart.yaml")
    parser.add_argument("--steps", type=int, default=40_000, help="env steps per training")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--env", dest="env", action="append", default=[], metavar="NAME=VALUE",
                        help="environment variable for the trainings")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    env = dict(item.split("=", 1) for item in args.env)
    from myo_sds.threads import available_cpus

    print(f"{available_cpus()} CPUs; config {args.config.name}, {args.steps} env steps per training"
          + "".join(f", --set {o}" for o in args.overrides) + "".join(f", {e}" for e in args.env), flush=True)
    results: dict[str, list[float]] = {}
    with tempfile.TemporaryDirectory(prefix="shared_machine_") as tmp:
        scenarios = [("solo", 1, None, False), ("pair", 2, None, False), ("stress", 1, "normal", False)]
        if hasattr(os, "SCHED_IDLE"):
            scenarios += [("idle stress", 1, "idle", False), ("background", 1, None, True)]
        for name, trainings, stress, background in scenarios:
            results[name] = run_scenario(name, trainings, stress, background, args.config, args.steps,
                                         args.overrides, env, Path(tmp))
            print(f"  {name:<11} {', '.join(f'{rate:7.0f}' for rate in results[name])} env steps/s", flush=True)
    solo = results["solo"][0]
    print(f"\n{'scenario':<36}{'env steps/s':>12}{'vs solo':>9}")
    rows = [("alone", solo)]
    rows += [(f"two side by side: training {index + 1}", rate) for index, rate in enumerate(results["pair"])]
    rows += [("beside a CPU-bound process", results["stress"][0])]
    if "background" in results:
        rows += [("beside one at idle priority", results["idle stress"][0]),
                 ("beside a --background training", results["background"][0])]
    for label, rate in rows:
        print(f"{label:<36}{rate:>12.0f}{rate / solo:>8.2f}x")
    if args.json:
        args.json.write_text(json.dumps({"config": str(args.config), "steps": args.steps, "overrides": args.overrides,
                                         "env": env,
                                         "cpus": available_cpus(), "steps_per_s": results,
                                         "vs_solo": {k: [r / solo for r in v] for k, v in results.items()}}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
