"""A stage's periodic evaluation (``evaluate`` in the curriculum) and the curriculum's stage-end
probe (``probe``): deterministic episodes of the policy being trained, on the stage's task, another
stage's or a preset, scored as ``evaluate.py`` scores them and logged to the run's
``evaluations.csv``.

It reads the model and the current normalization statistics and draws nothing from the
training's random streams (its envs are its own, reset with seeds ``first .. first + episodes -
1``: the env step of the evaluation with ``seeds: fresh``, 0 with ``fixed`` and for the probe), so
a run with evaluations trains exactly as one without them. Its episodes run together, one batched
forward pass per step and the envs stepped on every CPU (about twice as fast as one at a time:
the training's envs and update wait meanwhile); ``evaluate.py --env stage:NAME`` plays the same
seeds one at a time, the same episodes up to the last bits of the batched arithmetic.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import torch

from myo_sds.curricula.schema import Curriculum, Stage, StageEndProbe
from myo_sds.curricula.state import CurriculumState
from myo_sds.envs.metrics import EpisodeResult, drop_rate, official_score
from myo_sds.evaluation.checkpoints import EnvChoice, LoadedPolicy
from myo_sds.evaluation.episodes import make_env, run_episodes_together
from myo_sds.evaluation.summary import describe_directions
from myo_sds.run_folder import EvaluationRecord
from myo_sds.threads import available_cpus


@dataclass(frozen=True)
class EvaluationResult:
    """What a set of deterministic episodes says: mean official score, mean return (under the
    evaluated env's reward weights), drop rate and median solved steps."""

    env: str
    episodes: int
    score: float
    reward: float | None
    drop_rate: float
    median_solved_steps: float
    # Baoding: per direction (hold, cw, ccw), its episodes, mean return, median solved steps and
    # drop rate; a policy may pick the balls up from rest one way and not the other.
    by_direction: dict[str, dict] | None = None
    first_seed: int = 0  # the episodes' seeds: first_seed .. first_seed + episodes - 1

    @classmethod
    def of(cls, env: str, results: list[EpisodeResult], first_seed: int = 0) -> EvaluationResult:
        by_direction = {d: {"episodes": len(group), "reward": _mean_reward(group),
                            "median_solved_steps": float(np.median([r.solved_steps for r in group])),
                            "drop_rate": drop_rate(group)}
                        for d in sorted({r.direction for r in results if r.direction})
                        for group in [[r for r in results if r.direction == d]]}
        return cls(env, len(results), official_score(results), _mean_reward(results), drop_rate(results),
                   float(np.median([r.solved_steps for r in results])), by_direction or None, first_seed)

    def as_dict(self) -> dict:
        values = {"env": self.env, "episodes": self.episodes, "score": self.score, "reward": self.reward,
                  "drop_rate": self.drop_rate, "median_solved_steps": self.median_solved_steps,
                  "first_seed": self.first_seed}
        return values | ({"by_direction": self.by_direction} if self.by_direction else {})

    def describe(self) -> str:
        """One line: score, median solved steps, drops, and per direction when there are several."""
        text = (f"score {self.score:.3f}, median solved steps {self.median_solved_steps:.0f}, "
                f"{self.drop_rate:.0%} dropped ({self.episodes} episodes)")
        return text + describe_directions(self.by_direction)


def _mean_reward(results: list[EpisodeResult]) -> float | None:
    rewards = [r.reward for r in results if r.reward is not None]
    return float(np.mean(rewards)) if rewards and len(rewards) == len(results) else None


# Episodes run together at most: each needs its own env (~64 MB for the MyoHand), and 20 (the
# 2022 winner's evaluation) already make each step's forward pass a batch.
TOGETHER = 20


class StageEvaluator:
    """Runs evaluation episodes; keeps the envs (one per episode) of the last evaluated task."""

    def __init__(self, curriculum: Curriculum) -> None:
        self.curriculum = curriculum
        self.task = curriculum.task
        # The envs of the last evaluated task (~64 MB each for the MyoHand: one per episode, so
        # a set per stage kept for the whole run would grow by ~1.3 GB per stage).
        self._envs: list = []
        self._envs_key: tuple[str, float] | None = None
        self._pool: ThreadPoolExecutor | None = None  # steps them
        self._last_step: int | None = None  # the env step of the last evaluation

    def _choice(self, env: str, stage: Stage, start_noise: float) -> EnvChoice:
        from myo_sds.envs.task_specs import TASK_SPECS

        if env == "stage":
            return EnvChoice(self.task, f"stage:{stage.name}", stage.distribution, False, start_noise)
        if env.startswith("stage:"):
            other = self.curriculum.stages[self.curriculum.stage_index(env[len("stage:"):])]
            return EnvChoice(self.task, env, other.distribution, False, start_noise)
        return EnvChoice(self.task, env, TASK_SPECS[self.task].knobs.parse(env), False, start_noise)

    def choice(self, stage: Stage) -> EnvChoice:
        return self._choice(stage.evaluate.env, stage, stage.evaluate.start_noise)

    def run(self, model, venv, choice: EnvChoice, episodes: int, first_seed: int = 0) -> EvaluationResult:
        """``episodes`` deterministic episodes (seeds ``first_seed`` ..) of ``model``, its observations
        normalized by ``venv``'s current statistics, run together (``run_episodes_together``)."""
        key = (choice.name, choice.start_noise)
        if self._envs_key != key:  # a stage's own task, or a probe's: only one set is kept
            self._close_envs()
            self._envs_key = key
        envs = self._envs
        envs.extend(make_env(choice) for _ in range(min(episodes, TOGETHER) - len(envs)))
        if self._pool is None and available_cpus() > 1:
            self._pool = ThreadPoolExecutor(available_cpus(), thread_name_prefix="evaluation")
        policy = LoadedPolicy(model, venv if hasattr(venv, "normalize_obs") else None)
        # One torch thread: the envs' threads have the CPUs (2.5 s against 3.4 s with two for 20
        # Baoding episodes), and the arithmetic is the same whatever threads the update last used.
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            results = []
            for first in range(first_seed, first_seed + episodes, TOGETHER):
                seeds = range(first, min(first + TOGETHER, first_seed + episodes))
                results += run_episodes_together(policy, envs[:len(seeds)], choice, seeds, self._pool)
        finally:
            torch.set_num_threads(threads)
        return EvaluationResult.of(choice.name, results, first_seed)

    @staticmethod
    def first_seed(stage: Stage, step: int) -> int:
        """The first seed of the stage's evaluation at env step ``step`` (``seeds: fresh``: the step)."""
        return step if stage.evaluate.seeds == "fresh" else 0

    def evaluate(self, model, venv, stage: Stage, state: CurriculumState, folder, kind: str = "periodic") -> str:
        """The stage's evaluation at the current step: logged, recorded in ``state`` and the run's
        ``evaluations.csv``, a new best policy kept in the run folder. Returns the line to print."""
        result = self.run(model, venv, self.choice(stage), stage.evaluate.episodes,
                          self.first_seed(stage, state.num_timesteps))
        self._last_step = state.num_timesteps
        best = state.record_evaluation(result.score, result.reward, stage.evaluate.select)
        if best:
            folder.save_best(model, venv, state.num_timesteps)
        folder.append_evaluations([self._record(result, state, stage, kind, best)])
        logger = model.logger
        logger.record("eval/score", result.score)
        logger.record("eval/best_score", state.best_evaluated)
        logger.record("eval/drop_rate", result.drop_rate)
        logger.record("eval/median_solved_steps", result.median_solved_steps)
        if result.reward is not None:
            logger.record("eval/reward", result.reward)
        reward = "" if result.reward is None else f", return {result.reward:.0f}"
        best_reward = "" if state.best_evaluated_reward is None else f", return {state.best_evaluated_reward:.0f}"
        return (f"evaluation at step {state.num_timesteps}: {result.score:.3f}{reward} (best {state.best_evaluated:.3f}"
                f"{best_reward} at step {state.best_evaluated_step})")

    def probe(self, model, venv, probe: StageEndProbe, stage: Stage, state: CurriculumState, folder) -> EvaluationResult:
        """The curriculum's stage-end probe of the policy in ``model`` (the one handed on)."""
        result = self.run(model, venv, self._choice(probe.env, stage, probe.start_noise), probe.episodes)
        folder.append_evaluations([self._record(result, state, stage, "probe", False)])
        model.logger.record("probe/score", result.score)
        model.logger.record("probe/median_solved_steps", result.median_solved_steps)
        model.logger.record("probe/drop_rate", result.drop_rate)
        return result

    @staticmethod
    def _record(result: EvaluationResult, state: CurriculumState, stage: Stage, kind: str,
                best: bool) -> EvaluationRecord:
        return EvaluationRecord(state.num_timesteps, state.stage_index, stage.name, kind, result.env, result.episodes,
                                result.score, result.reward, result.drop_rate, result.median_solved_steps, best,
                                result.first_seed, result.by_direction)

    def hand_off(self, model, venv, stage: Stage, state: CurriculumState, folder) -> tuple[int | None, str]:
        """At the stage's end, with ``hand_off: best``: evaluate the last policy too (unless it just
        was), then load the best one into ``model`` and ``venv`` (weights, optimizer,
        normalization statistics). Returns the step of the policy handed on (None: the last)
        and a line to print."""
        from myo_sds.curricula.schema import stage_label
        from myo_sds.published import load_statistics

        evaluation = stage.evaluate
        if evaluation is None or evaluation.hand_off != "best":
            return None, ""
        line = ""
        if self._last_step != state.num_timesteps:
            line = (f"{stage_label(state.stage_index, stage.name)} "
                    f"{self.evaluate(model, venv, stage, state, folder, kind='final')}\n")
        best = state.best_evaluated_step
        if best is None or best == state.num_timesteps:
            return None, line.rstrip()
        model_file, statistics_file = folder.best_files(best)
        if not (model_file.is_file() and statistics_file.is_file()):
            return None, line + f"the best policy of step {best} is missing ({model_file}); the stage hands on its last"
        model.set_parameters(str(model_file), exact_match=True, device=model.device)
        statistics = load_statistics(statistics_file)
        venv.obs_rms, venv.ret_rms = statistics.obs_rms, statistics.ret_rms
        return best, line + f"the next stage starts from the best evaluated policy: step {best}, score " \
                            f"{state.best_evaluated:.3f}"

    def _close_envs(self) -> None:
        for env in self._envs:
            env.close()
        self._envs, self._envs_key = [], None

    def close(self) -> None:
        self._close_envs()
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None
