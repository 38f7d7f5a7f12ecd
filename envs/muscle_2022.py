"""MuJoCo 2.1.0's muscle length curve, added to ours: the 2022 challenge's muscles.

MyoChallenge 2022 ran on MuJoCo 2.1.0, whose muscle length curve does not return 0 below
``lmin``: it falls through to its ``L <= 1`` branch, ``1 - x^2/2`` with
``x = (1 - L) / (1 - (lmin + 1) / 2)``, which is negative there, so an over-shortened muscle
pushes (up to ~75 N on the hand's ``RI2`` and ``RI5``; experiments/RESULTS.md, "The 2022
physics"). Above ``lmin`` both versions agree, so the difference is an extra actuator force on
the short muscles only, which :class:`MuscleCurve2022` adds as an applied joint force.
"""

from __future__ import annotations

import mujoco
import numpy as np

_TINY = 1e-15


def fl_210_excess(normalized_length: np.ndarray, lmin: np.ndarray) -> np.ndarray:
    """2.1.0's length curve minus ours: ``1 - x^2/2`` at or below ``lmin`` (negative below ~0.65
    of the optimal length), 0 above it, where the two agree."""
    midpoint = 0.5 * (lmin + 1.0)
    x = (1.0 - normalized_length) / np.maximum(_TINY, 1.0 - midpoint)
    return np.where(normalized_length <= lmin, 1.0 - 0.5 * x * x, 0.0)


def force_velocity(v: np.ndarray, fvmax: np.ndarray) -> np.ndarray:
    """MuJoCo's muscle force-velocity curve (the same in both versions), at normalized velocity ``v``."""
    y = fvmax - 1.0
    return np.where(v <= -1, 0.0, np.where(v <= 0, (v + 1) ** 2,
                    np.where(v <= y, fvmax - (y - v) ** 2 / np.maximum(_TINY, y), fvmax)))


class MuscleCurve2022:
    """The extra joint force 2.1.0's length curve gives ``model``'s muscles at a state."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.muscles = np.flatnonzero(model.actuator_gaintype == mujoco.mjtGain.mjGAIN_MUSCLE)
        prm = model.actuator_gainprm[self.muscles]
        self.range_low, self.lmin, self.vmax, self.fvmax = prm[:, 0], prm[:, 4], prm[:, 6], prm[:, 8]
        lengthrange = model.actuator_lengthrange[self.muscles]
        self.length0 = lengthrange[:, 0]
        self.optimum = np.maximum(_TINY, (lengthrange[:, 1] - lengthrange[:, 0])
                                  / np.maximum(_TINY, prm[:, 1] - prm[:, 0]))
        peak = prm[:, 2].copy()
        scaled = peak < 0  # force < 0: the peak force is scale / acc0, as MuJoCo computes it
        peak[scaled] = prm[scaled, 3] / np.maximum(_TINY, model.actuator_acc0[self.muscles][scaled])
        self.peak = peak
        self.act_adr = model.actuator_actadr[self.muscles]

    def actuator_force(self, data: mujoco.MjData) -> np.ndarray:
        """Per muscle (in ``self.muscles`` order), N: what 2.1.0 adds to ours at ``data``'s
        actuator lengths, velocities and activations (0 for every muscle above ``lmin``)."""
        length = self.range_low + (data.actuator_length[self.muscles] - self.length0) / self.optimum
        excess = fl_210_excess(length, self.lmin)
        if not excess.any():
            return excess
        velocity = data.actuator_velocity[self.muscles] / (self.optimum * self.vmax)
        return -self.peak * excess * force_velocity(velocity, self.fvmax) * data.act[self.act_adr]

    def add_joint_force(self, data: mujoco.MjData, qfrc: np.ndarray) -> None:
        """Add the extra actuator forces, mapped through the muscles' moment arms, to ``qfrc``."""
        force = self.actuator_force(data)
        for k in np.flatnonzero(force):
            row = self.muscles[k]
            adr, nnz = data.moment_rowadr[row], data.moment_rownnz[row]
            qfrc[data.moment_colind[adr:adr + nnz]] += data.actuator_moment[adr:adr + nnz] * force[k]

    def step(self, model: mujoco.MjModel, data: mujoco.MjData, nstep: int) -> None:
        """``nstep`` physics steps with the extra force: mj_step1 computes the muscles' lengths and
        moment arms, the force goes in as an applied joint force, mj_step2 integrates (what a
        passive-force callback would do, without MuJoCo's one process-wide callback)."""
        for _ in range(nstep):
            mujoco.mj_step1(model, data)
            data.qfrc_applied[:] = 0.0
            self.add_joint_force(data, data.qfrc_applied)
            mujoco.mj_step2(model, data)
