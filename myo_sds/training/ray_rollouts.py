"""Rollouts on Ray: ``workers`` actors, each stepping K envs with a copy of the policy.

Per rollout the learner puts the weights in Ray's object store once, every worker runs
``n_steps`` steps with them (:class:`~myo_sds.training.rollout_worker.RolloutWorker`) and
returns its columns of the rollout buffer; the learner fills sb3-contrib's buffer (workers x K
columns) and runs the unchanged PPO update. Normalization statistics: each worker starts the
rollout from the learner's, and the learner merges what every worker added (the parallel
mean/variance combination), so one VecNormalize is checkpointed as with the local backend.

A worker whose process dies during a rollout is restarted by Ray (``max_restarts=-1``; its
constructor builds its envs again) and its rollout is redone, with a warning and the
``rollout/worker_restarts`` counter; nothing of the lost rollout reaches the buffer. A worker
that dies ``max_restarts`` times in a row stops the run (the trainer checkpoints first).
"""

from __future__ import annotations

import copy
import logging
import time
from typing import Any

import numpy as np

from myo_sds.curricula.run_config import RunConfig
from myo_sds.curricula.schedule import PpoSettings
from myo_sds.curricula.schema import ConfigError
from myo_sds.envs.knobs import TaskKnobs
from myo_sds.training.rollout import WorkerLost
from myo_sds.training.rollout_worker import BUFFER_FIELDS, Moments, RolloutResult, RolloutWorker

log = logging.getLogger(__name__)
PLACEMENT_TIMEOUT_S = 120.0


def _check_reachable(address: str | None, timeout_s: float = 5.0) -> None:
    """A ``host:port`` address that answers no TCP connection fails at once (ray.init would wait
    minutes); ``auto`` and ``ray://`` addresses are left to Ray."""
    import socket

    if not address or address == "auto" or "://" in address or ":" not in address:
        return
    host, _, port = address.rpartition(":")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout_s):
            return
    except (OSError, ValueError) as error:
        raise ConfigError(f"rollout.address: no Ray cluster answers at {address} ({error}); start one with "
                          "`ray start --head --port=6379` there, or leave address unset for this machine only") from None


def connect(config: RunConfig) -> None:
    """Start or join the Ray cluster the config names, checking it has room for the workers."""
    try:
        import ray
    except ImportError:
        raise ConfigError("rollout.backend: ray needs the ray package: pip install 'ray>=2.58,<2.61'") from None
    if not ray.is_initialized():
        _check_reachable(config.rollout.address)
        try:
            if config.rollout.address:
                ray.init(address=config.rollout.address, log_to_driver=False)
            else:
                ray.init(num_cpus=max(config.rollout.workers, 1), log_to_driver=False, include_dashboard=False)
        except (ConnectionError, RuntimeError, ValueError) as error:
            raise ConfigError(f"rollout.address: cannot reach a Ray cluster at {config.rollout.address!r} ({error}); "
                              "start one with `ray start --head` or leave address unset") from None
    cpus = int(ray.cluster_resources().get("CPU", 0))
    if config.rollout.workers > cpus:
        raise ConfigError(f"rollout.workers: {config.rollout.workers} workers of one CPU each, but the Ray cluster "
                          f"has {cpus} CPUs")


