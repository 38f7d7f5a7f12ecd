"""The 2022 challenge's physics against ours: same hand, different MuJoCo.

    python experiments/physics_2022.py [--policy DIR] [--episodes 80] [--start-noise RAD]
        [--stages hold,p1_2022,fixed10_ccw] [--scores-only] [--cache DIR] [--json FILE]

MyoChallenge 2022 ran MyoSuite 1.2.x on MuJoCo 2.1.0 (through free-mujoco-py), with the Baoding
hand compiled to a binary (``myo_hand_baoding.mjb``) that no MuJoCo installable on Python 3.11
reads. This script downloads (``pip download``, nothing installed) MyoSuite 1.2.2's wheel for
that file and free-mujoco-py 2.1.6's wheel for the MuJoCo 2.1.0 library and headers, loads the
library with ctypes (struct offsets from its own X-macro headers) and reports:

1. model: our compiled hand (MyoSuite 3.0.0's XML) against the 2022 binary, field by field;
2. muscle length curve: the active gain of one muscle against its normalized length, both
   MuJoCo versions (2.1.0 lets an over-shortened muscle push, see RESULTS.md);
3. one env step from identical states (along ``--policy``'s hold-stage episodes in the 2022
   physics): per-actuator force difference and hand/ball position error after 10 substeps, with
   and without 2.1.0's length curve emulated in ours;
4. ``--policy``'s score on the hold stage (random phases, balls on the targets at their resting
   heights, as the 2022 winner's env placed them), on ``p1_2022`` and on the 2022 start from
   rest counter-clockwise at 10 s per revolution (``fixed10_ccw``, the chain's ``fixed-10s``
   stage in the 2022 task's direction), stepped by the 2022 physics, by ours, and by ours with
   2.1.0's length curve; observations and rewards always come from our env (the model state is
   copied between the two simulators each step). ``--start-noise`` moves each hand joint by
   U(-noise, noise) at reset, the same offsets per seed as ``evaluate.py --start-noise``, so a
   fixed start is scored as a policy rather than as one replayed episode.

Timing-free; takes ~2-4 min for 80 episodes per physics.
"""

from __future__ import annotations

from myo_sds import set_process_environment

set_process_environment()  # before NumPy, torch and MuJoCo load: pinned kernels, short OpenMP spins

import argparse
import contextlib
import ctypes
import json
import math
import re
import subprocess
import sys
import types
import zipfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import mujoco  # noqa: E402

import myo_sds.envs.hand_env as hand_env  # noqa: E402
from myo_sds.envs.assets import load_hand_model  # noqa: E402
from myo_sds.envs.baoding import N_HAND_JOINTS, BaodingEnv  # noqa: E402
from myo_sds.envs.muscle_2022 import MuscleCurve2022  # noqa: E402
from myo_sds.evaluation.checkpoints import load_policy, resolve_checkpoint  # noqa: E402
from myo_sds.evaluation.episodes import start_offsets  # noqa: E402

WHEELS = {"free-mujoco-py==2.1.6": "free_mujoco_py-2.1.6-py3-none-any.whl",
          "MyoSuite==1.2.2": "MyoSuite-1.2.2-py2.py3-none-any.whl"}
MJ210 = "mujoco_py/binaries/linux/mujoco210/"
MJB = "myosuite/envs/myo/assets/hand/myo_hand_baoding.mjb"
STATE_FIELDS = ("qpos", "qvel", "act", "qacc_warmstart")
HOLD_STAGE = dict(preset="p1_2022", direction="hold", period="static", start_angle="uniform",
                  rsi_probability=1.0, rsi_height="rest")
STAGES = {"hold": HOLD_STAGE, "p1_2022": {"preset": "p1_2022"},
          "fixed10_ccw": {"preset": "p1_2022", "direction": "ccw", "period": 10.0}}
