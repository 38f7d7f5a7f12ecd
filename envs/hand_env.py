"""What the MyoHand tasks share: model loading, muscle actions, stepping, episode accounting.

A task subclasses :class:`MuscleHandEnv` once and fills in its task instance, observation and
reward terms; the step/reset skeleton, input checks, instability handling and official
episode bookkeeping live here, in one place.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

import gymnasium as gym
import mujoco
import numpy as np

from myo_sds.envs.assets import load_hand_model
from myo_sds.envs.knobs import DEFAULT_PRESET, TaskKnobs, check_known
from myo_sds.envs.metrics import PHASE_SECTORS, EpisodeResult, phase_sector
from myo_sds.envs.muscle_2022 import MuscleCurve2022
from myo_sds.envs.state_bank import StateBank

_INSTABILITY_WARNINGS = np.array([mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL,
                                  mujoco.mjtWarning.mjWARN_BADQACC], dtype=int)


FINGERTIP_SITES = ("THtip", "IFtip", "MFtip", "RFtip", "LFtip")  # sites of both task models


def vector_norm(vector: np.ndarray) -> float:
    """Euclidean norm of a 1-D float array; the same arithmetic as ``np.linalg.norm``, faster."""
    return math.sqrt(vector.dot(vector))


def make_renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
    """A MuJoCo offscreen renderer, or a clear error saying which system packages provide one."""
    try:
        return mujoco.Renderer(model, height, width)
    except Exception as error:  # mujoco raises several types depending on the backend
        raise RuntimeError(
            f"offscreen rendering needs an OpenGL backend ({error}). On Debian/Ubuntu install "
            "EGL with `apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri` and set MUJOCO_GL=egl "
            "(the default here), or `apt-get install libosmesa6` and set MUJOCO_GL=osmesa.") from None


class MuscleHandEnv(gym.Env):
    """Base of the MyoHand tasks. Subclasses set the class constants and implement
    :meth:`sample_task`, :meth:`_start_episode`,
    :meth:`_observe` and :meth:`_reward_terms` (which must include ``solved`` and ``done``).

    Args:
        preset: ``"p1"`` or ``"p2"``, the official phase's task distribution.
        render_mode: ``None`` or ``"rgb_array"``.
        horizon: control steps before truncation (default: the task's official horizon).
        distribution: knobs already read (a curriculum stage's); then ``preset`` and ``knobs``
            must not be given.
        **knobs: overrides of the preset; see the task's knob dataclass.
    """

    MODEL_FILE: ClassVar[str]
    FRAME_SKIP: ClassVar[int]
    HORIZON: ClassVar[int]
    OBS_SIZE: ClassVar[int]
    TASK_NAME: ClassVar[str]
    TASK_CLASS: ClassVar[type]  # the task-instance dataclass, with ``from_mapping``
    KNOBS_CLASS: ClassVar[type[TaskKnobs]]
    REWARD_TERMS: ClassVar[tuple[str, ...]]
    # myosuite's Baoding env maps actions in float32, its die env in float64: keep each one's.
    ACTION_DTYPE: ClassVar[type | None] = None
    metadata = {"render_modes": ["rgb_array"]}

    # Features of the simulation the official observation leaves out, by name (size, meaning), that
    # a critic may see in training (``policy.critic_extra``): appended to the observation in order.
    PRIVILEGED: ClassVar[Mapping[str, tuple[int, str]]] = {}

    def __init__(self, preset: str = DEFAULT_PRESET, render_mode: str | None = None,
                 horizon: int | None = None, *, distribution: TaskKnobs | None = None,
                 privileged: tuple[str, ...] = (), **knobs: Any) -> None:
        super().__init__()
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode: {render_mode!r} is not one of None, 'rgb_array'")
        self.render_mode = render_mode
        self.horizon = int(horizon or self.HORIZON)
        self.preset = preset
        self.knobs = self._distribution(preset, distribution, knobs)
        self.model, self._spec = load_hand_model(self.MODEL_FILE)
        self.data = mujoco.MjData(self.model)
        self._scratch = mujoco.MjData(self.model)  # for mj_setConst after geometry edits
        self.dt = self.model.opt.timestep * self.FRAME_SKIP
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.model.nu,), np.float32)
        unknown = [name for name in privileged if name not in self.PRIVILEGED]
        if unknown:
            raise ValueError(f"privileged: {', '.join(map(repr, unknown))} not among the {self.TASK_NAME} task's "
                             f"{', '.join(self.PRIVILEGED) or 'none'}")
        self.privileged = tuple(privileged)
        size = self.OBS_SIZE + sum(self.PRIVILEGED[name][0] for name in self.privileged)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (size,), np.float32)
        self.task: Any = None
        self._counter = 0
        self.state_bank: StateBank | None = None  # states of earlier episodes (``recorded_start`` knob)
        self.recorded_start = False  # whether this episode began from a banked state
        self._renderer: mujoco.Renderer | None = None
        self._muscle_curve_2022: MuscleCurve2022 | None = None  # built on first use
        self._camera = mujoco.MjvCamera()

    # -- to implement ---------------------------------------------------------------------

    @classmethod
    def _distribution(cls, preset: str, distribution: TaskKnobs | None, knobs: Mapping[str, Any]) -> TaskKnobs:
        if distribution is None:
            return cls.KNOBS_CLASS.parse(preset, **knobs)
        if knobs or not isinstance(distribution, cls.KNOBS_CLASS):
            raise ValueError(f"distribution: expected {cls.KNOBS_CLASS.__name__} and no other knobs, got "
                             f"{type(distribution).__name__}" + (f" and {', '.join(knobs)}" if knobs else ""))
        return distribution

    def sample_task(self, rng: np.random.Generator) -> Any:
        raise NotImplementedError

    def task_from_mapping(self, values: Mapping[str, Any]) -> Any:
        return self.TASK_CLASS.from_mapping(values)

    def _start_episode(self, task: Any, rng: np.random.Generator, state: Mapping[str, Any] | None) -> None:
        """Apply the task to the model and set the initial state (``data`` was just reset)."""
        raise NotImplementedError

    def _before_physics(self) -> None:
        """Called each step before the substeps (e.g. to move targets)."""

    def _observe(self) -> np.ndarray:
        """Fill and return the float64 observation buffer."""
        raise NotImplementedError

    def _privileged_feature(self, name: str) -> np.ndarray:
        """One of :attr:`PRIVILEGED`, at the current state (after :meth:`_observe`)."""
        raise NotImplementedError

    def _observation(self) -> np.ndarray:
        """What the agent gets: the official observation, then the privileged features asked for."""
        obs = self._observe()
        if self.privileged:
            obs = np.concatenate([obs, *(self._privileged_feature(name) for name in self.privileged)])
        return obs.astype(np.float32)

    def _reward_terms(self) -> dict[str, float]:
        raise NotImplementedError

    def _episode_label(self) -> str | None:
        """A grouping of episodes in reports (Baoding: the direction)."""
        return None

    def _episode_start_phase(self) -> float | None:
        """Where the episode's goal starts, for reports by start phase (the task's
        ``start_phase_name``); called at reset, after the first observation."""
        return None

    def _episode_start_kind(self) -> str | None:
        """How the episode began, for reports (EpisodeResult.start); called at reset."""
        return "recorded" if self.recorded_start else None

    def _episode_horizon(self) -> int:
        """Control steps before truncation: the task's ``episode_steps`` knob if set, else the horizon."""
        return getattr(self.knobs, "episode_steps", None) or self.horizon

    def _goal_phase(self) -> float | None:
        """Where on its path the goal is at this step (rad), for reports by goal phase."""
        return None

    def _next_goal(self, offset, rng: np.random.Generator) -> None:
        """Chained goals (``goal_chain`` knob): move the goal on from the current one (``offset``:
        the knob's range, None for the task's default). Tasks that declare the knob implement it."""
        raise NotImplementedError(f"{type(self).__name__} does not support chained goals")

    def _task_for_recorded_state(self, task: Any, rng: np.random.Generator) -> Any:
        """The episode's task once a recorded state has replaced the start: its goal placed
        relative to the restored objects. Tasks that declare a ``recorded_start`` knob implement it."""
        raise NotImplementedError(f"{type(self).__name__} does not support recorded starts")

    # -- distribution -------------------------------------------------------------------

    def configure(self, preset: str | None = None, *, distribution: TaskKnobs | None = None, **knobs: Any) -> None:
        """Replace the task distribution (takes effect at the next reset): ``distribution``
        (knobs already read), or the preset (default the current one) with ``knobs`` over it.

        The result depends only on the arguments, so a curriculum can re-send a stage after a
        restart.
        """
        preset = self.preset if preset is None else preset
        self.knobs = self._distribution(preset, distribution, knobs)
        self.preset = preset

    # -- gymnasium API ------------------------------------------------------------------

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode.

        Options:
            task: a task instance or a mapping of its fields, pinning the episode's task.
            state: mapping with any of ``qpos``, ``qvel``, ``act``, set after the task is
                applied (no start noise or reference state initialization then).
        """
        super().reset(seed=seed)
        options = dict(options or {})
        check_known("reset option", options, ("task", "state"))
        mujoco.mj_resetData(self.model, self.data)
        task = options.get("task")
        if task is None:
            task = self.sample_task(self.np_random)
        elif isinstance(task, Mapping):
            task = self.task_from_mapping(task)
        self.task = task
        self._counter = 0
        state = options.get("state")
        if state is not None:
            check_known("state field", state, ("qpos", "qvel", "act"))
        self._start_episode(task, self.np_random, state)
        if state is not None:
            self._set_state(state)
        self.recorded_start = state is None and self._start_from_bank(self.np_random)
        task = self.task
        # The observation needs positions only; mj_step computes everything else itself.
        mujoco.mj_kinematics(self.model, self.data)
        obs = self._observation()
        self._episode = {"solved_steps": 0, "effort_sum": 0.0, "reward": 0.0, "length": 0, "goals": 0, "on_goal": 0,
                         "start_phase": self._episode_start_phase(), "start": self._episode_start_kind(),
                         "phase_steps": [0] * PHASE_SECTORS, "phase_solved": [0] * PHASE_SECTORS}
        return obs, {"task": task}

    def move_hand_joints(self, offsets: np.ndarray) -> np.ndarray:
        """Add ``offsets`` to the first ``len(offsets)`` joint angles right after a reset (start
        noise drawn outside the env, e.g. by an evaluation) and return the new observation.

        Not clipped to the joint ranges and followed by ``mj_forward``, exactly as the same move
        on the official env, so both replay the same perturbed episode.
        """
        if self._counter != 0:
            raise RuntimeError("move_hand_joints: only at the start of an episode, before the first step")
        self.data.qpos[:len(offsets)] += offsets
        mujoco.mj_forward(self.model, self.data)
        return self._observation()

    def _substeps(self) -> None:
        """``FRAME_SKIP`` physics steps, with MuJoCo 2.1.0's muscles where the ``muscle_curve`` knob asks."""
        if getattr(self.knobs, "muscle_curve", "mujoco") == "2.1.0":
            self._muscle_curve_2022 = self._muscle_curve_2022 or MuscleCurve2022(self.model)
            self._muscle_curve_2022.step(self.model, self.data, self.FRAME_SKIP)
        else:
            mujoco.mj_step(self.model, self.data, self.FRAME_SKIP)

    def _recorded_start_knob(self):
        return getattr(self.knobs, "recorded_start", None)

    def _start_from_bank(self, rng: np.random.Generator) -> bool:
        """With the ``recorded_start`` knob's probability (one draw at every reset while the knob
        is set), replace the start by a random banked state and let the task place its goal."""
        recorded = self._recorded_start_knob()
        if recorded is None:
            return False
        if self.state_bank is None or self.state_bank.capacity != recorded.capacity:
            self.state_bank = StateBank(recorded.capacity, self.model)
        if rng.uniform() >= recorded.probability or self.state_bank.size == 0:
            return False
        self.state_bank.restore(int(rng.integers(self.state_bank.size)), self.data)
        self.task = self._task_for_recorded_state(self.task, rng)
        return True

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply one control step (``FRAME_SKIP`` physics substeps).

        Raises:
            ValueError: if the action has the wrong shape or a NaN/inf value (the
                simulation is left untouched).
        """
        if self.task is None:
            raise RuntimeError("call reset() before step()")
        action = np.asarray(action)
        if action.shape != (self.model.nu,):
            raise ValueError(f"action: expected shape ({self.model.nu},), got {action.shape}")
        if not np.isfinite(action).all():
            raise ValueError("action: contains NaN or inf; the simulation was not stepped")
        action = np.clip(action, -1.0, 1.0)
        if self.ACTION_DTYPE is not None:
            action = action.astype(self.ACTION_DTYPE)
        model, data = self.model, self.data
        self._before_physics()
        data.ctrl[:] = 1.0 / (1.0 + np.exp(-5.0 * (action - 0.5)))  # official muscle mapping
        self._substeps()
        # Sites after mj_step lag the integrated state by one substep: refresh kinematics
        # only (all the observation needs) instead of a full mj_forward.
        mujoco.mj_kinematics(model, data)
        self._counter += 1
        unstable = bool(data.warning.number[_INSTABILITY_WARNINGS].any())
        obs = self._observation()
        terms = self._reward_terms()
        reward = 0.0
        for key, weight in self.knobs.reward_weights.items():  # in order, as the official sum
            reward += weight * terms[key]
        terminated = bool(terms["done"]) or unstable
        recorded = self._recorded_start_knob()
        if (recorded is not None and self.state_bank is not None and not terminated
                and self._counter % recorded.every == 0 and (terms["solved"] or not recorded.solved_only)):
            self.state_bank.offer(data, self.np_random)
        horizon = self._episode_horizon()
        truncated = not terminated and self._counter >= horizon
        episode = self._episode
        episode["length"] += 1
        episode["solved_steps"] += int(terms["solved"])
        episode["effort_sum"] -= terms["act_reg"]
        episode["reward"] += reward
        chain = getattr(self.knobs, "goal_chain", None)
        if chain is not None and terms["solved"] and not (terminated or truncated):
            episode["on_goal"] += 1
            if episode["on_goal"] >= chain.after_solved:
                episode["on_goal"], episode["goals"] = 0, episode["goals"] + 1
                self._next_goal(chain.offset, self.np_random)
                mujoco.mj_kinematics(model, data)  # the new goal is in this step's observation
                obs = self._observation()
        phase = self._goal_phase()
        if phase is not None:
            sector = phase_sector(phase)
            episode["phase_steps"][sector] += 1
            episode["phase_solved"][sector] += int(terms["solved"])
        info: dict[str, Any] = {**terms, "dropped": bool(terms["done"]), "unstable": unstable, "task": self.task}
        if terminated or truncated:
            info["episode_result"] = EpisodeResult(
                solved_steps=episode["solved_steps"], length=episode["length"], horizon=horizon,
                dropped=bool(terms["done"]), effort=episode["effort_sum"] / episode["length"],
                direction=self._episode_label(), task=self.TASK_NAME, start_phase=episode["start_phase"],
                reward=episode["reward"], start=episode["start"],
                goals_reached=episode["goals"] if chain is not None else None, **self._phase_counts(episode))
        return obs, reward, terminated, truncated, info

    @staticmethod
    def _phase_counts(episode: dict[str, Any]) -> dict[str, tuple[int, ...]]:
        """The episode's counts by goal phase, for ``EpisodeResult``; none for tasks without phases."""
        if not any(episode["phase_steps"]):
            return {}
        return {"steps_by_target_phase": tuple(episode["phase_steps"]),
                "solved_by_target_phase": tuple(episode["phase_solved"])}

    def render(self) -> np.ndarray | None:
        """An RGB frame (480 x 640) when ``render_mode == "rgb_array"``.

        Raises:
            RuntimeError: when no OpenGL backend is available, naming the packages to install.
        """
        if self.render_mode != "rgb_array":
            return None
        if self._renderer is None:
            self._renderer = make_renderer(self.model, 480, 640)
            # Shadows and floor reflections triple the cost of a frame in software rendering.
            for flag in (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_REFLECTION):
                self._renderer.scene.flags[flag] = 0
            self._camera.azimuth, self._camera.elevation, self._camera.distance = self.CAMERA
        mujoco.mj_forward(self.model, self.data)  # derived quantities drawn (tendons) need it
        self._camera.lookat[:] = self._camera_target()
        self._renderer.update_scene(self.data, self._camera)
        self._decorate_scene(self._renderer.scene)
        return self._renderer.render()

    CAMERA = (90.0, -50.0, 0.35)  # azimuth, elevation (degrees), distance (m) of the render camera

    def _camera_target(self) -> np.ndarray:
        return self.data.xpos[self.model.body("trapezium").id]

    def _decorate_scene(self, scene: mujoco.MjvScene) -> None:
        """Add visual-only geoms to a rendered frame (the task's goals); none by default."""

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # -- helpers ------------------------------------------------------------------------

    @staticmethod
    def _add_sphere(scene: mujoco.MjvScene, position: np.ndarray, radius: float, rgba: tuple[float, ...]) -> None:
        """A visual-only sphere in a rendered frame (nothing if the scene is full)."""
        if scene.ngeom >= scene.maxgeom:
            return
        geom = scene.geoms[scene.ngeom]
        mujoco.mjv_initGeom(geom, mujoco.mjtGeom.mjGEOM_SPHERE, np.array([radius, 0, 0]),
                            np.asarray(position, dtype=np.float64), np.eye(3).ravel(), np.asarray(rgba, np.float32))
        geom.objtype, geom.objid = int(mujoco.mjtObj.mjOBJ_UNKNOWN), -1  # initGeom leaves them unset
        scene.ngeom += 1

    def _set_state(self, state: Mapping[str, Any]) -> None:
        data = self.data
        for key in state:
            target = getattr(data, key)
            value = np.asarray(state[key], dtype=float)
            if value.shape != target.shape:
                raise ValueError(f"state.{key}: expected shape {target.shape}, got {value.shape}")
            target[:] = value

    def _refresh_constants(self) -> None:
        """Recompute ``mj_setConst`` quantities after mass or geometry edits."""
        mujoco.mj_setConst(self.model, self._scratch)
