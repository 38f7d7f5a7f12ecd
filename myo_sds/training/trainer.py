"""The curriculum trainer: rollouts, updates and stage changes, into a run folder.

Each iteration applies the PPO settings in force (``curricula.schedule``), collects one rollout
(``training.rollout``), runs the PPO update, then feeds the stage's finished training episodes
to the advancement rule (``curricula.advancement``). A stage change reaches every env in place
(same model, same normalization statistics). Checkpoints and logs go to the run folder
(``run_folder``).
"""

from __future__ import annotations

import math
import signal
import time
from pathlib import Path

import yaml

from myo_sds.cli import train_command
from myo_sds.curricula.advancement import (
    Decision,
    decide,
    episode_metric,
    measured_value,
)
from myo_sds.curricula.run_config import RunConfig, load_run_config
from myo_sds.curricula.schedule import ppo_settings_at
from myo_sds.curricula.schema import ConfigError, Stage, stage_label
from myo_sds.curricula.state import CurriculumState, RunStatus
from myo_sds.envs.task_specs import TASK_SPECS
from myo_sds.run_folder import EpisodeRecord, RunFolder
from myo_sds.sb3_internals import set_last_observation, start_training, tensorboard_output, updates_done
from myo_sds.threads import UpdateThreads, available_cpus
from myo_sds.training.callbacks import EpisodeCollector, RolloutTiming, UpdateInterrupted, log_rollout
from myo_sds.training.divergence import UpdateDiverged, finite, restore_training_state, training_state
from myo_sds.training.factory import (
    apply_ppo_settings,
    build_model,
    build_training_venv,
    initialize_from,
    trained_policy_files,
)
from myo_sds.training.progress import StageProgressBar
from myo_sds.training.rollout import LocalRollouts, RolloutCollector, WorkerLost
from myo_sds.training.stage_evaluation import StageEvaluator

RESUMABLE = (RunStatus.RUNNING, RunStatus.INTERRUPTED, RunStatus.TIME_LIMIT)


def _rollouts(config: RunConfig, model, stage: Stage, settings) -> RolloutCollector:
    """The config's rollout backend for ``model`` (whose env is the envs, or on Ray the holder
    of the merged normalization statistics)."""
    venv = model.get_env()
    if config.rollout.backend == "local":
        return LocalRollouts(venv)
    import torch

    from myo_sds.training.ray_rollouts import RayRollouts

    # The learner never resets the stand-in envs (that would feed zeros to the statistics).
    set_last_observation(model, venv.venv.reset())
    return RayRollouts(config, venv, stage.distribution, settings, torch.get_rng_state())


