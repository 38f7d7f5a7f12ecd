"""MuJoCo 2.1.0's muscle length curve as the Baoding knob ``muscle_curve: '2.1.0'``."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from myo_sds.envs.baoding import BaodingEnv
from myo_sds.envs.muscle_2022 import MuscleCurve2022

# RI5's active gain (N per unit activation, zero velocity) at normalized lengths, read from MuJoCo
# 2.1.0's own mju_muscleGain (free-mujoco-py 2.1.6's library) and from ours: the difference is
# what the knob adds (experiments/RESULTS.md, "The 2022 physics").
RI5_GAIN_210 = {0.30: 174.9, 0.40: 112.6, 0.45: 85.1, 0.55: -1.2, 0.75: -30.0, 1.00: -59.9}
RI5_GAIN_OURS = {0.30: 0.0, 0.40: 0.0, 0.45: 0.0, 0.55: -1.2, 0.75: -30.0, 1.00: -59.9}


def _set_normalized_length(curve: MuscleCurve2022, data: mujoco.MjData, k: int, length: float) -> None:
    data.actuator_length[curve.muscles[k]] = curve.length0[k] + (length - curve.range_low[k]) * curve.optimum[k]


def test_extra_force_is_210_gain_minus_ours_for_ri5():
    env = BaodingEnv("p1_2022")
    curve = MuscleCurve2022(env.model)
    names = [env.model.actuator(int(i)).name for i in curve.muscles]
    k = names.index("RI5")
    data = env.data
    data.actuator_velocity[:] = 0.0
    data.act[:] = 0.0
    data.act[curve.act_adr[k]] = 1.0
    for length, gain in RI5_GAIN_210.items():
        _set_normalized_length(curve, data, k, length)
        force = curve.actuator_force(data)
        assert force[k] == pytest.approx(gain - RI5_GAIN_OURS[length], abs=0.1), length
        assert np.count_nonzero(force) == (1 if length < 0.5 else 0)
    data.act[curve.act_adr[k]] = 0.25  # the force scales with activation
    _set_normalized_length(curve, data, k, 0.30)
    assert curve.actuator_force(data)[k] == pytest.approx(0.25 * 174.9, abs=0.05)


def _upper_limit_state(env: BaodingEnv) -> None:
    """Every hand hinge at its upper limit: RI5, FDS4 and FDP5 are shorter than their lmin."""
    model, data = env.model, env.data
    for j in range(model.njnt):
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE and model.jnt_limited[j]:
            data.qpos[model.jnt_qposadr[j]] = model.jnt_range[j][1]
    data.qvel[:] = 0.0
    data.act[:] = 0.6


def test_knob_applies_the_force_through_the_moment_arms_and_changes_the_motion():
    envs = {curve: BaodingEnv("p1_2022", muscle_curve=curve) for curve in ("mujoco", "2.1.0")}
    action = np.zeros(envs["mujoco"].action_space.shape, np.float32)
    obs = {}
    for curve, env in envs.items():
        env.reset(seed=3)
        obs[curve] = env.step(action)[0]  # from the resting hand no muscle is short: the same step
    np.testing.assert_array_equal(obs["mujoco"], obs["2.1.0"])
    for env in envs.values():
        _upper_limit_state(env)
    model = envs["2.1.0"].model
    data = mujoco.MjData(model)  # a copy: the envs step from the same state below
    mujoco.mj_copyData(data, model, envs["2.1.0"].data)
    curve = MuscleCurve2022(model)
    mujoco.mj_forward(model, data)
    force = np.zeros(model.nu)
    force[curve.muscles] = curve.actuator_force(data)
    assert np.count_nonzero(force) == 3
    moment = np.zeros((model.nu, model.nv))
    mujoco.mju_sparse2dense(moment, data.actuator_moment, data.moment_rownnz, data.moment_rowadr, data.moment_colind)
    expected = moment.T @ force
    curve.step(model, data, 1)
    np.testing.assert_allclose(data.qfrc_applied, expected, rtol=1e-9, atol=1e-9)
    for env in envs.values():
        obs[env.knobs.muscle_curve] = env.step(action)[0]
    assert not envs["mujoco"].data.qfrc_applied.any()
    assert np.abs(obs["mujoco"] - obs["2.1.0"]).max() > 1e-3


def test_muscle_curve_rejects_unknown_values():
    with pytest.raises(ValueError, match="muscle_curve: '2.2' is not one of mujoco, 2.1.0"):
        BaodingEnv("p1_2022", muscle_curve="2.2")
