"""Rollout collection behind one small interface: the trainer asks for a rollout in the model's
buffer and for stage changes; where the envs run is the collector's business.

:class:`LocalRollouts` steps the envs of this process (a thread pool, dummy or subprocess
vec env under one VecNormalize). Another backend (workers on other machines) implements the
same methods.
"""

from __future__ import annotations

import random
import time
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from myo_sds.curricula.schedule import PpoSettings
from myo_sds.envs.knobs import TaskKnobs
from myo_sds.sb3_internals import drop_queued_seeds


class WorkerLost(RuntimeError):
    """A rollout worker kept dying; the run stops after a checkpoint."""


class RolloutCollector(Protocol):
    """Where the trainer's samples come from."""

    venv: Any  # the VecNormalize whose statistics are checkpointed with the model
    env_seconds: float  # wall time spent stepping envs so far
    restarts: int  # workers lost and restarted so far (a local backend has none)

    def collect(self, model, callback) -> bool:
        """Fill ``model.rollout_buffer`` with ``model.n_steps`` steps of every env; False when
        the callback stopped it early (nothing to train on then)."""

    def set_stage(self, distribution: TaskKnobs) -> None:
        """Give every env the new stage's knobs before the next rollout."""

    def set_ppo_settings(self, settings: PpoSettings) -> None:
        """The PPO settings in force from the next rollout on (its length, for remote buffers)."""

    def random_state(self) -> dict[str, Any]:
        """Everything random that shapes the episodes and updates to come."""

    def restore_random_state(self, saved: dict[str, Any] | None, fallback_seed: int) -> None:
        """Continue the streams of ``saved`` (None: seed them from ``fallback_seed``)."""

    def close(self) -> None: ...


class WallClock:
    """Wall time spent inside wrapped callables."""

    def __init__(self) -> None:
        self.seconds = 0.0

    def wrap(self, function: Callable) -> Callable:
        def timed(*args, **kwargs):
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - start
        return timed


class LocalRollouts:
    """The envs of this process under one VecNormalize."""

    restarts = 0

    def __init__(self, venv) -> None:
        self.venv = venv
        # Env stepping is timed on the inner VecEnv, which is never pickled.
        self._clock = WallClock()
        inner = venv.venv
        inner.step_async = self._clock.wrap(inner.step_async)
        inner.step_wait = self._clock.wrap(inner.step_wait)

    @property
    def env_seconds(self) -> float:
        return self._clock.seconds

    def collect(self, model, callback) -> bool:
        return model.collect_rollouts(self.venv, callback, model.rollout_buffer, n_rollout_steps=model.n_steps)

    def set_stage(self, distribution: TaskKnobs) -> None:
        self.venv.env_method("configure", distribution=distribution)

    def set_ppo_settings(self, settings: PpoSettings) -> None:
        pass  # the model the trainer updates is the one that collects

    def random_state(self) -> dict[str, Any]:
        """Each env's generator (task draws at reset), and the global python, numpy (minibatch
        order) and torch (action noise) generators."""
        import torch

        return {"envs": list(self.venv.get_attr("np_random")), "python": random.getstate(),
                "numpy": np.random.get_state(), "torch": torch.get_rng_state()}

    def restore_random_state(self, saved: dict[str, Any] | None, fallback_seed: int) -> None:
        """Continue the saved streams; without them (an older checkpoint), seed every stream
        from ``fallback_seed``, so a resume still draws new episodes. Either way the envs' next
        reset draws from their own generators, not from the run's seed."""
        import torch

        venv = self.venv
        drop_queued_seeds(venv.venv)
        if saved is not None and len(saved["envs"]) == venv.num_envs:
            for index, generator in enumerate(saved["envs"]):
                venv.set_attr("np_random", generator, indices=[index])
            random.setstate(saved["python"])
            np.random.set_state(saved["numpy"])
            torch.set_rng_state(saved["torch"])
            return
        from gymnasium.utils import seeding
        from stable_baselines3.common.utils import set_random_seed

        set_random_seed(fallback_seed)
        for index in range(venv.num_envs):
            venv.set_attr("np_random", seeding.np_random(fallback_seed * 1000 + index)[0], indices=[index])

    def close(self) -> None:
        self.venv.close()