class CurriculumTrainer:
    """Train a RecurrentPPO policy through a curriculum into a run folder.

    Use :meth:`start` for a new run and :meth:`resume` to continue one; then :meth:`run`.
    """

    def __init__(self, config: RunConfig, folder: RunFolder, state: CurriculumState, model,
                 rollouts: RolloutCollector, progress: bool = True) -> None:
        self.config, self.folder, self.state = config, folder, state
        self.model, self.rollouts = model, rollouts
        self.progress_bar = StageProgressBar(progress, len(config.curriculum.stages))
        self.next_checkpoint = (state.num_timesteps // config.checkpoint_every + 1) * config.checkpoint_every
        self.timings: list[RolloutTiming] = []
        self.iteration_started_at = time.perf_counter()
        self.update_threads = UpdateThreads(available_cpus(), fixed=config.num_threads or None)
        self.episode_callback = EpisodeCollector(config.n_envs, state.stage_index, TASK_SPECS[config.curriculum.task].reward_terms,
                                          run_wall_s=lambda: self.state.wall_s + time.perf_counter() - self.iteration_started_at,
                                          update_threads=self.update_threads)
        self.minibatch_hook = model.policy.optimizer.register_step_pre_hook(self.episode_callback.before_optimizer_step)
        self.stage_evaluator = StageEvaluator(config.curriculum)
        self.apply_ppo_settings()

    @property
    def run_dir(self) -> Path:
        return self.folder.path

    @property
    def venv(self):
        return self.rollouts.venv

    @property
    def stage(self) -> Stage:
        return self.config.curriculum.stages[self.state.stage_index]

    # construction ------------------------------------------------------------------------

    @classmethod
    def start(cls, config_path: str | Path, overrides: tuple[str, ...] = (), run_dir: Path | None = None,
              overwrite: bool = False, progress: bool = True, init_from: Path | None = None) -> CurriculumTrainer:
        """Validate the config, create the run folder and a new model at stage 1; with
        ``init_from``, the model starts from that trained policy (fine-tuning)."""
        from stable_baselines3.common.logger import configure
        from stable_baselines3.common.utils import set_random_seed

        config_path = Path(config_path)
        config = load_run_config(config_path, overrides)
        init_from = init_from if init_from is not None else config.init_from
        trained = trained_policy_files(init_from) if init_from is not None else None
        if run_dir is None:
            folder = RunFolder.create(config.output_dir, config_path.stem, config.seed)
        else:
            folder = RunFolder.claim(Path(run_dir), overwrite)
        venv = None
        try:
            # The run folder is self-contained: its config points at its own copy of the curriculum.
            resolved = {**config.source, "curriculum": folder.curriculum_file.name, "seed": config.seed}
            if init_from is not None:  # where the run's first policy came from (a resume never reads it)
                resolved["init_from"] = str(Path(init_from).resolve())
            folder.write_provenance(yaml.safe_dump(resolved, sort_keys=False), config.curriculum.file_text())
            set_random_seed(config.seed)
            state = CurriculumState()
            stage, settings = config.curriculum.stages[0], ppo_settings_at(config, 0, state.stage_starts(), 0)
            venv = build_training_venv(config, stage)
            model = build_model(config, venv, settings)
            if trained is not None:
                initialize_from(model, venv, *trained)
            model.set_logger(configure(str(folder.tensorboard_dir), ["tensorboard"]))
            return cls(config, folder, state, model, _rollouts(config, model, stage, settings), progress)
        except BaseException:  # an error or Ctrl-C before the first step: no half-made run folder stays
            if venv is not None:
                venv.close()
            folder.remove()
            raise

    @classmethod
    def resume(cls, run_dir: str | Path, progress: bool = True,
               total_steps: int | None = None) -> CurriculumTrainer:
        """Continue a run from its latest complete checkpoint: same stage, counters, optimizer,
        normalization state and random streams, same TensorBoard folder, under its own (possibly
        edited) curriculum. ``total_steps`` raises the run's step budget (in its config)."""
        from stable_baselines3.common.logger import Logger
        from stable_baselines3.common.vec_env import VecNormalize

        from myo_sds.policy import load_model

        folder = RunFolder(run_dir)
        config = load_run_config(folder.config_file)
        checkpoint = folder.latest_checkpoint()
        if checkpoint is None:
            raise ConfigError(f"{folder.path}: no complete checkpoint to resume from")
        state = checkpoint.read_state()
        resumable = RESUMABLE + ((RunStatus.BUDGET_REACHED,) if total_steps else ())
        if state.status not in resumable:
            hint = ("; add --total-steps N to train on to N steps" if state.status is RunStatus.BUDGET_REACHED
                    else "; nothing to resume")
            raise ConfigError(f"{folder.path}: the run already ended ({state.status.value}){hint}")
        if total_steps is not None:
            if total_steps <= state.num_timesteps:
                raise ConfigError(f"{folder.config_file}: total_steps {total_steps} must exceed the "
                                  f"{state.num_timesteps} steps already trained")
            config = load_run_config(folder.config_file, (f"total_steps={total_steps}",))
            folder.config_file.write_text(yaml.safe_dump(dict(config.source), sort_keys=False))
        if mismatch := state.curriculum_mismatch([s.name for s in config.curriculum.stages]):
            raise ConfigError(f"{folder.curriculum_file}: {mismatch}")
        state.status = RunStatus.RUNNING
        stage = config.curriculum.stages[state.stage_index]
        venv = VecNormalize.load(str(checkpoint.vecnormalize), build_training_venv(config, stage).venv)
        venv.training = True
        model = load_model(str(checkpoint.model), env=venv, device=config.device)
        settings = ppo_settings_at(config, state.stage_index, state.stage_starts(), state.num_timesteps)
        rollouts = _rollouts(config, model, stage, settings)
        # Loading reseeds torch, numpy and the envs' next reset with the run's seed: continue
        # the streams of the checkpoint instead, so the resumed run draws new episodes.
        rollouts.restore_random_state(checkpoint.read_random_state(), fallback_seed=config.seed + state.num_timesteps)
        # Events a killed run logged after this checkpoint are hidden from TensorBoard.
        tb = str(folder.tensorboard_dir)
        model.set_logger(Logger(tb, [tensorboard_output(tb, purge_step=state.num_timesteps + 1)]))
        folder.truncate_episodes(state.num_timesteps)
        folder.record_session(state.num_timesteps)
        return cls(config, folder, state, model, rollouts, progress)

    # the loop ----------------------------------------------------------------------------

    def apply_ppo_settings(self) -> None:
        """Give the model (and the rollouts) the PPO settings in force at the current stage and step."""
        settings = ppo_settings_at(self.config, self.state.stage_index, self.state.stage_starts(),
                                   int(self.model.num_timesteps))
        apply_ppo_settings(self.model, settings)
        self.rollouts.set_ppo_settings(settings)

    def run(self, max_wall_s: float | None = None) -> CurriculumState:
        """Train until the curriculum completes or stops, the step budget is spent, or a
        SIGINT/SIGTERM arrives or this call has trained for ``max_wall_s`` seconds (then a
        checkpoint is written and the run can be resumed)."""
        config, model, state, episode_callback = self.config, self.model, self.state, self.episode_callback
        episode_callback.progress_bar = self.progress_bar
        previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}

        def request_stop(signum, frame):
            episode_callback.stop_requested = signal.Signals(signum).name
            signal.signal(signal.SIGINT, signal.default_int_handler)  # a second Ctrl-C aborts

        for sig in previous:
            signal.signal(sig, request_stop)
        start_wall = state.wall_s
        # SB3's setup for training: the callback, and the first reset (or the LSTM states of a
        # loaded model); the trainer then drives rollouts and updates itself.
        callback = start_training(model, config.total_steps, episode_callback)
        try:
            self._start_stage_display()
            while state.status is RunStatus.RUNNING:
                if model.num_timesteps >= config.total_steps:
                    state.status = RunStatus.BUDGET_REACHED
                    break
                if max_wall_s is not None and state.wall_s - start_wall >= max_wall_s:
                    state.status = RunStatus.TIME_LIMIT
                    self.progress_bar.write(f"time limit of {max_wall_s:.0f} s reached; continue with "
                                            f"`{train_command()} --resume {self.run_dir}`")
                    break
                self.apply_ppo_settings()  # a decaying rate or a warm-up's end acts between rollouts
                try:
                    self._iterate()
                except UpdateDiverged as error:
                    state.status = RunStatus.DIVERGED
                    self.progress_bar.write(f"error: {error}")
                    break
                except WorkerLost as error:
                    state.status = RunStatus.INTERRUPTED
                    self.progress_bar.write(f"{error}; saving a checkpoint; continue with "
                                            f"`{train_command()} --resume {self.run_dir}`")
                    break
                self._after_rollout()
                if episode_callback.stop_requested:
                    state.status = RunStatus.INTERRUPTED
                    self.progress_bar.write(f"{episode_callback.stop_requested}: saving a checkpoint; continue with "
                                            f"`{train_command()} --resume {self.run_dir}`")
                    break
                rule = self.stage.advance
                self.progress_bar.describe(measured_value(rule, state) if rule else state.measured, self._rule_text(),
                                           model.num_timesteps)
                if model.num_timesteps >= self.next_checkpoint and state.status is RunStatus.RUNNING:
                    self.save_checkpoint()
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
            self.progress_bar.close()
        callback.on_training_end()
        self.save_checkpoint()
        if state.status not in (RunStatus.INTERRUPTED, RunStatus.TIME_LIMIT):
            self.folder.save_final(model, self.venv)
        return state

    def _iterate(self) -> None:
        """One rollout and, unless a stop cut the rollout short, one PPO update."""
        model, episode_callback = self.model, self.episode_callback
        steps_before, self.iteration_started_at = model.num_timesteps, time.perf_counter()
        env_before = self.rollouts.env_seconds
        complete = self.rollouts.collect(model, episode_callback)
        updated_at = time.perf_counter()
        if complete:
            epochs_before = updates_done(model)
            before = training_state(model)
            try:
                model.train()
            except UpdateInterrupted:
                pass  # stopped between minibatches: weights and optimizer are consistent
            except RuntimeError:  # e.g. Lattice's Cholesky factor of a covariance made of NaNs
                if finite(model):
                    raise
            if not finite(model):
                restore_training_state(model, before)
                raise UpdateDiverged(
                    f"the PPO update at env step {model.num_timesteps:,} made the policy's parameters non-finite "
                    "(a probability ratio overflowed); the run stops with the policy from before it. "
                    + ("With exploration: lattice, give the action noise a floor (policy.lattice_std_reg: 0.1) "
                       "or lower ppo.learning_rate" if self.config.policy.exploration == "lattice"
                       else "Lower ppo.learning_rate or clip_range"))
            # SB3 counts an update's epochs, the one target_kl cut short included.
            model.logger.record("train/epochs_run", updates_done(model) - epochs_before)
        finished_at = time.perf_counter()
        self.state.wall_s += finished_at - self.iteration_started_at
        self.timings.append(RolloutTiming(model.num_timesteps - steps_before, finished_at - self.iteration_started_at,
                                          self.rollouts.env_seconds - env_before,
                                          finished_at - updated_at if complete else 0.0))

    def _rule_text(self) -> str:
        rule = self.stage.advance
        if rule is None:
            return "no advancement rule"
        if rule.window_metric != rule.metric:
            return f"{rule.metric} {{value}} of {rule.threshold:g} (latest evaluation)"
        return f"{rule.metric} {{value}} of {rule.threshold} over {len(self.state.recent)}/{rule.window} episodes"

    def _start_stage_display(self) -> None:
        state = self.state
        self.progress_bar.start_stage(state.stage_index, self.stage, state.stage_steps, int(self.model.num_timesteps),
                                      self.config.total_steps)

    def _after_rollout(self) -> None:
        model, state, episode_callback = self.model, self.state, self.episode_callback
        results = episode_callback.pop_results()
        rule = self.stage.advance
        metric = rule.window_metric if rule else "score"
        window = rule.window if rule else 100
        state.record(self.stage.name, int(model.num_timesteps), (episode_metric(metric, r) for _, _, r in results),
                     window, rule.tracked_gain if rule else None)
        self.folder.append_episodes(
            EpisodeRecord(step, wall_s, state.stage_index, self.stage.name, r.score, r.solved_steps, r.length,
                          r.dropped, r.effort, r.direction, r.start_phase, r.reward, r.start, r.goals_reached)
            for step, wall_s, r in results)
        logger = model.logger
        for key, value in episode_callback.pop_term_means().items():
            logger.record(f"reward/{key}", value)
        log_rollout(logger, [r for _, _, r in results], self.timings[-1] if self.timings else None, model.policy)
        logger.record("time/update_threads", self.update_threads.current)
        if self.config.rollout.backend != "local":
            logger.record("rollout/worker_restarts", self.rollouts.restarts)
        logger.record("curriculum/stage_index", state.stage_index)
        logger.record("curriculum/stage_steps", state.stage_steps)
        if not math.isnan(state.measured):
            logger.record("curriculum/measured", state.measured)
        if rule is not None and not math.isnan(measured_value(rule, state)) and rule.window_metric != rule.metric:
            logger.record("curriculum/evaluated", measured_value(rule, state))
        evaluation = self.stage.evaluate
        if evaluation is not None and state.stage_steps >= (state.evaluations + 1) * evaluation.every:
            self._evaluate_stage()
        decision = decide(rule, state)
        if decision is not Decision.STAY:
            self._transition(decision)
        logger.dump(model.num_timesteps)

    def _evaluate_stage(self) -> None:
        line = self.stage_evaluator.evaluate(self.model, self.venv, self.stage, self.state, self.folder)
        self.progress_bar.write(f"{stage_label(self.state.stage_index, self.stage.name)} {line}")

    def _hand_off(self) -> int | None:
        handed, line = self.stage_evaluator.hand_off(self.model, self.venv, self.stage, self.state, self.folder)
        if line:
            self.progress_bar.write(line)
        return handed

    def _probe(self) -> dict | None:
        """The curriculum's stage-end probe of the policy the stage hands on (None: no probe)."""
        probe = self.config.curriculum.probe
        if probe is None:
            return None
        result = self.stage_evaluator.probe(self.model, self.venv, probe, self.stage, self.state, self.folder)
        self.progress_bar.write(f"{stage_label(self.state.stage_index, self.stage.name)} probe on {result.env}: "
                                f"{result.describe()}")
        return result.as_dict()

    def _transition(self, decision: Decision) -> None:
        state, model, config = self.state, self.model, self.config
        stage = self.stage
        handed_off = self._hand_off()  # a stopped run's final model is its best too
        self.folder.save_stage_policy(state.stage_index, stage.name, model, self.venv)
        probe = self._probe()
        transition = state.end_stage(stage.name, decision.value, state.wall_s, handed_off, probe)
        rule = stage.advance
        measured = transition.measured if rule is None or rule.window_metric == rule.metric else measured_value(rule, state)
        verdict = {Decision.PASSED: "passed", Decision.TIMED_OUT: "ended unpassed (max_steps)",
                   Decision.PLATEAUED: "ended unpassed (plateau_steps without a gain of plateau_gain)",
                   Decision.STOP: "ended unpassed"}[decision]
        self.progress_bar.write(f"{stage_label(state.stage_index, stage.name)} {verdict} at step {model.num_timesteps}: "
                                + self._rule_text().format(value=f"{measured:.3f}"))
        model.logger.record("curriculum/transition", state.stage_index + 1)
        if decision is Decision.STOP:
            state.status = RunStatus.STOPPED
            return
        if state.stage_index + 1 >= len(config.curriculum.stages):
            state.status = RunStatus.COMPLETED
            self.progress_bar.write("curriculum completed")
            return
        state.begin_next_stage()
        self.episode_callback.stage_index = state.stage_index
        self.rollouts.set_stage(self.stage.distribution)
        self.apply_ppo_settings()
        self._start_stage_display()

    def close(self) -> None:
        """Release the envs (and a Ray backend's workers)."""
        self.rollouts.close()
        self.stage_evaluator.close()

    def save_checkpoint(self) -> Path:
        """Model, statistics, curriculum state and random streams of this step (``run_folder``)."""
        self.state.record(self.stage.name, int(self.model.num_timesteps))
        files = self.folder.save_checkpoint(self.model, self.venv, self.state, self.rollouts.random_state(),
                                            keep=self.config.keep_checkpoints)
        self.next_checkpoint = (files.steps // self.config.checkpoint_every + 1) * self.config.checkpoint_every
        return files.model
