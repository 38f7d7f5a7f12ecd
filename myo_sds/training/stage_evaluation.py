"""A stage's periodic evaluation (``evaluate`` in the curriculum): deterministic episodes of the
policy being trained, on the stage's task or a preset, scored as ``evaluate.py`` scores them.

It reads the model and the current normalization statistics and draws nothing from the
training's random streams (its env is its own, reset with seeds 0 .. episodes-1), so a run
with evaluations trains exactly as one without them.
"""

from __future__ import annotations

from myo_sds.curricula.schema import Stage
from myo_sds.curricula.state import CurriculumState
from myo_sds.envs.metrics import official_score
from myo_sds.evaluation.checkpoints import EnvChoice, LoadedPolicy
from myo_sds.evaluation.episodes import make_env, run_episode


class StageEvaluator:
    """Runs a stage's evaluation episodes; keeps one env per evaluated task distribution."""

    def __init__(self, task: str) -> None:
        self.task = task
        self._envs: dict[tuple[str, float], object] = {}
        self._last_step: int | None = None  # the env step of the last evaluation

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

    def evaluate(self, model, venv, stage: Stage, state: CurriculumState, folder) -> str:
        """The stage's evaluation at the current step: logged, recorded in ``state``, a new best
        policy kept in the run folder. Returns the line to print."""
        score = self.score(model, venv, stage)
        self._last_step = state.num_timesteps
        if state.record_evaluation(score):
            folder.save_best(model, venv, state.num_timesteps)
        model.logger.record("eval/score", score)
        model.logger.record("eval/best_score", state.best_evaluated)
        return (f"evaluation at step {state.num_timesteps}: {score:.3f} (best {state.best_evaluated:.3f} at step "
                f"{state.best_evaluated_step})")

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
            line = f"{stage_label(state.stage_index, stage.name)} {self.evaluate(model, venv, stage, state, folder)}\n"
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

    def close(self) -> None:
        for env in self._envs.values():
            env.close()
        self._envs.clear()
