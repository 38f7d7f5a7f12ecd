"""Simulator states an env keeps from its own earlier episodes (the ``recorded_start`` knob)."""

from __future__ import annotations

import mujoco
import numpy as np


class StateBank:
    """A bounded reservoir of simulator states (``qpos``, ``qvel``, ``act``): every state offered
    is equally likely to be in it, whatever the number offered (Vitter's algorithm R)."""

    def __init__(self, capacity: int, model: mujoco.MjModel) -> None:
        self.capacity = capacity
        self.qpos = np.zeros((capacity, model.nq))
        self.qvel = np.zeros((capacity, model.nv))
        self.act = np.zeros((capacity, model.na))
        self.size = 0
        self.offered = 0

    def offer(self, data: mujoco.MjData, rng: np.random.Generator) -> None:
        """Keep ``data``'s state: in a free slot, else in place of a random kept one with
        probability capacity / offered (one draw from ``rng`` once the bank is full)."""
        self.offered += 1
        if self.size < self.capacity:
            slot = self.size
            self.size += 1
        else:
            slot = int(rng.integers(self.offered))
            if slot >= self.capacity:
                return
        self.qpos[slot], self.qvel[slot], self.act[slot] = data.qpos, data.qvel, data.act

    def restore(self, slot: int, data: mujoco.MjData) -> None:
        data.qpos[:], data.qvel[:], data.act[:] = self.qpos[slot], self.qvel[slot], self.act[slot]