class RayRollouts:
    """The rollout collector of the Ray backend (see the module docstring)."""

    def __init__(self, config: RunConfig, venv, distribution: TaskKnobs, settings: PpoSettings,
                 torch_rng: Any) -> None:
        connect(config)
        import ray

        self.config, self.venv = config, venv
        self.k = config.rollout.envs_per_worker
        self.restarts = 0
        # A worker's process starts before it imports anything of ours: its environment comes with it.
        from myo_sds import process_environment

        remote = ray.remote(num_cpus=1, max_restarts=-1, max_task_retries=0,
                            runtime_env={"env_vars": {**process_environment(), **_user_settings()}})(RolloutWorker)
        self.workers = [remote.remote(config, index, distribution, settings, torch_rng if index == 0 else None)
                        for index in range(config.rollout.workers)]
        self.distribution, self.settings = distribution, settings
        self.env_seconds = 0.0
        # Where a rollout's wall time goes, summed: putting the weights, waiting for the workers,
        # filling the buffer and merging the statistics.
        self.seconds = {"broadcast": 0.0, "sampling": 0.0, "gathering": 0.0}
        _, waiting = ray.wait([worker.pid.remote() for worker in self.workers], num_returns=len(self.workers),
                                  timeout=PLACEMENT_TIMEOUT_S)
        if waiting:
            self.close()
            raise ConfigError(f"rollout.workers: {len(waiting)} of {len(self.workers)} workers could not start within "
                              f"{PLACEMENT_TIMEOUT_S:.0f} s: the cluster's CPUs are taken (another run's workers?)")

    # RolloutCollector ------------------------------------------------------------------

    def collect(self, model, callback) -> bool:
        import ray

        callback.on_rollout_start()
        started = time.perf_counter()
        weights = ray.put({k: v.detach().cpu() for k, v in model.policy.state_dict().items()})
        put_at = time.perf_counter()
        self.seconds["broadcast"] += put_at - started
        stats = (self.venv.obs_rms, self.venv.ret_rms)
        results = self._gather(weights, stats, self.settings, callback.stage_index)
        gathered_at = time.perf_counter()
        self.seconds["sampling"] += gathered_at - put_at
        buffer, k = model.rollout_buffer, self.k
        buffer.reset()  # the last update's get() flattened its arrays
        for index, result in enumerate(results):
            for name in BUFFER_FIELDS:
                target = getattr(buffer, name)
                columns = slice(index * k, (index + 1) * k)
                if target.ndim == 4:  # LSTM states: (steps, layers, envs, hidden)
                    target[:, :, columns] = result.buffer[name]
                else:
                    target[:, columns] = result.buffer[name]
        buffer.pos, buffer.full, buffer.generator_ready = buffer.buffer_size, True, False
        self._merge_statistics(results)
        n_envs = self.config.n_envs
        start_step, start_wall = int(model.num_timesteps), callback.run_wall_s() - (time.perf_counter() - started)
        model.num_timesteps += model.n_steps * n_envs
        # In env step order, and within a step in global env rank order (workers in turn), as locally.
        episodes = sorted(((start_step + (step + 1) * n_envs, start_wall + seconds, stage, result)
                           for result_set in results for step, seconds, stage, result in result_set.episodes),
                          key=lambda episode: episode[0])
        callback.add_remote_results(episodes, [r.term_sums for r in results], sum(r.term_count for r in results),
                                    model.n_steps * n_envs)
        self.env_seconds += max(r.seconds for r in results)
        self.seconds["gathering"] += time.perf_counter() - gathered_at
        callback.on_rollout_end()
        return True

    def set_ppo_settings(self, settings: PpoSettings) -> None:
        self.settings = settings

    def set_stage(self, distribution: TaskKnobs) -> None:
        import ray

        self.distribution = distribution
        ray.get([worker.set_stage.remote(distribution) for worker in self.workers])

    def random_state(self) -> dict[str, Any]:
        """The workers' env generators (in global rank order) and torch streams; ``torch`` is
        worker 0's, so a one-worker checkpoint resumes on the local backend where it left off."""
        import random


        states = [self._call(index, "random_state") for index in range(len(self.workers))]
        return {"envs": [g for state in states for g in state["envs"]], "python": random.getstate(),
                "numpy": np.random.get_state(), "torch": states[0]["torch"],
                "worker_torch": [state["torch"] for state in states]}

    def restore_random_state(self, saved: dict[str, Any] | None, fallback_seed: int) -> None:
        import random

        import ray
        import torch
        from gymnasium.utils import seeding

        n_envs = self.config.n_envs
        if saved is not None and len(saved["envs"]) == n_envs:
            envs, torches = saved["envs"], saved.get("worker_torch") or [saved["torch"]]
            random.setstate(saved["python"])
            np.random.set_state(saved["numpy"])
        else:
            envs = [seeding.np_random(fallback_seed * 1000 + index)[0] for index in range(n_envs)]
            torches = []
        generator = torch.Generator()
        for index, worker in enumerate(self.workers):
            if index < len(torches):
                torch_rng = torches[index]
            else:
                torch_rng = generator.manual_seed(fallback_seed * 1000 + n_envs + index).get_state()
            ray.get(worker.restore_random_state.remote(envs[index * self.k:(index + 1) * self.k], torch_rng))

    def close(self) -> None:
        import ray

        for worker in self.workers:
            ray.kill(worker)
        self.workers = []

    # internals ---------------------------------------------------------------------------

    def _gather(self, weights, stats, settings: PpoSettings, stage_index: int) -> list[RolloutResult]:
        """Every worker's rollout; a worker that died is restarted by Ray and asked again."""
        import ray
        from ray.exceptions import RayActorError

        pending = {index: worker.rollout.remote(weights, *stats, settings, stage_index)
                   for index, worker in enumerate(self.workers)}
        results: dict[int, dict[str, Any]] = {}
        failures = [0] * len(self.workers)
        while pending:
            index, future = next(iter(pending.items()))
            try:
                results[index] = ray.get(future)
                del pending[index]
            except RayActorError as error:
                failures[index] += 1
                self.restarts += 1
                if failures[index] > self.config.rollout.max_restarts:
                    raise WorkerLost(f"rollout worker {index} died {failures[index]} times in a row "
                                     f"({type(error).__name__}); stopping the run") from None
                log.warning("rollout worker %d died during a rollout (%s); redoing its rollout", index,
                            type(error).__name__)
                self._wait_until_alive(index)
                pending[index] = self.workers[index].rollout.remote(weights, *stats, settings, stage_index)
        return [results[index] for index in range(len(self.workers))]

    def _call(self, index: int, method: str, *args, timeout_s: float = 120.0):
        """A call on worker ``index`` that waits out a restart of the worker."""
        import ray
        from ray.exceptions import RayActorError

        deadline = time.monotonic() + timeout_s
        while True:
            try:
                return ray.get(getattr(self.workers[index], method).remote(*args))
            except RayActorError:
                if time.monotonic() > deadline:
                    raise WorkerLost(f"rollout worker {index} did not answer within {timeout_s:.0f} s") from None
                time.sleep(0.5)

    def _wait_until_alive(self, index: int, timeout_s: float = 120.0) -> None:
        """After Ray restarts a worker (its constructor runs again), give it the current stage."""
        import torch
        from gymnasium.utils import seeding

        base = (self.config.seed + 7919 * self.restarts) * 1000
        self._call(index, "set_stage", self.distribution, timeout_s=timeout_s)
        # Fresh streams: the rebuilt envs would otherwise replay the run's first episodes.
        envs = [seeding.np_random(base + index * self.k + rank)[0] for rank in range(self.k)]
        self._call(index, "restore_random_state", envs, torch.Generator().manual_seed(base + index).get_state())

    def _merge_statistics(self, results: list[RolloutResult]) -> None:
        """Worker 0's statistics (the learner's plus what it saw, updated step by step) plus
        what every other worker added."""
        obs_rms, ret_rms = copy.deepcopy(results[0].obs_rms), copy.deepcopy(results[0].ret_rms)
        for result in results[1:]:
            for rms, added in ((obs_rms, result.obs_added), (ret_rms, result.ret_added)):
                if added.count > 0:
                    rms.update_from_moments(added.mean, added.var, added.count)
        self.venv.obs_rms, self.venv.ret_rms = obs_rms, ret_rms


__all__ = ["Moments", "RayRollouts", "WorkerLost", "connect"]


def _user_settings() -> dict[str, str]:
    """The process-environment variables this process has (a user's setting, or ours), for the workers."""
    import os

    from myo_sds import process_environment

    return {name: os.environ[name] for name in process_environment() if name in os.environ}
