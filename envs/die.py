"""MyoChallenge 2022 die reorientation on the ``mujoco`` bindings, with curriculum knobs.

Physics, observation, reward, termination and scoring reproduce myosuite's
``myoChallengeDieReorientP1-v0`` / ``P2-v0`` (tests/test_die_parity.py checks it step by
step); only the model files are shared with myosuite.

Random draws at reset, in this order (the official order, so the presets give the same task
instance as the official env for the same seed):
  1. goal position offset (3), 2. goal orientation (3 Euler angles),
  3. friction of each of the die's 15 geoms (15 x 3), 4. die mass, 5. die size change;
  6. hand joint noise (23), only when ``hand_noise > 0``;
  7. with ``recorded_start`` set: whether to start from a recorded state, and which one.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import mujoco
import numpy as np

from myo_sds.envs.die_task import (  # noqa: F401  (re-exported: the env's public names)
    FRAME_SKIP,
    HORIZON,
    MODEL_FILE,
    N_HAND_JOINTS,
    PRIVILEGED,
    REWARD_TERMS,
    DieKnobs,
    DieTask,
)
from myo_sds.envs.hand_env import FINGERTIP_SITES, MuscleHandEnv, vector_norm
from myo_sds.envs.knobs import DEFAULT_PRESET, TaskKnobs
from myo_sds.envs.physics import euler_to_quat, mat_to_euler, quat_to_mat, refresh_bodies


class DieEnv(MuscleHandEnv):
    """Turn a die in the palm of the 39-muscle MyoHand to a goal position and orientation.

    Constructor arguments as :class:`MuscleHandEnv`'s (official horizon: 150 steps).

    Observation (102, float32): hand joint angles but the last (22), hand joint velocities
    times dt (23), die position, goal position, position error, die Euler angles, goal Euler
    angles, orientation error (3 each), muscle activations (39).
    """

    MODEL_FILE = MODEL_FILE
    FRAME_SKIP = FRAME_SKIP
    HORIZON = HORIZON
    OBS_SIZE = 102
    TASK_NAME = "die"
    TASK_CLASS = DieTask
    KNOBS_CLASS = DieKnobs
    REWARD_TERMS = REWARD_TERMS
    ACTION_DTYPE = np.float64
    metadata = {"render_modes": ["rgb_array"], "render_fps": 100}
    PRIVILEGED = PRIVILEGED

    def __init__(self, preset: str = DEFAULT_PRESET, render_mode: str | None = None, horizon: int = HORIZON, *,
                 distribution: TaskKnobs | None = None, **knobs: Any) -> None:
        super().__init__(preset, render_mode, horizon, distribution=distribution, **knobs)
        model, data = self.model, self.data
        self._object_site, self._goal_site = model.site("object_o").id, model.site("target_o").id
        self._goal_body, self._object_body = model.body("target").id, model.body("Object").id
        self._goal_geom = model.geom("target_dice").id
        first = int(model.body_geomadr[self._object_body])
        self._object_geoms = slice(first, first + int(model.body_geomnum[self._object_body]))
        self._goal_default_size = model.geom_size[self._goal_geom].copy()
        self._object_default_size = model.geom_size[self._object_geoms].copy()
        self._object_default_pos = model.geom_pos[self._object_geoms].copy()
        self._nominal_friction = model.geom_friction[self._object_geoms].copy()
        self._init_qpos = model.qpos0.copy()
        self._init_qpos[:-6] = 0.0  # open hand; the die's joints start at 0
        self._init_qpos[0] = -1.5
        self._joint_low = model.jnt_range[:N_HAND_JOINTS, 0].copy()
        self._joint_high = model.jnt_range[:N_HAND_JOINTS, 1].copy()
        data.qpos[:] = self._init_qpos
        mujoco.mj_forward(model, data)
        # Reference frame of the official env: the goal's nominal position, and its offset
        # from the die at rest (the error is measured relative to that offset).
        self._goal_init_pos = data.site_xpos[self._goal_site].copy()
        self._goal_object_offset = data.site_xpos[self._goal_site] - data.site_xpos[self._object_site]
        self._obs = np.zeros(self.OBS_SIZE)
        self._tip_sites = [model.site(name).id for name in FINGERTIP_SITES]
        self._die_dofs = slice(model.nv - 6, model.nv - 3)  # the die's three slide joints: its linear velocity
        self._applied_physics: tuple[float, float] | None = None

    def sample_task(self, rng: np.random.Generator) -> DieTask:
        """Draw a task instance from the current knobs (draw order: module docstring)."""
        k = self.knobs
        offset = rng.uniform(high=k.goal_position.high, low=k.goal_position.low, size=3)
        euler = rng.uniform(high=[r.high for r in k.goal_rotation], low=[r.low for r in k.goal_rotation])
        change = np.asarray(k.friction_change)
        friction = rng.uniform(low=self._nominal_friction - change, high=self._nominal_friction + change)
        mass = float(rng.uniform(low=k.mass.low, high=k.mass.high))
        size_change = float(rng.uniform(low=-k.size_change, high=k.size_change))
        return DieTask(tuple(offset.tolist()), tuple(euler.tolist()),
                       tuple(tuple(row) for row in friction.tolist()), mass, size_change)

    def _start_episode(self, task: DieTask, rng: np.random.Generator,
                       state: Mapping[str, Any] | None) -> None:
        self._apply_task(task)
        self.data.qpos[:] = self._init_qpos
        if state is None and self.knobs.hand_noise > 0:
            noise = self.knobs.hand_noise
            hand = self.data.qpos[:N_HAND_JOINTS]
            hand += rng.uniform(-noise, noise, N_HAND_JOINTS)
            np.clip(hand, self._joint_low, self._joint_high, out=hand)

    def _next_goal(self, offset, rng: np.random.Generator) -> None:
        """A new goal from the current one, as PKU-MARL chained them: its orientation turned by a
        random rotation of U(offset) rad about each axis (default: the stage's goal_rotation),
        composed onto the current goal's; its position drawn anew from goal_position. The die's
        physics stay."""
        k = self.knobs
        position = rng.uniform(high=k.goal_position.high, low=k.goal_position.low, size=3)
        ranges = (offset,) * 3 if offset is not None else k.goal_rotation
        turn = rng.uniform(high=[r.high for r in ranges], low=[r.low for r in ranges])
        quat = np.empty(4)
        mujoco.mju_mulQuat(quat, self.model.body_quat[self._goal_body], euler_to_quat(turn))
        euler = mat_to_euler(quat_to_mat(quat))
        self.task = replace(self.task, goal_offset=tuple(position.tolist()), goal_euler=tuple(euler.tolist()))
        self.model.body_pos[self._goal_body] = self._goal_init_pos + position
        self.model.body_quat[self._goal_body] = quat

    def _task_for_recorded_state(self, task: DieTask, rng: np.random.Generator) -> DieTask:
        """The goal stays the one drawn for this episode: the die starts where an earlier episode
        had it, and must be turned from there (PKU-MARL's starts for this task in 2022)."""
        return task

    def _apply_task(self, task: DieTask) -> None:
        """Goal pose and die physics into the model, as the official env edits it."""
        model = self.model
        model.body_pos[self._goal_body] = self._goal_init_pos + np.asarray(task.goal_offset)
        model.body_quat[self._goal_body] = euler_to_quat(np.asarray(task.goal_euler))
        model.geom_friction[self._object_geoms] = task.friction
        model.body_mass[self._object_body] = task.mass
        delta = task.size_change
        model.geom_size[self._goal_geom] = self._goal_default_size + delta
        sizes = model.geom_size[self._object_geoms]
        sizes[:-3, 1] = self._object_default_size[:-3, 1] + delta  # edge capsules: half-length
        sizes[-3:] = self._object_default_size[-3:] + delta  # the three boxes
        positions = model.geom_pos[self._object_geoms]
        positions[:] = positions / abs(positions + 1e-16) * (abs(self._object_default_pos) + delta)
        # Mass and size determine the derived fields; P1 never changes them after the first reset.
        if self._applied_physics != (task.mass, delta):
            refresh_bodies(model, self._spec, (self._object_body, self._goal_body), self._scratch)
            self._applied_physics = (task.mass, delta)

    def _episode_start_phase(self) -> float:
        # A recorded start turns the die away from where the task put it: read the error itself.
        return vector_norm(self._obs[60:63])

    def _camera_target(self) -> np.ndarray:
        return self.data.site_xpos[self._object_site]

    def _observe(self) -> np.ndarray:
        data, obs = self.data, self._obs
        die, goal = self._object_site, self._goal_site
        obs[0:22] = data.qpos[:22]
        obs[22:45] = data.qvel[:23] * self.dt
        obs[45:48], obs[48:51] = data.site_xpos[die], data.site_xpos[goal]
        obs[51:54] = obs[48:51] - obs[45:48] - self._goal_object_offset
        obs[54:57], obs[57:60] = (mat_to_euler(data.site_xmat[site].reshape(3, 3)) for site in (die, goal))
        obs[60:63] = obs[57:60] - obs[54:57]
        obs[63:102] = data.act
        return obs

    def _privileged_feature(self, name: str) -> np.ndarray:
        data, task = self.data, self.task
        if name == "die_velocity":
            return data.qvel[-6:].copy()
        if name == "fingertips":
            return (data.site_xpos[self._tip_sites] - data.site_xpos[self._object_site]).ravel()
        if name == "physics":
            return np.array([task.mass, task.size_change, *np.mean(task.friction, axis=0)])
        raise KeyError(name)

    def _reward_terms(self) -> dict[str, float]:
        obs, k = self._obs, self.knobs
        pos_dist = vector_norm(obs[51:54])
        rot_dist = vector_norm(obs[60:63])
        dropped = pos_dist > k.drop_threshold
        solved = pos_dist < k.position_threshold and rot_dist < k.rotation_threshold and not dropped
        data = self.data
        tips = data.site_xpos[self._tip_sites] - data.site_xpos[self._object_site]
        return {
            "pos_dist": -pos_dist,
            "rot_dist": -rot_dist,
            "rot_kernel": k.rotation_kernel_width / (rot_dist**2 + k.rotation_kernel_width),
            "pos_kernel": 1.0 / (1.0 + pos_dist**2),
            "rot_shaped": -0.5 * rot_dist + 0.5 / (1.0 + rot_dist**2),
            "tip_dist": -float(np.sqrt((tips**2).sum(axis=1)).sum()),
            "die_speed": -vector_norm(data.qvel[self._die_dofs]),
            "bonus": float(pos_dist < 2 * k.position_threshold) + float(pos_dist < k.position_threshold),
            "act_reg": -vector_norm(obs[63:102]) / self.model.na,
            "penalty": -float(dropped),
            "sparse": -rot_dist - 10.0 * pos_dist,
            "solved": float(solved),
            "done": float(dropped),
            "alive": float(not dropped),
        }
