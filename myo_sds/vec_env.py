"""A vector env that steps its envs on a thread pool.

MuJoCo releases the GIL inside ``mj_step``, so threads in one process use every core for
physics without pickling observations between processes. Semantics are DummyVecEnv's
(auto-reset, ``terminal_observation``, seeds and options at reset); each env is stepped by one
fixed thread, so results do not depend on scheduling.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv

from myo_sds.threads import available_cpus


class ThreadVecEnv(DummyVecEnv):
    """DummyVecEnv whose ``step`` runs the envs in ``n_threads`` contiguous groups in parallel.

    Args:
        env_fns: one factory per env.
        n_threads: worker threads; 0 means one per CPU this process may use.
    """

    def __init__(self, env_fns: Sequence[Callable[[], gym.Env]], n_threads: int = 0) -> None:
        super().__init__(list(env_fns))
        n_threads = n_threads or available_cpus()
        n_threads = max(1, min(n_threads, self.num_envs))
        bounds = np.linspace(0, self.num_envs, n_threads + 1).astype(int)
        self._groups = [range(bounds[i], bounds[i + 1]) for i in range(n_threads)]
        self._pool = ThreadPoolExecutor(n_threads, thread_name_prefix="env") if n_threads > 1 else None

    def _step_group(self, indices: range) -> None:
        for index in indices:
            obs, reward, terminated, truncated, info = self.envs[index].step(self.actions[index])
            self.buf_rews[index] = reward
            self.buf_dones[index] = terminated or truncated
            info["TimeLimit.truncated"] = truncated and not terminated
            if self.buf_dones[index]:
                info["terminal_observation"] = obs
                obs, self.reset_infos[index] = self.envs[index].reset()
            self.buf_infos[index] = info
            self._save_obs(index, obs)

    def step_wait(self):
        if self._pool is None:
            self._step_group(range(self.num_envs))
        else:
            for future in [self._pool.submit(self._step_group, group) for group in self._groups]:
                future.result()
        # The envs build a fresh info dict every step, so no deep copy is needed.
        return self._obs_from_buf(), np.copy(self.buf_rews), np.copy(self.buf_dones), list(self.buf_infos)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
        super().close()


class StatisticsOnlyVecEnv(VecEnv):
    """The learner's stand-in for the remote envs: their spaces and count, for the model and the
    VecNormalize that holds the merged statistics. It is never stepped."""

    def __init__(self, num_envs: int, observation_space: gym.Space, action_space: gym.Space) -> None:
        super().__init__(num_envs, observation_space, action_space)

    def reset(self):
        return np.zeros((self.num_envs, *self.observation_space.shape), dtype=np.float32)

    def step_async(self, actions) -> None:
        raise RuntimeError("the learner's envs run on Ray workers; it does not step them")

    def step_wait(self):
        raise RuntimeError("the learner's envs run on Ray workers; it does not step them")

    def close(self) -> None:
        pass

    def get_attr(self, attr_name, indices=None):
        if attr_name == "render_mode":  # asked by VecEnv's constructor
            return [None] * self.num_envs
        raise AttributeError(attr_name)

    def set_attr(self, attr_name, value, indices=None) -> None:
        raise AttributeError(attr_name)

    def env_method(self, method_name, *method_args, indices=None, **method_kwargs):
        raise AttributeError(method_name)

    def env_is_wrapped(self, wrapper_class, indices=None):
        return [False] * self.num_envs
