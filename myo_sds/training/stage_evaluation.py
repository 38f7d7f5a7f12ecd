"""A stage's periodic evaluation (``evaluate`` in the curriculum): deterministic episodes of the
policy being trained, on the stage's task or a preset, scored as ``evaluate.py`` scores them.

It reads the model and the current normalization statistics and draws nothing from the
training's random streams (its env is its own, reset with seeds 0 .. episodes-1), so a run
with evaluations trains exactly as one without them.
"""

from __future__ import annotations

from myo_sds.curricula.schema import Stage
from myo_sds.envs.metrics import official_score
from myo_sds.evaluation.checkpoints import EnvChoice, LoadedPolicy
from myo_sds.evaluation.episodes import make_env, run_episode


class StageEvaluator:
    """Runs a stage's evaluation episodes; keeps one env per evaluated task distribution."""

    def __init__(self, task: str) -> None:
        self.task = task
        self._envs: dict[tuple[str, float], object] = {}

    def choice(self, stage: Stage) -> EnvChoice:
        from myo_sds.envs.task_specs import TASK_SPECS

        evaluation = stage.evaluate
        if evaluation.env == "stage":
            return EnvChoice(self.task, f"stage:{stage.name}", stage.distribution, False, evaluation.start_noise)
        knobs = TASK_SPECS[self.task].knobs.parse(evaluation.env)
        return EnvChoice(self.task, evaluation.env, knobs, False, evaluation.start_noise)

    def score(self, model, venv, stage: Stage) -> float:
        """The mean official score of ``stage.evaluate.episodes`` deterministic episodes of
        ``model``, its observations normalized by ``venv``'s current statistics."""
        choice = self.choice(stage)
        key = (choice.name, choice.start_noise)
        env = self._envs.get(key)
        if env is None:
            env = self._envs[key] = make_env(choice)
        policy = LoadedPolicy(model, venv if hasattr(venv, "normalize_obs") else None)
        return official_score([run_episode(policy, env, choice, seed) for seed in range(stage.evaluate.episodes)])

    def close(self) -> None:
        for env in self._envs.values():
            env.close()
        self._envs.clear()