DTYPES = {"mjtNum": np.float64, "int": np.int32, "float": np.float32, "mjtByte": np.uint8, "char": np.uint8}


def fetch_2022_files(cache: Path) -> dict[str, Path]:
    """The MuJoCo 2.1.0 library, its headers and the 2022 Baoding binary, extracted into ``cache``."""
    cache.mkdir(parents=True, exist_ok=True)
    for requirement, wheel in WHEELS.items():
        if not (cache / wheel).exists():
            # free-mujoco-py declares Python < 3.11; we only read files from it.
            subprocess.run([sys.executable, "-m", "pip", "download", requirement, "--no-deps",
                            "--only-binary=:all:", "--python-version", "3.10", "-q", "-d", str(cache)],
                           check=True)
    members = {"lib": (WHEELS["free-mujoco-py==2.1.6"], MJ210 + "bin/libmujoco210nogl.so"),
               "mjxmacro": (WHEELS["free-mujoco-py==2.1.6"], MJ210 + "include/mjxmacro.h"),
               "mjmodel": (WHEELS["free-mujoco-py==2.1.6"], MJ210 + "include/mjmodel.h"),
               "mjb": (WHEELS["MyoSuite==1.2.2"], MJB)}
    paths = {}
    for key, (wheel, member) in members.items():
        target = cache / "extracted" / member
        if not target.exists():
            with zipfile.ZipFile(cache / wheel) as archive:
                archive.extract(member, cache / "extracted")
        paths[key] = target
    return paths


