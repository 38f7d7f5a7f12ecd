"""A rollout worker: K envs and a copy of the policy, filling a rollout buffer of its own.

It runs sb3-contrib's own ``collect_rollouts`` on its envs, so a worker holding all the run's
envs produces exactly what the local backend does (a test checks it bit for bit). The learner
sends weights, normalization statistics, PPO settings and the stage; the worker returns its
buffer's arrays (its columns of the learner's buffer), the episodes that ended, and what its
normalization statistics saw. Plain Python: :mod:`myo_sds.training.ray_rollouts` runs it as a
Ray actor, tests run it directly.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Logger

from myo_sds.curricula.run_config import RunConfig
from myo_sds.curricula.schedule import PpoSettings
from myo_sds.envs.knobs import TaskKnobs
from myo_sds.envs.metrics import EpisodeResult
from myo_sds.sb3_internals import drop_queued_seeds, prepare_rollout
from myo_sds.training.callbacks import EpisodeTally
from myo_sds.training.factory import apply_ppo_settings, build_model, env_factory, normalized

BUFFER_FIELDS = ("observations", "actions", "rewards", "returns", "episode_starts", "values", "log_probs",
                 "advantages", "hidden_states_pi", "cell_states_pi", "hidden_states_vf", "cell_states_vf")


@dataclass
class Moments:
    """Count, mean and variance of a set of samples (SB3's RunningMeanStd without the object)."""

    count: float
    mean: np.ndarray
    var: np.ndarray

    @classmethod
    def of(cls, rms) -> Moments:
        return cls(float(rms.count), np.array(rms.mean, dtype=np.float64), np.array(rms.var, dtype=np.float64))

    def added_since(self, start: Moments) -> Moments:
        """The moments of the samples added to ``start`` to reach these (the parallel
        combination run backwards)."""
        count = self.count - start.count
        if count <= 0:
            return Moments(0.0, np.zeros_like(self.mean), np.zeros_like(self.var))
        mean = (self.count * self.mean - start.count * start.mean) / count
        m2 = self.var * self.count - start.var * start.count - (mean - start.mean) ** 2 * start.count * count / self.count
        return Moments(count, mean, np.maximum(m2 / count, 0.0))


@dataclass
class RolloutResult:
    """What a worker sends back after one rollout."""

    buffer: dict[str, np.ndarray]  # its columns of the rollout buffer, by field (BUFFER_FIELDS)
    obs_rms: Any  # its normalization statistics at the rollout's end (the learner's plus what it saw)
    ret_rms: Any
    obs_added: Moments  # what its envs added to the statistics during the rollout
    ret_added: Moments
    # Finished episodes: (step index in the rollout, seconds since it began, stage it began in, result).
    episodes: list[tuple[int, float, int, EpisodeResult]] = field(default_factory=list)
    term_sums: dict[str, float] = field(default_factory=dict)  # reward terms summed over steps and envs
    term_count: int = 0  # env steps summed over
    seconds: float = 0.0  # the rollout's wall time on the worker


class _WorkerCallback(BaseCallback):
    """Records each finished episode (its step index in the rollout, seconds since the rollout
    began, the stage it began in) and sums the reward terms."""

    def __init__(self, n_envs: int, terms: tuple[str, ...]) -> None:
        super().__init__(verbose=0)
        self.tally = EpisodeTally(n_envs, terms)
        self.stage_index = 0
        self.reset()

    def reset(self) -> None:
        self.episodes: list[tuple[int, float, int, EpisodeResult]] = []
        self.tally.pop_sums()
        self.step_index = 0
        self.started_at = time.perf_counter()

    def _on_step(self) -> bool:
        infos, dones = self.locals["infos"], self.locals["dones"]
        elapsed = time.perf_counter() - self.started_at
        for began, result in self.tally.observe(infos, dones, self.stage_index):
            self.episodes.append((self.step_index, elapsed, began, result))
        self.step_index += 1
        return True


class RolloutWorker:
    """Worker ``index`` of ``workers``: envs of global ranks ``index * K .. index * K + K - 1``.

    Args:
        config: the run config (its ``rollout.envs_per_worker`` is K).
        index: this worker's place among the workers.
        distribution: the current stage's knobs.
        settings: the PPO settings in force (rollout length, for the buffer).
        torch_rng: the torch generator state to sample actions from (worker 0 continues the
            learner's stream, so that one worker matches the local backend bit for bit).
    """

    def __init__(self, config: RunConfig, index: int, distribution: TaskKnobs, settings: PpoSettings,
                 torch_rng: Any = None) -> None:
        import torch

        from myo_sds.envs.task_specs import TASK_SPECS
        from myo_sds.threads import available_cpus
        from myo_sds.vec_env import ThreadVecEnv

        torch.set_num_threads(1)  # inference on a few dozen observations; the CPUs step envs
        self.config, self.index = config, index
        k = config.rollout.envs_per_worker or config.n_envs
        first = index * k
        factories = [env_factory(config.curriculum.task, distribution, config.seed + first + rank,
                                 config.policy.critic_extra) for rank in range(k)]
        self.venv = normalized(config, ThreadVecEnv(factories, min(config.env_threads or available_cpus(), k)))
        self.model = build_model(config, self.venv, settings)
        # The driver logs; without a logger of its own SB3 would make an empty /tmp/SB3-<date>
        # folder at every rollout's set-up.
        self.model.set_logger(Logger(folder=None, output_formats=[]))
        self.venv.seed(config.seed + first)  # the model's constructor seeded them from the run's seed
        apply_ppo_settings(self.model, settings)
        if torch_rng is not None:
            torch.set_rng_state(torch_rng)
        self.callback = _WorkerCallback(k, TASK_SPECS[config.curriculum.task].reward_terms)
        self.callback.init_callback(self.model)

    def rollout(self, weights: dict[str, Any], obs_rms: Any, ret_rms: Any, settings: PpoSettings,
                stage_index: int) -> RolloutResult:
        """One rollout of ``settings.n_steps`` steps per env with the learner's weights and
        normalization statistics."""
        model, venv = self.model, self.venv
        model.policy.load_state_dict(weights)
        apply_ppo_settings(model, settings)
        venv.obs_rms, venv.ret_rms = copy.deepcopy(obs_rms), copy.deepcopy(ret_rms)
        start_obs, start_ret = Moments.of(venv.obs_rms), Moments.of(venv.ret_rms)
        callback = self.callback
        callback.reset()
        callback.stage_index = stage_index
        prepare_rollout(model, model.n_steps * venv.num_envs, callback)
        model.collect_rollouts(venv, callback, model.rollout_buffer, n_rollout_steps=model.n_steps)
        buffer = model.rollout_buffer
        return RolloutResult(
            buffer={name: getattr(buffer, name).copy() for name in BUFFER_FIELDS},
            obs_rms=copy.deepcopy(venv.obs_rms), ret_rms=copy.deepcopy(venv.ret_rms),
            obs_added=Moments.of(venv.obs_rms).added_since(start_obs),
            ret_added=Moments.of(venv.ret_rms).added_since(start_ret),
            episodes=callback.episodes, term_sums=callback.tally.term_sums, term_count=callback.tally.term_count,
            seconds=time.perf_counter() - callback.started_at)

    def set_stage(self, distribution: TaskKnobs) -> None:
        self.venv.env_method("configure", distribution=distribution)

    def random_state(self) -> dict[str, Any]:
        import torch

        return {"envs": list(self.venv.get_attr("np_random")), "torch": torch.get_rng_state()}

    def restore_random_state(self, envs: list[Any], torch_rng: Any) -> None:
        import torch

        drop_queued_seeds(self.venv.venv)
        for index, generator in enumerate(envs):
            self.venv.set_attr("np_random", generator, indices=[index])
        torch.set_rng_state(torch_rng)

    def pid(self) -> int:
        import os

        return os.getpid()

    def node_id(self) -> str:
        """The Ray node this worker runs on (a worker run outside Ray has none)."""
        import ray

        return ray.get_runtime_context().get_node_id()
