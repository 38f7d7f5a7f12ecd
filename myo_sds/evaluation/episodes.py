"""Deterministic episodes of a checkpoint on our env or the official one, and their report.

Episode ``i`` of an evaluation is reset with seed ``seed + i``. Our presets draw task
instances exactly as the official env does, so the same seeds give the same episodes on
both; with a deterministic policy the two scores then agree (tests/test_evaluation.py).

A fixed start (P1) with a deterministic policy is one episode however often it is played:
start noise (``EnvChoice.start_noise``) moves each hand joint by U(-noise, noise) after the
reset, drawn from the episode's seed apart from the env's own stream, so our env and the
official one get the same move and still replay the same episode.
"""

from __future__ import annotations

import math
import multiprocessing
from collections.abc import Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from myo_sds.envs.metrics import (
    PHASE_SECTORS,
    EpisodeResult,
    drop_rate,
    mean_confidence_interval,
    mean_effort,
    official_score,
    phase_sector,
    sector_name,
)
from myo_sds.envs.task_specs import TASK_SPECS
from myo_sds.evaluation.checkpoints import (
    _OFFICIAL_DIRECTIONS,
    CheckpointRef,
    EnvChoice,
    EvaluationError,
    LoadedPolicy,
    load_policy,
)
from myo_sds.run_folder import EpisodeRecord


@dataclass
class EvaluationReport:
    checkpoint: CheckpointRef
    env: EnvChoice
    seed: int
    episodes: list[EpisodeResult] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        scores = [e.score for e in self.episodes]
        mean, low, high = mean_confidence_interval(scores)
        per_direction = {}
        for direction in sorted({e.direction for e in self.episodes if e.direction}):
            values = [e.score for e in self.episodes if e.direction == direction]
            d_mean, d_low, d_high = mean_confidence_interval(values)
            per_direction[direction] = {"episodes": len(values), "score": d_mean, "ci95": [d_low, d_high]}
        return {
            "checkpoint": str(self.checkpoint.model),
            "run_dir": str(self.checkpoint.run_dir) if self.checkpoint.run_dir else None,
            "env": self.env.name,
            "official_env": self.env.official,
            "start": TASK_SPECS[self.env.task].preset_notes.get(
                self.env.name, "the stage's own start" if self.env.name.startswith("stage:") else ""),
            "seed": self.seed,
            "start_noise": self.env.start_noise,
            "episodes": len(self.episodes),
            "score": official_score(self.episodes),
            "score_ci95": [low, high],
            "score_spread": score_spread(scores),
            "effort": mean_effort(self.episodes),
            "drop_rate": drop_rate(self.episodes),
            "mean_length": float(np.mean([e.length for e in self.episodes])) if self.episodes else math.nan,
            "per_direction": per_direction,
            "per_start_phase": per_start_phase(self.episodes),
            "per_start_phase_of": TASK_SPECS[self.env.task].start_phase_name,
            "per_target_phase": per_target_phase(self.episodes),
            "per_episode": [e.to_dict() for e in self.episodes],
        }


def score_spread(scores: Sequence[float]) -> dict[str, float]:
    """How the episodes' scores spread: standard deviation, minimum, quartiles, maximum."""
    if not scores:
        return {}
    values = np.asarray(scores, dtype=float)
    q1, median, q3 = np.quantile(values, [0.25, 0.5, 0.75])
    return {"std": float(values.std()), "min": float(values.min()), "q1": float(q1), "median": float(median),
            "q3": float(q3), "max": float(values.max())}


