"""The SB3 callback that watches rollouts for the trainer, and the update's minibatch hook."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from myo_sds.envs.metrics import EpisodeResult
from myo_sds.threads import UpdateThreads


class UpdateInterrupted(Exception):
    """Raised between two minibatches of a PPO update when a stop was requested."""


class EpisodeTally:
    """What each env step of a rollout says of its episodes, for the trainer's callback and a
    Ray worker's alike: the reward terms summed over steps and envs, and each finished episode
    with the stage its env began it in (an episode begun before a stage change is not the new
    stage's)."""

    def __init__(self, n_envs: int, terms: tuple[str, ...], stage_index: int = 0) -> None:
        self.terms = tuple(t for t in terms if t != "done")
        self.episode_stage = [stage_index] * n_envs  # the stage each env's current episode began in
        self.term_sums: dict[str, float] = {}
        self.term_count = 0

    def observe(self, infos, dones, stage_index: int) -> list[tuple[int, EpisodeResult]]:
        """One step of every env; returns ``(stage begun in, result)`` of each episode it ended."""
        finished = []
        for rank, (info, done) in enumerate(zip(infos, dones)):
            for key in self.terms:
                self.term_sums[key] = self.term_sums.get(key, 0.0) + info.get(key, 0.0)
            if done:
                result = info.get("episode_result")
                if result is not None:
                    finished.append((self.episode_stage[rank], result))
                self.episode_stage[rank] = stage_index
        self.term_count += len(infos)
        return finished

    def add_sums(self, sums: dict[str, float], count: int) -> None:
        for key, value in sums.items():
            self.term_sums[key] = self.term_sums.get(key, 0.0) + value
        self.term_count += count

    def pop_sums(self) -> tuple[dict[str, float], int]:
        sums, count = self.term_sums, self.term_count
        self.term_sums, self.term_count = {}, 0
        return sums, count


class EpisodeCollector(BaseCallback):
    """SB3 callback: gathers finished episodes of the current stage (with the env step and
    the run's training wall time at which each ended), logs reward terms, drives the progress
    bar, sets torch's threads for each phase, and stops ``learn`` when a stop was requested."""

    def __init__(self, n_envs: int, stage_index: int, terms: tuple[str, ...], run_wall_s: Callable[[], float],
                 update_threads: UpdateThreads) -> None:
        super().__init__(verbose=0)
        self.run_wall_s = run_wall_s
        self.update_threads = update_threads
        self.tally = EpisodeTally(n_envs, terms, stage_index)
        self.stage_index = stage_index
        self.results: list[tuple[int, float, EpisodeResult]] = []
        self.stop_requested: str | None = None
        self.progress_bar: Any = None

    def _on_step(self) -> bool:
        infos, dones = self.locals["infos"], self.locals["dones"]
        wall_s = self.run_wall_s() if dones.any() else 0.0
        for began, result in self.tally.observe(infos, dones, self.stage_index):
            if began == self.stage_index:
                self.results.append((self.num_timesteps, wall_s, result))
        if self.progress_bar is not None:
            self.progress_bar.update(len(infos))
        return self.stop_requested is None

    def _on_rollout_start(self) -> None:
        # Env threads need the cores while collecting; torch's idle OpenMP workers would
        # spin on them. Policy inference on a few dozen observations needs one thread.
        self._set_threads(1)

    def _on_rollout_end(self) -> None:
        self._set_threads(self.update_threads.threads())

    def before_optimizer_step(self, optimizer, args, kwargs) -> None:
        """Optimizer pre-hook, once per minibatch: stop here if asked to (the weights and the
        optimizer state stay those of the last finished minibatch); otherwise make room for
        other processes that started using the CPUs during the update."""
        if self.stop_requested:
            raise UpdateInterrupted(self.stop_requested)
        self._set_threads(self.update_threads.threads())

    @staticmethod
    def _set_threads(threads: int) -> None:
        import torch

        if torch.get_num_threads() != threads:
            torch.set_num_threads(threads)

    def add_remote_results(self, episodes: list[tuple[int, float, int, EpisodeResult]],
                           term_sums: list[dict[str, float]], term_count: int, steps: int) -> None:
        """What rollout workers saw: ``(env step, wall time, stage begun in, result)`` per
        finished episode (the current stage's are kept), their reward-term sums, their steps."""
        self.results.extend((step, wall_s, result) for step, wall_s, stage, result in episodes
                            if stage == self.stage_index)
        for sums in term_sums:
            self.tally.add_sums(sums, 0)
        self.tally.add_sums({}, term_count)
        if self.progress_bar is not None:
            self.progress_bar.update(steps)

    def pop_results(self) -> list[tuple[int, float, EpisodeResult]]:
        results, self.results = self.results, []
        return results

    def pop_term_means(self) -> dict[str, float]:
        sums, count = self.tally.pop_sums()
        return {k: v / count for k, v in sums.items()} if count else {}


# -- the run -----------------------------------------------------------------------------


def log_rest_starts(logger, episodes) -> None:
    """The rest-start signal: of a rollout's episodes that began with the balls where the hand
    holds them (not placed on their targets), how many and their mean solved steps, by direction.
    Rotation stages with ``rsi_probability`` < 1 have some; picking moving targets up from rest is
    what the fixed-start stages then ask for."""
    by_direction: dict[str, list[int]] = {}
    for r in episodes:
        if r.start == "rest":
            by_direction.setdefault(r.direction or "all", []).append(r.solved_steps)
    for direction, solved in by_direction.items():
        logger.record(f"rest_start/{direction}_episodes", len(solved))
        logger.record(f"rest_start/{direction}_solved_steps", float(np.mean(solved)))


@dataclass
class RolloutTiming:
    steps: int
    wall_s: float
    env_s: float
    update_s: float


def log_rollout(logger, episodes, timing: RolloutTiming | None, policy) -> None:
    """A rollout's episodes (score, effort, drops, the rest-start signal), its timing and the
    policy's action noise, into TensorBoard."""
    if episodes:
        logger.record("rollout/score", float(np.mean([r.score for r in episodes])))
        logger.record("rollout/effort", float(np.mean([r.effort for r in episodes])))
        logger.record("rollout/drop_rate", float(np.mean([r.dropped for r in episodes])))
        log_rest_starts(logger, episodes)
    if timing and timing.wall_s > 0:
        logger.record("time/env_steps_per_s", timing.steps / timing.wall_s)
        logger.record("time/env_stepping_share", timing.env_s / timing.wall_s)
        logger.record("time/update_share", timing.update_s / timing.wall_s)
    std = policy.log_std.detach().exp()
    logger.record("policy/action_std_mean", float(std.mean()))  # SB3 logs the mean as train/std
    logger.record("policy/action_std_min", float(std.min()))
