"""MyoChallenge 2022 Baoding balls on the ``mujoco`` bindings, with every SDS curriculum knob.

Physics, observation, reward, termination and scoring reproduce myosuite's
``myoChallengeBaodingP1-v1`` / ``P2-v1`` (tests/test_baoding_parity.py checks it step by
step); only the model files are shared with myosuite. Knobs widen or narrow the task
distribution for the static-to-dynamic stabilization curriculum.

Random draws at reset, in this order (the presets draw exactly what the official env draws,
so the same seed gives the same task instance there and here):
  1. direction, if ``direction`` is ``"random"`` (one of hold, cw, ccw) or a list (one of its members);
  2. start angle, if ``start_angle == "uniform"`` (U(0, 2 pi)) or a list (one of its angles);
  3. start offset, if ``start_offset`` is set;
  4. x radius, y radius (always, even when fixed), period (unless static);
  5. ball mass x2, friction x2, size x2 (each only when its knob is set);
  6. palm noise (3 wrist joints), finger noise (20 joints), each only when > 0;
  7. whether to start on the targets, only when 0 < ``rsi_probability`` < 1;
  8. with ``recorded_start`` set: whether to start from a recorded state, which one, and the
     start offset of the targets placed on its balls (the last two only when it does).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import mujoco
import numpy as np

from myo_sds.envs.baoding_task import (  # noqa: F401  (re-exported: the env's public names)
    _DIRECTION_SIGN,
    DIRECTIONS,
    FRAME_SKIP,
    HORIZON,
    MODEL_FILE,
    N_HAND_JOINTS,
    N_WRIST_JOINTS,
    NOMINAL_FRICTION,
    OFFICIAL_START_ANGLE,
    ON_BALLS_START_ANGLE,
    ORBIT_CENTER,
    PRIVILEGED,
    REWARD_TERMS,
    BaodingKnobs,
    BaodingTask,
    draw_direction,
)
from myo_sds.envs.hand_env import FINGERTIP_SITES, MuscleHandEnv, vector_norm
from myo_sds.envs.knobs import DEFAULT_PRESET, TaskKnobs


class BaodingEnv(MuscleHandEnv):
    """Rotate two balls around each other in the palm of the 39-muscle MyoHand.

    Constructor arguments as :class:`MuscleHandEnv`'s (official horizon: 200 steps).

    Observation (86, float32): hand joint angles (23), ball 1 position (3) and velocity
    times dt (3), ball 2 likewise, target 1 and 2 positions (3 each), target minus ball
    for each ball (3 each), muscle activations (39). Action: 39 values in [-1, 1], mapped
    to muscle excitation by ``1 / (1 + exp(-5 (a - 0.5)))``.
    """

    MODEL_FILE = MODEL_FILE
    FRAME_SKIP = FRAME_SKIP
    HORIZON = HORIZON
    OBS_SIZE = 86
    TASK_NAME = "baoding"
    TASK_CLASS = BaodingTask
    KNOBS_CLASS = BaodingKnobs
    REWARD_TERMS = REWARD_TERMS
    metadata = {"render_modes": ["rgb_array"], "render_fps": 40}
    PRIVILEGED = PRIVILEGED

    def __init__(self, preset: str = DEFAULT_PRESET, render_mode: str | None = None, horizon: int = HORIZON, *,
                 distribution: TaskKnobs | None = None, **knobs: Any) -> None:
        super().__init__(preset, render_mode, horizon, distribution=distribution, **knobs)
        model = self.model
        self._ball_bodies = (model.body("ball1").id, model.body("ball2").id)
        self._ball_geoms = (model.geom("ball1").id, model.geom("ball2").id)
        self._ball_sites = (model.site("ball1_site").id, model.site("ball2_site").id)
        self._target_sites = (model.site("target1_site").id, model.site("target2_site").id)
        for site in self._target_sites:
            model.site_group[site] = 2  # visible in renders (visual only, as the official env)
        self._nominal_size = float(model.geom_size[self._ball_geoms[0], 0])
        self._nominal_mass = float(model.body_mass[self._ball_bodies[0]])
        self._nominal_friction = tuple(float(v) for v in model.geom_friction[self._ball_geoms[0]])
        self._ball_qpos = [model.jnt_qposadr[model.body_jntadr[b]] for b in self._ball_bodies]
        self._ball_dof = [model.jnt_dofadr[model.body_jntadr[b]] for b in self._ball_bodies]
        self._joint_low = model.jnt_range[:N_HAND_JOINTS, 0].copy()
        self._joint_high = model.jnt_range[:N_HAND_JOINTS, 1].copy()
        self._init_qpos = model.qpos0.copy()
        self._init_qpos[:N_HAND_JOINTS] = 0.0
        self._init_qpos[0] = -1.57  # palm up, as the official env
        self._obs = np.zeros(self.OBS_SIZE)
        self._tip_sites = [model.site(name).id for name in FINGERTIP_SITES]
        self._target_angle = 0.0  # the first target's angle on its orbit at this step
        self._balls_placed = False  # whether this episode's balls were put on their targets (RSI)

    def sample_task(self, rng: np.random.Generator) -> BaodingTask:
        """Draw a task instance from the current knobs (draw order: module docstring)."""
        k = self.knobs
        direction = draw_direction(k.direction, rng)
        if k.start_angle == "uniform":
            start = float(rng.uniform(low=0, high=2 * np.pi))
        elif isinstance(k.start_angle, tuple):
            start = k.start_angle[int(rng.integers(len(k.start_angle)))]
        elif k.start_angle == "fixed":
            start = OFFICIAL_START_ANGLE
        elif k.start_angle == "on_balls":
            start = ON_BALLS_START_ANGLE
        else:
            start = float(k.start_angle)
        if k.start_offset is not None:
            start += k.start_offset.sample(rng)
        x_radius, y_radius = k.x_radius.sample(rng), k.y_radius.sample(rng)
        period = math.inf if k.period is None else k.period.sample(rng)
        mass = tuple(k.ball_mass.sample(rng) for _ in range(2)) if k.ball_mass else (
            self._nominal_mass,) * 2
        if k.ball_friction:
            low, high = k.ball_friction
            friction = tuple(tuple(float(v) for v in rng.uniform(low=low, high=high)) for _ in range(2))
        else:
            friction = (self._nominal_friction,) * 2
        size = tuple(k.ball_size.sample(rng) for _ in range(2)) if k.ball_size else (
            self._nominal_size,) * 2
        return BaodingTask(direction, period, x_radius, y_radius, start, size, mass, friction)

    def _start_episode(self, task: BaodingTask, rng: np.random.Generator,
                       state: Mapping[str, Any] | None) -> None:
        self.data.qpos[:] = self._init_qpos
        self._balls_placed = False
        self._apply_ball_physics(task)
        self._place_targets(0)
        if state is None:
            self._randomize_start(rng)

    def _task_for_recorded_state(self, task: BaodingTask, rng: np.random.Generator) -> BaodingTask:
        """The targets placed on the restored balls (the orbit angle of the balls' pair), plus
        a ``start_offset`` draw; direction, period, radii and ball physics stay the task's."""
        offset = self.knobs.start_offset.sample(rng) if self.knobs.start_offset is not None else 0.0
        task = replace(task, start_angle=float((self.balls_phase() + offset) % (2 * np.pi)))
        self.task = task
        self._place_targets(0)
        return task

    def balls_phase(self) -> float:
        """The orbit angle at which the targets would sit on the balls as they are now: the angle
        of ball 1 minus ball 2 in the frame the targets move in, each axis scaled by its radius
        (for balls on their targets at angle a and a - pi it is a). Updates kinematics."""
        model, data = self.model, self.data
        mujoco.mj_kinematics(model, data)
        frame = model.site_bodyid[self._target_sites[0]]
        between = data.site_xpos[self._ball_sites[0]] - data.site_xpos[self._ball_sites[1]]
        local = data.xmat[frame].reshape(3, 3).T @ between
        return float(math.atan2(local[1] / self.task.y_radius, local[0] / self.task.x_radius) % (2 * np.pi))

    def _before_physics(self) -> None:
        self._place_targets(self._counter)

    def _next_goal(self, offset, rng: np.random.Generator) -> None:
        """The targets jump along their orbit by U(offset) rad (default +-45 degrees), keeping
        their direction and period. The offset is measured along the direction of travel (positive:
        ahead; clockwise flips its sign, hold keeps it as written), so one range sends cw and ccw
        targets ahead of the balls, as static targets drawn ahead (AL4Muscles) need."""
        if offset is None:
            shift = float(rng.uniform(-math.pi / 4, math.pi / 4))
        else:
            shift = offset.sample(rng) * (-1.0 if self.task.direction == "cw" else 1.0)
        self.task = replace(self.task, start_angle=float((self.task.start_angle + shift) % (2 * np.pi)))
        self._place_targets(self._counter)

    def _episode_label(self) -> str:
        return self.task.direction

    def _episode_start_phase(self) -> float:
        return float(self.task.start_angle % (2 * np.pi))

    def _episode_start_kind(self) -> str:
        if self.recorded_start:
            return "recorded"
        return "on_targets" if self._balls_placed else "rest"

    def _goal_phase(self) -> float:
        return self._target_angle  # of the targets this step was solved against

    # Close over the palm, from above the fingers, so the 1.5 cm solved radius can be seen.
    CAMERA = (90.0, -65.0, 0.2)

    def _camera_target(self) -> np.ndarray:
        return self.data.site_xpos[list(self._target_sites)].mean(axis=0)

    def _decorate_scene(self, scene: mujoco.MjvScene) -> None:
        """Each target as a translucent sphere of the solved radius, green while that ball's
        centre is inside it, red otherwise; the balls are drawn translucent, so the spheres show."""
        balls = set(self._ball_geoms)
        for index in range(scene.ngeom):
            geom = scene.geoms[index]
            if geom.objtype == mujoco.mjtObj.mjOBJ_GEOM and geom.objid in balls:
                geom.rgba[3] = 0.4
        radius = self.knobs.solved_radius
        for ball, target in zip(self._ball_sites, self._target_sites):
            inside = vector_norm(self.data.site_xpos[target] - self.data.site_xpos[ball]) < radius
            self._add_sphere(scene, self.data.site_xpos[target], radius,
                             (0.1, 0.9, 0.2, 0.55) if inside else (0.95, 0.15, 0.1, 0.55))

    # -- internals ----------------------------------------------------------------------

    def _place_targets(self, counter: int) -> None:
        """Move the target sites to their point of the trajectory at control step ``counter``."""
        task = self.task
        sign = _DIRECTION_SIGN[task.direction]
        # Same float operations as the official precomputed trajectory.
        angle = 0.0 if math.isinf(task.period) else sign * 2 * np.pi * (counter * self.dt / task.period)
        site_pos = self.model.site_pos
        self._target_angle = float(angle + task.start_angle)
        for site, start in zip(self._target_sites, (task.start_angle, task.start_angle - np.pi)):
            site_pos[site, 0] = task.x_radius * np.cos(angle + start) + ORBIT_CENTER[0]
            site_pos[site, 1] = task.y_radius * np.sin(angle + start) + ORBIT_CENTER[1]

    def _apply_ball_physics(self, task: BaodingTask) -> None:
        """Write the task's ball radius, mass and friction into the model.

        Size and mass edits leave derived fields stale; we recompute them as MuJoCo's
        compiler does for a sphere (inertia 2/5 m r^2 bounded below by ``boundinertia``,
        bounding boxes) and rerun ``mj_setConst``, matching a recompiled model.
        """
        model = self.model
        changed = False
        for i, (body, geom) in enumerate(zip(self._ball_bodies, self._ball_geoms)):
            model.geom_friction[geom] = task.ball_friction[i]
            radius, mass = task.ball_size[i], task.ball_mass[i]
            if model.geom_size[geom, 0] == radius and model.body_mass[body] == mass:
                continue
            changed = True
            model.geom_size[geom] = radius
            model.body_mass[body] = mass
            model.body_inertia[body] = max(0.4 * mass * radius**2, self._spec.compiler.boundinertia)
            model.geom_rbound[geom] = radius
            model.geom_aabb[geom] = (0, 0, 0, radius, radius, radius)
            node = model.body_bvhadr[body]
            model.bvh_aabb[node] = (0, 0, 0, radius, radius, radius)
        if changed:
            self._refresh_constants()

    def _randomize_start(self, rng: np.random.Generator) -> None:
        knobs, qpos = self.knobs, self.data.qpos
        if knobs.palm_noise > 0:
            qpos[:N_WRIST_JOINTS] += rng.uniform(-knobs.palm_noise, knobs.palm_noise, N_WRIST_JOINTS)
        if knobs.finger_noise > 0:
            n = N_HAND_JOINTS - N_WRIST_JOINTS
            qpos[N_WRIST_JOINTS:N_HAND_JOINTS] += rng.uniform(-knobs.finger_noise, knobs.finger_noise, n)
        np.clip(qpos[:N_HAND_JOINTS], self._joint_low, self._joint_high, out=qpos[:N_HAND_JOINTS])
        p = knobs.rsi_probability
        if p >= 1.0 or (p > 0.0 and rng.uniform() < p):
            self._balls_onto_targets()
            self._balls_placed = True

    def _balls_onto_targets(self) -> None:
        """Reference state initialization: each ball on its target site, at rest.

        The ball's centre goes to the target's x and y; its height follows ``rsi_height``.
        """
        model, data, height = self.model, self.data, self.knobs.rsi_height
        mujoco.mj_kinematics(model, data)
        for qadr, site in zip(self._ball_qpos, self._target_sites):
            data.qpos[qadr:qadr + 2] = data.site_xpos[site, :2]
            if height != "rest":  # "rest" keeps the model's resting height, as the 2022 winner's env did
                data.qpos[qadr + 2] = data.site_xpos[site, 2]
        if height == "clear":
            self._push_balls_clear()

    def _push_balls_clear(self, tolerance: float = 1e-4, max_rounds: int = 50) -> None:
        """Move each ball out of the hand until no contact of it is deeper than ``tolerance`` (m).

        A ball started inside the palm or the thumb is thrown off the hand by the contact force
        at the first step. Each round moves the ball by its deepest contact's depth along that contact's
        normal (about the smallest move out of the hand), so it stays as close to its target as it can.
        """
        model, data = self.model, self.data
        for _ in range(max_rounds):
            mujoco.mj_fwdPosition(model, data)
            contacts = data.contact
            deepest = 0.0
            for qadr, geom in zip(self._ball_qpos, self._ball_geoms):
                touching = np.flatnonzero((contacts.geom == geom).any(axis=1))
                if touching.size == 0:
                    continue
                i = touching[np.argmin(contacts.dist[touching])]
                depth = -float(contacts.dist[i])
                if depth > tolerance:
                    normal = contacts.frame[i, :3]  # points from geom 1 to geom 2
                    data.qpos[qadr:qadr + 3] += depth * (normal if contacts.geom[i, 1] == geom else -normal)
                    deepest = max(deepest, depth)
            if deepest <= tolerance:
                return

    def _observe(self) -> np.ndarray:
        data, obs = self.data, self._obs
        (b1, b2), (t1, t2) = self._ball_sites, self._target_sites
        site_xpos, qvel = data.site_xpos, data.qvel
        d1, d2 = self._ball_dof
        obs[0:23] = data.qpos[:N_HAND_JOINTS]
        obs[23:26] = site_xpos[b1]
        obs[26:29] = qvel[d1:d1 + 3] * self.dt
        obs[29:32] = site_xpos[b2]
        obs[32:35] = qvel[d2:d2 + 3] * self.dt
        obs[35:38] = site_xpos[t1]
        obs[38:41] = site_xpos[t2]
        obs[41:44] = obs[35:38] - obs[23:26]
        obs[44:47] = obs[38:41] - obs[29:32]
        obs[47:86] = data.act
        return obs

    def _privileged_feature(self, name: str) -> np.ndarray:
        data, task = self.data, self.task
        if name == "ball_spin":
            return np.concatenate([data.qvel[dof + 3:dof + 6] for dof in self._ball_dof])
        if name == "fingertips":
            middle = data.site_xpos[list(self._ball_sites)].mean(axis=0)
            return (data.site_xpos[self._tip_sites] - middle).ravel()
        if name == "physics":
            return np.array([*task.ball_size, *task.ball_mass, *task.ball_friction[0], *task.ball_friction[1]])
        if name == "goal_phase":
            speed = 0.0 if math.isinf(task.period) else 1.0 / task.period
            return np.array([math.cos(self._target_angle), math.sin(self._target_angle),
                             _DIRECTION_SIGN[task.direction], speed])
        raise KeyError(name)

    def _reward_terms(self) -> dict[str, float]:
        obs, knobs = self._obs, self.knobs
        dist_1, dist_2 = vector_norm(obs[41:44]), vector_norm(obs[44:47])  # each ball to its target
        dropped = obs[25] < knobs.drop_height or obs[31] < knobs.drop_height
        solved = dist_1 < knobs.solved_radius and dist_2 < knobs.solved_radius and not dropped
        return {
            "pos_dist_1": -dist_1,
            "pos_dist_2": -dist_2,
            "act_reg": -vector_norm(obs[47:86]) / self.model.na,
            "sparse": -(dist_1 + dist_2),
            "solved": float(solved),
            "alive": float(not dropped),
            "done": float(dropped),
        }