class Mujoco210:
    """A MuJoCo 2.1.0 model and data read through ctypes: numpy views of their arrays, mj_step."""

    def __init__(self, files: dict[str, Path]):
        macros = files["mjxmacro"].read_text()
        model_ptrs = self._x_macro(macros, "MJMODEL_POINTERS")
        data_ptrs = self._x_macro(macros, "MJDATA_POINTERS")
        header = files["mjmodel"].read_text()
        struct = header[header.index("struct _mjModel"):]
        size_names = re.findall(r"^\s*int (\w+);", struct[:struct.index("mjOption opt;")], re.M)
        self.lib = lib = ctypes.CDLL(str(files["lib"]))
        lib.mj_loadModel.restype = ctypes.c_void_p
        lib.mj_loadModel.argtypes = [ctypes.c_char_p, ctypes.c_void_p]
        lib.mj_makeData.restype = ctypes.c_void_p
        lib.mj_makeData.argtypes = [ctypes.c_void_p]
        for name in ("mj_step", "mj_forward", "mj_resetData"):
            getattr(lib, name).argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        lib.mju_muscleGain.restype = ctypes.c_double
        lib.mju_muscleGain.argtypes = [ctypes.c_double, ctypes.c_double, ctypes.POINTER(ctypes.c_double),
                                       ctypes.c_double, ctypes.POINTER(ctypes.c_double)]
        self.m = lib.mj_loadModel(str(files["mjb"]).encode(), None)
        if not self.m:
            raise RuntimeError(f"MuJoCo 2.1.0 could not load {files['mjb']}")
        sizes = dict(zip(size_names, np.ctypeslib.as_array(
            (ctypes.c_int32 * len(size_names)).from_address(self.m)).tolist()))
        sizes.update({"mjNDYN": 10, "mjNGAIN": 10, "mjNBIAS": 10, "mjNREF": 2, "mjNIMP": 5})
        self.sizes = sizes
        self.model = self._arrays(self.m, self._model_pointer_start(len(size_names), len(model_ptrs)),
                                  model_ptrs, sizes)
        self.d = lib.mj_makeData(self.m)
        lib.mj_resetData(self.m, self.d)
        self.data = self._arrays(self.d, self._data_pointer_start(), data_ptrs, sizes)

    @staticmethod
    def _x_macro(text: str, name: str) -> list[tuple[str, str, str, str]]:
        block = re.search(r"#define %s\s*\\\n(.*?)\n\s*\n" % name, text, re.S).group(1)
        return re.findall(r"X\(\s*(\w+),\s*(\w+),\s*(\w+),\s*(\w+)\s*\)", block)

    @staticmethod
    def _words(address: int, count: int) -> np.ndarray:
        return np.ctypeslib.as_array((ctypes.c_uint64 * count).from_address(address))

    def _model_pointer_start(self, n_sizes: int, n_pointers: int) -> int:
        """Word index of mjModel's first array pointer (qpos0): the word after ``buffer``, the
        first word followed by pointers that all fall inside the model's buffer."""
        words = self._words(self.m, 20000)
        nbuffer = self.sizes["nbuffer"]
        for i in range(n_sizes // 2, len(words) - n_pointers):
            base = int(words[i])
            following = words[i + 1:i + 1 + n_pointers].astype(np.int64)
            if base > 4096 and ((following >= base) & (following <= base + nbuffer)).mean() > 0.7:
                return i + 1
        raise RuntimeError("mjModel layout not recognised")

    def _data_pointer_start(self) -> int:
        """Word index of mjData's ``qpos`` pointer: after reset it points at qpos0, as ``buffer``
        (two words earlier, before ``stack``) does."""
        qpos0 = self.model["qpos0"]
        words = self._words(self.d, 20000)
        for i in range(len(words) - 2):
            address = int(words[i])
            if address > 1 << 20 and address % 8 == 0 and int(words[i + 2]) == address:
                values = np.ctypeslib.as_array((ctypes.c_double * len(qpos0)).from_address(address))
                if np.allclose(values, qpos0):
                    return i + 2
        raise RuntimeError("mjData layout not recognised")

    @staticmethod
    def _arrays(base: int, first_word: int, table, sizes) -> dict[str, np.ndarray]:
        words = Mujoco210._words(base, first_word + len(table))
        arrays = {}
        for k, (ctype, name, rows, cols) in enumerate(table):
            try:
                n_rows = int(rows) if rows.isdigit() else sizes[rows]
                n_cols = int(cols) if cols.isdigit() else sizes[cols]
            except KeyError:
                continue
            dtype = DTYPES.get(ctype)
            if dtype is None or n_rows * n_cols == 0:
                continue
            flat = np.ctypeslib.as_array((np.ctypeslib.as_ctypes_type(dtype) * (n_rows * n_cols))
                                         .from_address(int(words[first_word + k])))
            arrays[name] = flat.reshape(n_rows, n_cols) if n_cols > 1 else flat
        return arrays

    def step_from(self, data: mujoco.MjData, nstep: int) -> None:
        """Step ``data``'s state ``nstep`` substeps with MuJoCo 2.1.0 and write it back."""
        for field in STATE_FIELDS:
            self.data[field][:] = getattr(data, field)
        self.data["ctrl"][:] = data.ctrl
        for _ in range(nstep):
            self.lib.mj_step(self.m, self.d)
        for field in STATE_FIELDS:
            getattr(data, field)[:] = self.data[field]

    def muscle_gain(self, length: float, velocity: float, lengthrange, acc0: float, prm) -> float:
        c_range = (ctypes.c_double * 2)(*lengthrange)
        c_prm = (ctypes.c_double * 9)(*prm[:9])
        return self.lib.mju_muscleGain(length, velocity, c_range, acc0, c_prm)


# --- MuJoCo 2.1.0's muscle length curve, added to ours -----------------------------------------

@contextlib.contextmanager
def fl_210_in_ours(model: mujoco.MjModel) -> Iterator[None]:
    """Add 2.1.0's extra muscle force (over-shortened muscles) to ``model``'s passive forces
    (the env knob ``muscle_curve: '2.1.0'`` does the same per env, through mj_step1/mj_step2)."""
    curve = MuscleCurve2022(model)
    mujoco.set_mjcb_passive(lambda m, d: curve.add_joint_force(d, d.qfrc_passive))
    try:
        yield
    finally:
        mujoco.set_mjcb_passive(None)


@contextlib.contextmanager
def stepped_by(old: Mujoco210 | None) -> Iterator[None]:
    """Make our envs' ``mj_step`` go through MuJoCo 2.1.0 (``old``), or leave it (``None``)."""
    if old is None:
        yield
        return
    shim = types.SimpleNamespace(**{k: getattr(mujoco, k) for k in dir(mujoco) if not k.startswith("__")})

    def mj_step(model, data, nstep=1):
        old.step_from(data, nstep)
        data.time += nstep * model.opt.timestep

    shim.mj_step = mj_step
    hand_env.mujoco = shim
    try:
        yield
    finally:
        hand_env.mujoco = mujoco


# --- reports ------------------------------------------------------------------------------------

SKIP_FIELDS = re.compile(r"^(name_|names|mesh_|tex_|mat_|cam_|light_|.*_sameframe|.*_group|.*_dataid|"
                         r"geom_rgba|body_geomadr|exclude_signature|wrap_objid|actuator_(dyn|gain|bias)type)")


def compare_models(old: Mujoco210, ours: mujoco.MjModel) -> list[dict]:
    """Fields that differ beyond 1e-5 (relative), the 2022 model's extra full-body geom removed.
    Enum fields whose numbering changed between versions, indices and visuals are skipped."""
    extra_geoms = set(np.flatnonzero(old.model["geom_bodyid"] == 1).tolist())
    keep = [g for g in range(old.sizes["ngeom"]) if g not in extra_geoms]
    rows = []
    for name, theirs in old.model.items():
        if SKIP_FIELDS.match(name) or not hasattr(ours, name):
            continue
        a = np.asarray(theirs)
        if name.startswith("geom_") and a.shape[0] == old.sizes["ngeom"]:
            a = a[keep]
        b = np.asarray(getattr(ours, name))
        if a.size != b.size or a.size == 0:
            continue
        b = b.reshape(a.shape)
        diff = np.abs(a.astype(float) - b.astype(float))
        bad = diff > 1e-5 * np.maximum(1.0, np.abs(a.astype(float)))
        if bad.any():
            worst = np.unravel_index(np.argmax(np.where(bad, diff, 0)), diff.shape)
            row = int(worst[0])
            rows.append({"field": name, "entries": int(bad.sum()), "max_abs_diff": float(diff[worst]),
                         "row": row, "old": float(a[worst]), "ours": float(b[worst])})
    return rows


def muscle_curve(old: Mujoco210, ours: mujoco.MjModel, muscle: str) -> list[dict]:
    i = ours.actuator(muscle).id
    prm, lr, acc0 = ours.actuator_gainprm[i], ours.actuator_lengthrange[i], ours.actuator_acc0[i]
    optimum = (lr[1] - lr[0]) / (prm[1] - prm[0])
    rows = []
    for normalized in (0.3, 0.4, 0.45, 0.5, 0.55, 0.75, 1.0, 1.5, 1.6, 1.7):
        length = lr[0] + (normalized - prm[0]) * optimum
        rows.append({"normalized_length": normalized,
                     "gain_mujoco210": old.muscle_gain(length, 0.0, lr, acc0, prm),
                     "gain_ours": mujoco.mju_muscleGain(length, 0.0, lr, acc0, prm[:9])})
    return rows


def hold_states(old: Mujoco210, policy, episodes: int, steps: int) -> list[tuple[dict, np.ndarray]]:
    """(state, ctrl) pairs along ``policy``'s hold-stage episodes in the 2022 physics."""
    env = BaodingEnv(**HOLD_STAGE)
    states = []
    with stepped_by(old):
        for seed in range(episodes):
            obs, _ = env.reset(seed=seed)
            lstm, first = None, True
            for _ in range(steps):
                action, lstm = policy.act(obs, lstm, first)
                first = False
                states.append(({f: getattr(env.data, f).copy() for f in STATE_FIELDS},
                               1.0 / (1.0 + np.exp(-5.0 * (np.clip(action, -1, 1) - 0.5)))))
                obs, _, terminated, truncated, _ = env.step(action)
                if terminated or truncated:
                    break
    return states


def one_step_errors(old: Mujoco210, ours: mujoco.MjModel, states) -> dict:
    data = mujoco.MjData(ours)
    force_gap = np.zeros(ours.nu)
    for state, ctrl in states:
        for f in STATE_FIELDS:
            old.data[f][:] = state[f]
            getattr(data, f)[:] = state[f]
        old.data["ctrl"][:] = ctrl
        data.ctrl[:] = ctrl
        old.lib.mj_forward(old.m, old.d)
        mujoco.mj_forward(ours, data)
        force_gap = np.maximum(force_gap, np.abs(old.data["actuator_force"] - data.actuator_force))
    report = {"states": len(states), "actuator_force_max_abs_diff_N": {
        ours.actuator(int(i)).name: float(force_gap[i]) for i in np.argsort(-force_gap)[:4]}}
    for label, emulate in (("ours", False), ("ours_with_2.1.0_length_curve", True)):
        hand, balls = [], []
        with fl_210_in_ours(ours) if emulate else contextlib.nullcontext():
            for state, ctrl in states:
                for f in STATE_FIELDS:
                    getattr(data, f)[:] = state[f]
                    old.data[f][:] = state[f]
                data.ctrl[:] = ctrl
                old.data["ctrl"][:] = ctrl
                for _ in range(BaodingEnv.FRAME_SKIP):
                    old.lib.mj_step(old.m, old.d)
                mujoco.mj_step(ours, data, BaodingEnv.FRAME_SKIP)
                error = np.abs(old.data["qpos"] - data.qpos)
                hand.append(error[:23].max())
                balls.append(error[23:].max())
        report[label] = {"hand_qpos_err_median": float(np.median(hand)), "hand_qpos_err_p90": float(np.percentile(hand, 90)),
                         "ball_qpos_err_p90_m": float(np.percentile(balls, 90))}
    return report


def policy_score(policy, env_knobs: dict, episodes: int, old: Mujoco210 | None, emulate: bool,
                 start_noise: float = 0.0) -> dict:
    env = BaodingEnv(**env_knobs)
    by_sector: dict[int, list[tuple[float, bool]]] = {}
    solved_steps: list[int] = []
    with stepped_by(old), (fl_210_in_ours(env.model) if emulate else contextlib.nullcontext()):
        for seed in range(episodes):
            obs, _ = env.reset(seed=seed)
            if start_noise:
                obs = env.move_hand_joints(start_offsets(seed, start_noise, N_HAND_JOINTS))
            start = env.task.start_angle
            lstm, first, solved, dropped = None, True, 0, False
            for _ in range(env.horizon):
                action, lstm = policy.act(obs, lstm, first)
                first = False
                obs, _, terminated, truncated, info = env.step(action)
                solved += int(info["solved"])
                if terminated or truncated:
                    dropped = bool(info["dropped"])
                    break
            sector = int((start % (2 * math.pi)) / (2 * math.pi) * 8) if start is not None else 0
            by_sector.setdefault(sector, []).append((solved / env.horizon, dropped))
            solved_steps.append(solved)
    every = [x for v in by_sector.values() for x in v]
    return {"score": float(np.mean([s for s, _ in every])), "dropped": float(np.mean([d for _, d in every])),
            "median_solved_steps": float(np.median(solved_steps)),
            "by_sector_45deg": {f"{45 * k}-{45 * k + 45}": round(float(np.mean([s for s, _ in v])), 3)
                                for k, v in sorted(by_sector.items())}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default=str(REPO / "models/reference/stiff_fingers_2022_p1"),
                        help="checkpoint, run or model folder (default: the 2022 winner's phase-1 policy)")
    parser.add_argument("--episodes", type=int, default=80)
    parser.add_argument("--cache", type=Path, default=Path.home() / ".cache/myo-sds/physics_2022")
    parser.add_argument("--muscle", default="RI5", help="muscle whose length curve is tabulated")
    parser.add_argument("--start-noise", type=float, default=0.0,
                        help="rad: each hand joint moved by U(-noise, noise) at reset (as evaluate.py's)")
    parser.add_argument("--stages", default="hold,p1_2022",
                        help=f"comma-separated, of {', '.join(STAGES)}")
    parser.add_argument("--scores-only", action="store_true", help="skip reports 1-3 (model, curve, one step)")
    parser.add_argument("--json", type=Path, help="also write the report here")
    args = parser.parse_args()
    stages = args.stages.split(",")
    if unknown := [s for s in stages if s not in STAGES]:
        parser.error(f"--stages: unknown {', '.join(unknown)}; allowed: {', '.join(STAGES)}")
    if args.start_noise < 0 or not math.isfinite(args.start_noise):
        parser.error(f"--start-noise {args.start_noise}: expected radians >= 0, e.g. 0.02")

    old = Mujoco210(fetch_2022_files(args.cache))
    ours, _ = load_hand_model("myohand_baoding.xml")
    policy = load_policy(resolve_checkpoint(args.policy), "baoding")
    report = {"policy": args.policy, "episodes": args.episodes, "start_noise": args.start_noise}
    if not args.scores_only:
        model_reports(report, old, ours, policy, args.muscle)

    report["scores"] = {}
    for stage in stages:
        # Without noise a fixed start replays one episode: a few suffice there.
        fixed = stage != "hold" and not args.start_noise
        episodes = max(4, args.episodes // 20) if fixed else args.episodes
        for label, physics, emulate in (("mujoco210_2022_model", old, False), ("ours", None, False),
                                        ("ours_with_2.1.0_length_curve", None, True)):
            result = policy_score(policy, STAGES[stage], episodes, physics, emulate, args.start_noise)
            report["scores"][f"{stage}/{label}"] = result
            print(f"4. {stage:11s} {label:30s} score {result['score']:.3f}, dropped {result['dropped']:.2f}, "
                  f"median solved steps {result['median_solved_steps']:.0f} ({episodes} episodes, start noise "
                  f"{args.start_noise:g}) by sector {result['by_sector_45deg']}")
    if args.json:
        args.json.write_text(json.dumps(report, indent=1))


def model_reports(report: dict, old: Mujoco210, ours: mujoco.MjModel, policy, muscle: str) -> None:
    """Reports 1-3: model fields, one muscle's length curve, one env step from the same states."""
    report["model_differences"] = compare_models(old, ours)
    print("1. model fields differing beyond 1e-5 (2022 binary vs ours):")
    for row in report["model_differences"]:
        print(f"   {row['field']:24s} {row['entries']:4d} entries, max |diff| {row['max_abs_diff']:.3g} "
              f"(row {row['row']}: 2022 {row['old']:.4g}, ours {row['ours']:.4g})")

    report["muscle_curve"] = muscle_curve(old, ours, muscle)
    print(f"2. {muscle}'s active gain (N per unit activation, negative pulls) at zero velocity:")
    for row in report["muscle_curve"]:
        print(f"   L/L0 {row['normalized_length']:4.2f}: MuJoCo 2.1.0 {row['gain_mujoco210']:8.2f}   ours {row['gain_ours']:8.2f}")

    states = hold_states(old, policy, episodes=6, steps=60)
    report["one_step"] = one_step_errors(old, ours, states)
    print(f"3. one env step from the same {len(states)} states:", json.dumps(report["one_step"], indent=1))


if __name__ == "__main__":
    main()