def per_start_phase(episodes: Sequence[EpisodeResult | EpisodeRecord]) -> dict[str, dict[str, Any]]:
    """Score, drop rate and the mean step of the drops by the goal's start phase, in 45-degree
    sectors ("0-45", ...), of evaluated episodes or of a run's logged training episodes.

    Empty unless the start phase varies between episodes (stages with random phases, P2's
    random start offsets): a policy's average can hide sectors where it always drops the balls.
    """
    phased = [e for e in episodes if e.start_phase is not None]
    if len({e.start_phase for e in phased}) < 2:
        return {}
    sectors: dict[int, list[EpisodeResult]] = {}
    for e in phased:
        sectors.setdefault(phase_sector(e.start_phase), []).append(e)
    return {sector_name(k): {"episodes": len(members), "score": official_score(members),
                             "drop_rate": drop_rate(members), "drop_step": _mean_drop_step(members)}
            for k, members in sorted(sectors.items())}


def _mean_drop_step(episodes: Sequence[EpisodeResult | EpisodeRecord]) -> float | None:
    """When the dropped episodes ended, on average (None without drops): a sector whose drops
    come early loses the balls to the start, one whose drops come late to what follows."""
    lengths = [e.length for e in episodes if e.dropped]
    return float(np.mean(lengths)) if lengths else None


def per_target_phase(episodes: Sequence[EpisodeResult]) -> dict[str, dict[str, Any]]:
    """The fraction of steps solved while the first target was in each 45-degree phase sector,
    over all episodes (steps after a drop are not counted). A policy that carries the balls
    along most of the orbit but loses them at one part shows a low sector there; empty when
    the env does not report target phases (the official env, the die)."""
    counted = [e for e in episodes if e.steps_by_target_phase is not None]
    if not counted:
        return {}
    steps = np.sum([e.steps_by_target_phase for e in counted], axis=0)
    solved = np.sum([e.solved_by_target_phase for e in counted], axis=0)
    return {sector_name(k): {"steps": int(steps[k]), "solved_fraction": float(solved[k] / steps[k])}
            for k in range(PHASE_SECTORS) if steps[k] > 0}


def make_env(choice: EnvChoice, render: bool = False):
    if choice.official:
        import gymnasium as gym

        try:
            import myosuite  # noqa: F401  (registers the official ids)
        except ImportError:
            raise EvaluationError("--official needs the myosuite package: pip install myosuite==3.0.0") from None
        spec = TASK_SPECS[choice.task]
        env = gym.make(spec.official_ids[choice.name])
        if choice.name in spec.official_setup:
            spec.official_setup[choice.name](env.unwrapped)
        return env
    return TASK_SPECS[choice.task].env_class()(render_mode="rgb_array" if render else None,
                                               distribution=choice.distribution)


def _official_direction(env) -> str | None:
    which = getattr(env.unwrapped, "which_task", None)
    return _OFFICIAL_DIRECTIONS[which.value] if which is not None else None


_START_NOISE_STREAM = 0x57A27  # mixed with the episode's seed: a stream apart from the env's own


def start_offsets(seed: int, noise: float, joints: int) -> np.ndarray:
    """The hand-joint offsets (rad) of the episode reset with ``seed``: U(-noise, noise) each."""
    return np.random.default_rng([_START_NOISE_STREAM, seed]).uniform(-noise, noise, joints)


def move_hand_joints(env, choice: EnvChoice, offsets: np.ndarray) -> np.ndarray:
    """Add ``offsets`` to the hand's joint angles of a just-reset env, ours or the official one
    (the same arithmetic on both: no clipping, then ``mj_forward``); the new observation."""
    if not choice.official:
        return env.unwrapped.move_hand_joints(offsets)
    import mujoco

    official = env.unwrapped
    official.data.qpos[:len(offsets)] += offsets
    mujoco.mj_forward(official.model, official.data)
    if hasattr(official, "get_obs"):  # Baoding's; the die env has only the observation dict
        return np.asarray(official.get_obs(), dtype=np.float32)
    obs_dict = official.get_obs_dict(official.model, official.data)
    return np.asarray(official._obs_dict_to_vec(obs_dict), dtype=np.float32)


def run_episode(policy: LoadedPolicy, env, choice: EnvChoice, seed: int, frames: list | None = None) -> EpisodeResult:
    """One deterministic episode; the LSTM state starts fresh. With ``frames``, each step's
    rendered image and whether the step was solved are appended to it."""
    obs, _ = env.reset(seed=seed)
    if choice.start_noise:
        offsets = start_offsets(seed, choice.start_noise, TASK_SPECS[choice.task].hand_joints)
        obs = move_hand_joints(env, choice, offsets)
    state, start = None, True
    solved = length = 0
    effort = 0.0
    while True:
        action, state = policy.act(obs, state, start)
        start = False
        obs, _, terminated, truncated, info = env.step(action)
        if frames is not None:
            frames.append((env.render(), bool(info["solved"])))
        length += 1
        solved += int(bool(info["solved"]))
        effort -= float(info["act_reg"])
        if terminated or truncated:
            break
    if not choice.official:
        return info["episode_result"]
    horizon = env.spec.max_episode_steps
    return EpisodeResult(solved_steps=solved, length=length, horizon=horizon, dropped=bool(terminated),
                         effort=effort / length, direction=_official_direction(env), task=choice.task)


def run_episodes_together(policy: LoadedPolicy, envs: Sequence, choice: EnvChoice, seeds: Sequence[int],
                          pool: Executor | None = None) -> list[EpisodeResult]:
    """Deterministic episodes on our env, one per env and seed, in lockstep: one batched forward
    pass per step for all of them, the envs stepped on ``pool``'s threads (MuJoCo releases the
    GIL). Each episode is ``run_episode``'s with that seed up to the last bits of the batched
    arithmetic, which a long chaotic episode can amplify."""
    if choice.official:
        raise ValueError("episodes run together on our env only")
    observations = []
    for env, seed in zip(envs, seeds, strict=True):
        obs, _ = env.reset(seed=seed)
        if choice.start_noise:
            obs = move_hand_joints(env, choice, start_offsets(seed, choice.start_noise,
                                                              TASK_SPECS[choice.task].hand_joints))
        observations.append(obs)
    batch = np.stack(observations)
    results: list[EpisodeResult | None] = [None] * len(seeds)
    state, starts = None, np.ones(len(seeds), dtype=bool)

    def step(index: int):
        return index, envs[index].step(actions[index])

    while running := [i for i, result in enumerate(results) if result is None]:
        actions, state = policy.act_together(batch, state, starts)
        starts[:] = False
        for index, (obs, _, terminated, truncated, info) in (pool.map(step, running) if pool else map(step, running)):
            batch[index] = obs  # a finished episode's row stays in the batch, its actions unused
            if terminated or truncated:
                results[index] = info["episode_result"]
    return results


def _episodes_worker(args: tuple[CheckpointRef, EnvChoice, list[int]]) -> list[EpisodeResult]:
    import torch

    ref, choice, seeds = args
    torch.set_num_threads(1)  # the same arithmetic whatever the number of workers
    policy = load_policy(ref, choice.task)
    env = make_env(choice)
    return [run_episode(policy, env, choice, seed) for seed in seeds]


def evaluate(ref: CheckpointRef, choice: EnvChoice, episodes: int, seed: int = 0, workers: int = 1) -> EvaluationReport:
    """Run ``episodes`` deterministic episodes (seeds ``seed .. seed + episodes - 1``)."""
    load_policy(ref, choice.task)  # fail early, in this process, with a clear message
    seeds = [seed + i for i in range(episodes)]
    workers = max(1, min(workers, episodes))
    if workers == 1:
        results = _episodes_worker((ref, choice, seeds))
    else:
        chunks = [seeds[i::workers] for i in range(workers)]
        with multiprocessing.get_context("spawn").Pool(workers) as pool:
            parts = pool.map(_episodes_worker, [(ref, choice, chunk) for chunk in chunks])
        by_seed = {s: r for chunk, part in zip(chunks, parts) for s, r in zip(chunk, part)}
        results = [by_seed[s] for s in seeds]
    return EvaluationReport(ref, choice, seed, results)


