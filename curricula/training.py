"""Curriculum training with sb3-contrib RecurrentPPO: stages, checkpoints, resume, signals.

The loop runs ``model.learn`` one rollout at a time. Between rollouts it feeds the finished
training episodes of the current stage to :func:`curricula.advancement.decide`, switches
stages in place (``env_method("configure", ...)`` on every worker; same model, same
normalization statistics), applies the stage's PPO overrides, and writes checkpoints.
"""

from __future__ import annotations

import csv
import json
import math
import multiprocessing
import os
import pickle
import platform
import random
import signal
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from stable_baselines3.common.callbacks import BaseCallback

from curricula.advancement import Decision, StageProgress, decide, episode_metric
from curricula.policy import SequenceLstmPolicy
from curricula.schema import (
    ConfigError,
    Curriculum,
    LearningRateDecay,
    PpoConfig,
    RunConfig,
    Stage,
    load_run_config,
)
from curricula.threads import UpdateThreads, available_cpus
from envs.task_specs import TASK_SPECS
from envs.metrics import EpisodeResult

STATE_FILE = "curriculum_state.json"
CHECKPOINT_DIR = "checkpoints"
LATEST_FILE = "latest.json"
EPISODES_FILE = "episodes.csv"
EPISODE_COLUMNS = ("step", "wall_s", "stage_index", "stage", "score", "solved_steps", "length", "dropped",
                   "effort", "direction", "start_phase")


# -- envs --------------------------------------------------------------------------------

def stage_knobs(stage: Stage) -> dict[str, Any]:
    """The complete knobs a stage sends to every env (the preset is always explicit)."""
    return {"preset": "p1", **stage.env}


def _make_env(task: str, knobs: dict[str, Any], seed: int) -> Callable[[], Any]:
    def build():
        if multiprocessing.current_process().name != "MainProcess":
            # Ctrl-C goes to the whole process group: let the main process save and stop
            # the workers, instead of the workers dying mid-step.
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        env = TASK_SPECS[task].env_class()(**knobs)
        env.reset(seed=seed)
        return env
    return build


def build_vec_env(config: RunConfig, stage: Stage):
    """The training VecEnv (``n_envs`` workers, seeded ``seed + rank``) under VecNormalize."""
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize

    from curricula.vec_env import ThreadVecEnv

    knobs = stage_knobs(stage)
    factories = [_make_env(config.curriculum.task, knobs, config.seed + rank) for rank in range(config.n_envs)]
    if config.vec_env == "subproc":
        venv = SubprocVecEnv(factories)
    elif config.vec_env == "thread":
        venv = ThreadVecEnv(factories, config.env_threads)
    else:
        venv = DummyVecEnv(factories)
    venv.seed(config.seed)
    norm = config.normalize
    return VecNormalize(venv, norm_obs=norm.observations, norm_reward=norm.rewards,
                        clip_obs=norm.clip_obs, clip_reward=norm.clip_reward, gamma=config.ppo.gamma)


# -- model -------------------------------------------------------------------------------

def build_model(config: RunConfig, venv):
    import torch
    from sb3_contrib import RecurrentPPO

    activations = {"relu": torch.nn.ReLU, "tanh": torch.nn.Tanh, "elu": torch.nn.ELU,
                   "leaky_relu": torch.nn.LeakyReLU}
    policy = config.policy
    ppo = config.ppo
    policy_kwargs = {
        "lstm_hidden_size": policy.lstm_hidden_size,
        "enable_critic_lstm": policy.enable_critic_lstm,
        "shared_lstm": False,
        "net_arch": {"pi": list(policy.net_arch), "vf": list(policy.net_arch)},
        "activation_fn": activations[policy.activation],
        "log_std_init": policy.log_std_init,
        "ortho_init": policy.ortho_init,
    }
    if policy.fast_lstm_update:
        policy_kwargs["action_mean_bound"] = policy.action_mean_bound
        policy_kwargs["action_head_lr_scale"] = policy.action_head_lr_scale
    return RecurrentPPO(
        SequenceLstmPolicy if policy.fast_lstm_update else "MlpLstmPolicy", venv,
        learning_rate=learning_rate_at(config, CurriculumState(), step=0), n_steps=ppo.n_steps,
        batch_size=ppo.batch_size, n_epochs=ppo.n_epochs, gamma=ppo.gamma,
        gae_lambda=ppo.gae_lambda, clip_range=ppo.clip_range, ent_coef=ppo.ent_coef,
        vf_coef=ppo.vf_coef, max_grad_norm=ppo.max_grad_norm, policy_kwargs=policy_kwargs,
        seed=config.seed, device=config.device, verbose=0)


def effective_ppo(base: PpoConfig, curriculum: Curriculum, stage_index: int, step: int) -> dict[str, Any]:
    """PPO settings in force at a stage and env step: the run's, then each stage's overrides
    in order up to this one (an override stays until a later stage changes it), then the
    run's warm-up while it lasts. The learning rate, which may decay with env steps, comes
    from :func:`learning_rate_at`."""
    settings = {k: getattr(base, k) for k in ("n_steps", "batch_size", "n_epochs", "clip_range", "ent_coef")}
    for stage in curriculum.stages[: stage_index + 1]:
        settings.update({k: v for k, v in stage.ppo.as_dict().items() if k in settings})
    if base.warmup.active(step):
        settings.update({k: v for k in ("n_steps", "batch_size", "n_epochs")
                         if (v := getattr(base.warmup, k)) is not None})
    return settings


def learning_rate_at(config: RunConfig, state: "CurriculumState", step: int) -> float:
    """The learning rate in force at env step ``step`` of the run's current stage: set by the
    run config or by the latest stage up to the current one that sets it (an override stays
    until a later stage changes it); a decay runs from that stage's first step."""
    stage_starts = [0] + [entry["at_step"] for entry in state.history[: state.stage_index]]
    rate, set_at_step = config.ppo.learning_rate, 0
    for index, stage in enumerate(config.curriculum.stages[: state.stage_index + 1]):
        if stage.ppo.learning_rate is not None:
            rate, set_at_step = stage.ppo.learning_rate, stage_starts[index]
    if isinstance(rate, LearningRateDecay):
        return rate.at(step - set_at_step)
    return rate


def apply_ppo_settings(model, settings: dict[str, Any], learning_rate: float) -> None:
    """Set learning rate, clip range, entropy coefficient, batch size, epochs and rollout length."""
    from stable_baselines3.common.utils import ConstantSchedule

    # Our loop runs ``learn`` one rollout at a time, so SB3's progress-based schedules
    # would restart every rollout: the rate is set from the env step count instead.
    model.learning_rate = learning_rate
    model.lr_schedule = ConstantSchedule(learning_rate)
    model.clip_range = ConstantSchedule(settings["clip_range"])
    model.ent_coef = settings["ent_coef"]
    model.batch_size = settings["batch_size"]
    model.n_epochs = settings["n_epochs"]
    if settings["n_steps"] != model.n_steps:
        model.n_steps = settings["n_steps"]
        buffer = model.rollout_buffer
        lstm = model.policy.lstm_actor
        model.rollout_buffer = type(buffer)(
            model.n_steps, model.observation_space, model.action_space,
            (model.n_steps, lstm.num_layers, model.n_envs, lstm.hidden_size), model.device,
            gamma=model.gamma, gae_lambda=model.gae_lambda, n_envs=model.n_envs)


# -- timing ------------------------------------------------------------------------------

class WallClock:
    """Wall time spent inside wrapped callables (env stepping, PPO updates)."""

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


@dataclass
class RolloutTiming:
    steps: int
    wall_s: float
    env_s: float
    update_s: float


# -- curriculum state ---------------------------------------------------------------------

@dataclass
class CurriculumState:
    """Where the run is in its curriculum; saved with every checkpoint."""

    stage_index: int = 0
    stage_start_step: int = 0
    stage_episodes: int = 0
    recent: list[float] = field(default_factory=list)  # the advancement window's values
    episodes_per_stage: dict[str, int] = field(default_factory=dict)
    steps_per_stage: dict[str, int] = field(default_factory=dict)
    history: list[dict[str, Any]] = field(default_factory=list)  # one entry per transition
    status: str = "running"  # running | completed | stopped | budget_reached | interrupted | time_limit
    num_timesteps: int = 0
    wall_s: float = 0.0  # training wall time so far, over all sessions of the run

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=2)

    @classmethod
    def from_json(cls, text: str) -> "CurriculumState":
        return cls(**json.loads(text))


def _atomic_write_text(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


# -- callback ----------------------------------------------------------------------------

class UpdateInterrupted(Exception):
    """Raised between two minibatches of a PPO update when a stop was requested."""


class EpisodeCollector(BaseCallback):
    """SB3 callback: gathers finished episodes of the current stage (with the env step and
    the run's training wall time at which each ended), logs reward terms, drives the progress
    bar, sets torch's threads for each phase, and stops ``learn`` when a stop was requested."""

    def __init__(self, n_envs: int, stage_index: int, terms: tuple[str, ...], run_wall_s: Callable[[], float],
                 update_threads: UpdateThreads) -> None:
        super().__init__(verbose=0)
        self.run_wall_s = run_wall_s
        self.update_threads = update_threads
        self.rollout_ended_at: float | None = None  # None while a rollout is being collected
        self.terms = tuple(t for t in terms if t != "done")
        self.stage_index = stage_index
        self.episode_stage = [stage_index] * n_envs  # stage each env's current episode began in
        self.results: list[tuple[int, float, EpisodeResult]] = []
        self.term_sums: dict[str, float] = {}
        self.term_count = 0
        self.stop_requested: str | None = None
        self.progress_bar: Any = None

    def _on_step(self) -> bool:
        infos, dones = self.locals["infos"], self.locals["dones"]
        wall_s = self.run_wall_s() if dones.any() else 0.0
        for rank, (info, done) in enumerate(zip(infos, dones)):
            for key in self.terms:
                self.term_sums[key] = self.term_sums.get(key, 0.0) + info.get(key, 0.0)
            if done:
                result = info.get("episode_result")
                if result is not None and self.episode_stage[rank] == self.stage_index:
                    self.results.append((self.num_timesteps, wall_s, result))
                self.episode_stage[rank] = self.stage_index
        self.term_count += len(infos)
        if self.progress_bar is not None:
            self.progress_bar.update(len(infos))
        return self.stop_requested is None

    def _on_rollout_start(self) -> None:
        # Env threads need the cores while collecting; torch's idle OpenMP workers would
        # spin on them. Policy inference on a few dozen observations needs one thread.
        self._set_threads(1)
        self.rollout_ended_at = None

    def _on_rollout_end(self) -> None:
        self.rollout_ended_at = time.perf_counter()
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

    def pop_results(self) -> list[tuple[int, float, EpisodeResult]]:
        results, self.results = self.results, []
        return results

    def pop_term_means(self) -> dict[str, float]:
        means = {k: v / self.term_count for k, v in self.term_sums.items()} if self.term_count else {}
        self.term_sums, self.term_count = {}, 0
        return means


# -- the run -----------------------------------------------------------------------------

def _package_versions() -> dict[str, str]:
    from importlib import metadata

    versions = {"python": platform.python_version(), "platform": platform.platform()}
    for name in ("mujoco", "gymnasium", "stable-baselines3", "sb3-contrib", "torch", "numpy", "myosuite"):
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def new_run_dir(config: RunConfig, config_path: Path) -> Path:
    """A fresh, race-free run folder ``<output_dir>/<config>-<date>-<time>-s<seed>[-n]``."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    base = config.output_dir / f"{config_path.stem}-{stamp}-s{config.seed}"
    for attempt in range(1000):
        candidate = base if attempt == 0 else base.with_name(f"{base.name}-{attempt}")
        try:
            candidate.mkdir(parents=True, exist_ok=False)
            return candidate
        except FileExistsError:
            continue
    raise RuntimeError(f"could not create a run folder next to {base}")


class CurriculumTrainer:
    """Train a RecurrentPPO policy through a curriculum into a run folder.

    Use :meth:`start` for a new run and :meth:`resume` to continue one; then :meth:`run`.
    """

    def __init__(self, config: RunConfig, run_dir: Path, state: CurriculumState, model, venv,
                 progress: bool = True) -> None:
        self.config, self.run_dir, self.state = config, run_dir, state
        self.model, self.venv = model, venv
        self.show_progress = progress
        self.checkpoint_dir = run_dir / CHECKPOINT_DIR
        self.checkpoint_dir.mkdir(exist_ok=True)
        self.next_checkpoint = (state.num_timesteps // config.checkpoint_every + 1) * config.checkpoint_every
        self.progress = StageProgress(steps=state.num_timesteps - state.stage_start_step,
                                      episodes=state.stage_episodes)
        self.progress.recent.extend(state.recent)
        # Where wall time goes: env stepping (timed on the inner VecEnv, which is never
        # pickled), the PPO update (from the end of the rollout to the end of ``learn``), and
        # the rest of the rollout: policy inference and bookkeeping.
        self.env_clock = WallClock()
        inner = venv.venv
        inner.step_async = self.env_clock.wrap(inner.step_async)
        inner.step_wait = self.env_clock.wrap(inner.step_wait)
        self.timings: list[RolloutTiming] = []
        self.learn_started_at = time.perf_counter()
        self.update_threads = UpdateThreads(available_cpus(), fixed=config.num_threads or None)
        self.collector = EpisodeCollector(config.n_envs, state.stage_index, TASK_SPECS[config.curriculum.task].reward_terms,
                                          run_wall_s=lambda: self.state.wall_s + time.perf_counter() - self.learn_started_at,
                                          update_threads=self.update_threads)
        self.minibatch_hook = model.policy.optimizer.register_step_pre_hook(self.collector.before_optimizer_step)

    # construction ------------------------------------------------------------------------

    @classmethod
    def start(cls, config_path: str | Path, overrides: tuple[str, ...] = (), run_dir: Path | None = None,
              overwrite: bool = False, progress: bool = True) -> "CurriculumTrainer":
        """Validate the config, create the run folder and a new model at stage 1."""
        import shutil

        from stable_baselines3.common.logger import configure
        from stable_baselines3.common.utils import set_random_seed

        config_path = Path(config_path)
        config = load_run_config(config_path, overrides)
        if run_dir is None:
            run_dir = new_run_dir(config, config_path)
        else:
            if run_dir.exists() and any(run_dir.iterdir()):
                if not overwrite:
                    raise ConfigError(f"{run_dir}: run folder exists and is not empty; use --resume "
                                      "to continue it or --overwrite to replace it")
                shutil.rmtree(run_dir)
            run_dir.mkdir(parents=True, exist_ok=True)
        # The run folder is self-contained: its config points at its own copy of the curriculum.
        (run_dir / "curriculum.yaml").write_text(config.curriculum_path.read_text())
        resolved = {**config.source, "curriculum": "curriculum.yaml", "seed": config.seed}
        (run_dir / "config.yaml").write_text(yaml.safe_dump(resolved, sort_keys=False))
        (run_dir / "command.txt").write_text(" ".join(sys.argv) + "\n")
        (run_dir / "versions.json").write_text(json.dumps(_package_versions(), indent=2))
        set_random_seed(config.seed)
        stage = config.curriculum.stages[0]
        venv = build_vec_env(config, stage)
        model = build_model(config, venv)
        model.set_logger(configure(str(run_dir / "tb"), ["tensorboard"]))
        state = CurriculumState()
        trainer = cls(config, run_dir, state, model, venv, progress)
        trainer.apply_ppo_settings()
        return trainer

    @classmethod
    def resume(cls, run_dir: str | Path, progress: bool = True,
               total_steps: int | None = None) -> "CurriculumTrainer":
        """Continue a run from its latest complete checkpoint: same stage, counters,
        optimizer and normalization state, same TensorBoard folder. ``total_steps`` raises
        the run's step budget (recorded in its config.yaml), which also continues a run that
        ended at its budget."""
        from sb3_contrib import RecurrentPPO
        from stable_baselines3.common.logger import Logger
        from stable_baselines3.common.vec_env import VecNormalize

        run_dir = Path(run_dir)
        config_path = run_dir / "config.yaml"
        config = load_run_config(config_path)
        checkpoint = latest_checkpoint(run_dir)
        if checkpoint is None:
            raise ConfigError(f"{run_dir}: no complete checkpoint to resume from")
        state = CurriculumState.from_json(checkpoint.state.read_text())
        resumable = ("running", "interrupted", "time_limit") + (("budget_reached",) if total_steps else ())
        if state.status not in resumable:
            hint = ("; add --total-steps N to train on to N steps" if state.status == "budget_reached"
                    else "; nothing to resume")
            raise ConfigError(f"{run_dir}: the run already ended ({state.status}){hint}")
        if total_steps is not None:
            if total_steps <= state.num_timesteps:
                raise ConfigError(f"{config_path}: total_steps {total_steps} must exceed the "
                                  f"{state.num_timesteps} steps already trained")
            config = load_run_config(config_path, (f"total_steps={total_steps}",))
            config_path.write_text(yaml.safe_dump(dict(config.source), sort_keys=False))
        state.status = "running"
        stage = config.curriculum.stages[state.stage_index]
        venv = VecNormalize.load(str(checkpoint.vecnormalize), build_vec_env(config, stage).venv)
        venv.training = True
        model = RecurrentPPO.load(str(checkpoint.model), env=venv, device=config.device)
        # Loading reseeds torch, numpy and the envs' next reset with the run's seed: continue
        # the streams of the checkpoint instead, so the resumed run draws new episodes.
        restore_random_state(venv, checkpoint.random_state, fallback_seed=config.seed + state.num_timesteps)
        # Events a killed run logged after this checkpoint are hidden from TensorBoard.
        tb_folder = str(run_dir / "tb")
        model.set_logger(Logger(tb_folder, [resumed_tensorboard_format(tb_folder, purge_step=state.num_timesteps + 1)]))
        _truncate_episode_log(run_dir / EPISODES_FILE, state.num_timesteps)
        trainer = cls(config, run_dir, state, model, venv, progress)
        trainer.apply_ppo_settings()
        return trainer

    # the loop ----------------------------------------------------------------------------

    @property
    def stage(self) -> Stage:
        return self.config.curriculum.stages[self.state.stage_index]

    def apply_ppo_settings(self) -> None:
        """Give the model the PPO settings in force at the current stage and step."""
        step = int(self.model.num_timesteps)
        apply_ppo_settings(self.model, effective_ppo(self.config.ppo, self.config.curriculum, self.state.stage_index, step),
                           learning_rate_at(self.config, self.state, step))

    def run(self, max_wall_s: float | None = None) -> CurriculumState:
        """Train until the curriculum completes or stops, the step budget is spent, or a
        SIGINT/SIGTERM arrives or this call has trained for ``max_wall_s`` seconds (then a
        checkpoint is written and the run can be resumed)."""
        from tqdm import tqdm

        config, model, state = self.config, self.model, self.state
        bar = tqdm(total=config.total_steps, initial=model.num_timesteps, unit="step", dynamic_ncols=True,
                   disable=not self.show_progress, smoothing=0.1,
                   mininterval=0.5 if sys.stderr.isatty() else 30.0)
        collector = self.collector
        collector.progress_bar = bar
        previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}

        def request_stop(signum, frame):
            collector.stop_requested = signal.Signals(signum).name
            signal.signal(signal.SIGINT, signal.default_int_handler)  # a second Ctrl-C aborts

        for sig in previous:
            signal.signal(sig, request_stop)
        started, start_steps, start_wall = time.perf_counter(), model.num_timesteps, state.wall_s
        try:
            self._announce_stage(bar)
            while state.status == "running":
                if model.num_timesteps >= config.total_steps:
                    state.status = "budget_reached"
                    break
                if max_wall_s is not None and state.wall_s - start_wall >= max_wall_s:
                    state.status = "time_limit"
                    bar.write(f"time limit of {max_wall_s:.0f} s reached; continue with "
                              f"`python train.py --resume {self.run_dir}`")
                    break
                self.apply_ppo_settings()  # a decaying rate or a warm-up's end acts between rollouts
                rollout = model.n_steps * model.n_envs
                steps_before, started_at, env_before = model.num_timesteps, time.perf_counter(), self.env_clock.seconds
                self.learn_started_at = started_at
                try:
                    model.learn(total_timesteps=rollout, callback=collector, reset_num_timesteps=False,
                                log_interval=1)
                except UpdateInterrupted:
                    pass  # stopped between minibatches: weights and optimizer are consistent
                finished_at = time.perf_counter()
                state.wall_s += finished_at - started_at
                ended = collector.rollout_ended_at  # None: a stop cut the rollout, no update ran
                self.timings.append(RolloutTiming(
                    model.num_timesteps - steps_before, finished_at - started_at,
                    self.env_clock.seconds - env_before, finished_at - ended if ended else 0.0))
                self._after_rollout(collector, bar)
                if collector.stop_requested:
                    state.status = "interrupted"
                    bar.write(f"{collector.stop_requested}: saving a checkpoint; continue with "
                              f"`python train.py --resume {self.run_dir}`")
                    break
                rate = (model.num_timesteps - start_steps) / max(time.perf_counter() - started, 1e-9)
                bar.set_postfix_str(f"stage {state.stage_index + 1}/{len(config.curriculum.stages)} "
                                    f"{self.stage.name} | {self.stage_metric_text()} | {rate:.0f} steps/s", refresh=False)
                if model.num_timesteps >= self.next_checkpoint and state.status == "running":
                    self.save_checkpoint()
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
            bar.close()
        self.save_checkpoint()
        if state.status not in ("interrupted", "time_limit"):
            self.save_final()
        return state

    def stage_metric_text(self) -> str:
        rule = self.stage.advance
        if rule is None:
            return "no advancement rule"
        measured = self.progress.measured
        value = "-" if math.isnan(measured) else f"{measured:.3f}"
        return f"{rule.metric} {value}/{rule.threshold} over {len(self.progress.recent)}/{rule.window} eps"

    def _announce_stage(self, bar) -> None:
        bar.write(f"stage {self.state.stage_index + 1}/{len(self.config.curriculum.stages)}: {self.stage.name}")

    def _after_rollout(self, collector: EpisodeCollector, bar) -> None:
        model, state = self.model, self.state
        results = collector.pop_results()
        rule = self.stage.advance
        metric = rule.metric if rule else "score"
        window = rule.window if rule else 100
        self.progress.record((episode_metric(metric, r) for _, _, r in results), window)
        self.progress.steps = model.num_timesteps - state.stage_start_step
        self._log_episodes(results)
        logger = model.logger
        for key, value in collector.pop_term_means().items():
            logger.record(f"reward/{key}", value)
        if results:
            episodes = [r for _, _, r in results]
            logger.record("rollout/score", float(np.mean([r.score for r in episodes])))
            logger.record("rollout/effort", float(np.mean([r.effort for r in episodes])))
            logger.record("rollout/drop_rate", float(np.mean([r.dropped for r in episodes])))
        timing = self.timings[-1] if self.timings else None
        if timing and timing.wall_s > 0:
            logger.record("time/env_steps_per_s", timing.steps / timing.wall_s)
            logger.record("time/env_stepping_share", timing.env_s / timing.wall_s)
            logger.record("time/update_share", timing.update_s / timing.wall_s)
        logger.record("time/update_threads", self.update_threads.current)
        logger.record("curriculum/stage_index", state.stage_index)
        logger.record("curriculum/stage_steps", self.progress.steps)
        if not math.isnan(self.progress.measured):
            logger.record("curriculum/measured", self.progress.measured)
        decision = decide(rule, self.progress)
        if decision is not Decision.STAY:
            self._transition(decision, collector, bar)
        logger.dump(model.num_timesteps)
        self._sync_state()

    def _transition(self, decision: Decision, collector: EpisodeCollector, bar) -> None:
        state, model, config = self.state, self.model, self.config
        stage = self.stage
        entry = {"stage": stage.name, "stage_index": state.stage_index, "decision": decision.value,
                 "at_step": model.num_timesteps, "stage_steps": self.progress.steps,
                 "stage_episodes": self.progress.episodes, "measured": self.progress.measured}
        state.history.append(entry)
        state.episodes_per_stage[stage.name] = self.progress.episodes
        state.steps_per_stage[stage.name] = self.progress.steps
        verdict = {"passed": "passed", "timed_out": "ended unpassed (max_steps)", "stop": "ended unpassed"}[decision.value]
        bar.write(f"stage {stage.name} {verdict} at step {model.num_timesteps}: "
                  f"{self.stage_metric_text()}")
        model.logger.record("curriculum/transition", state.stage_index + 1)
        last = state.stage_index + 1 >= len(config.curriculum.stages)
        if decision is Decision.STOP:
            state.status = "stopped"
            return
        if last:
            state.status = "completed"
            bar.write("curriculum completed")
            return
        state.stage_index += 1
        state.stage_start_step = model.num_timesteps
        self.progress = StageProgress()
        collector.stage_index = state.stage_index
        self.venv.env_method("configure", **stage_knobs(self.stage))
        self.apply_ppo_settings()
        self._announce_stage(bar)

    def _sync_state(self) -> None:
        state = self.state
        state.num_timesteps = int(self.model.num_timesteps)
        state.stage_episodes = self.progress.episodes
        state.recent = list(self.progress.recent)
        name = self.stage.name
        state.episodes_per_stage[name] = self.progress.episodes
        state.steps_per_stage[name] = self.progress.steps

    def _log_episodes(self, results: list[tuple[int, EpisodeResult]]) -> None:
        path = self.run_dir / EPISODES_FILE
        new = not path.exists()
        # A run begun before the last columns existed keeps its header, and its rows match it.
        n_columns = len(EPISODE_COLUMNS) if new else len(_episode_log_header(path))
        with path.open("a", newline="") as file:
            writer = csv.writer(file)
            if new:
                writer.writerow(EPISODE_COLUMNS)
            for step, wall_s, r in results:
                phase = "" if r.start_phase is None else f"{r.start_phase:.4f}"
                writer.writerow((step, f"{wall_s:.2f}", self.state.stage_index, self.stage.name, f"{r.score:.6g}",
                                 r.solved_steps, r.length, int(r.dropped), f"{r.effort:.6g}", r.direction,
                                 phase)[:n_columns])

    # checkpoints -------------------------------------------------------------------------

    def save_checkpoint(self) -> Path:
        """Write model (with optimizer), normalization statistics and curriculum state of the
        same step; each file is written under a temporary name and renamed, and the pointer
        ``latest.json`` last, so a crash leaves the previous checkpoint intact."""
        self._sync_state()
        steps = int(self.model.num_timesteps)
        files = checkpoint_files(self.checkpoint_dir, steps)
        tmp_model = self.checkpoint_dir / f".tmp_{files.model.name}"
        self.model.save(tmp_model)
        os.replace(tmp_model, files.model)
        tmp_norm = self.checkpoint_dir / f".tmp_{files.vecnormalize.name}"
        self.venv.save(str(tmp_norm))
        os.replace(tmp_norm, files.vecnormalize)
        tmp_random = self.checkpoint_dir / f".tmp_{files.random_state.name}"
        tmp_random.write_bytes(pickle.dumps(capture_random_state(self.venv)))
        os.replace(tmp_random, files.random_state)
        _atomic_write_text(files.state, self.state.to_json())
        _atomic_write_text(self.checkpoint_dir / LATEST_FILE, json.dumps({"steps": steps}))
        _atomic_write_text(self.run_dir / STATE_FILE, self.state.to_json())
        self.next_checkpoint = (steps // self.config.checkpoint_every + 1) * self.config.checkpoint_every
        self._prune_checkpoints()
        return files.model

    def save_final(self) -> None:
        self.model.save(self.run_dir / "final_model.zip")
        self.venv.save(str(self.run_dir / "final_vecnormalize.pkl"))

    def _prune_checkpoints(self) -> None:
        steps = sorted(checkpoint_steps(self.checkpoint_dir))
        for old in steps[: -self.config.keep_checkpoints]:
            for path in checkpoint_files(self.checkpoint_dir, old):
                path.unlink(missing_ok=True)


@dataclass(frozen=True)
class CheckpointFiles:
    """A checkpoint's files. The random state is optional: checkpoints written before it
    existed resume with streams seeded from the run's seed and step count."""

    model: Path
    vecnormalize: Path
    state: Path
    random_state: Path

    def __iter__(self):
        return iter((self.model, self.vecnormalize, self.state, self.random_state))

    def complete(self) -> bool:
        return all(path.is_file() for path in (self.model, self.vecnormalize, self.state))


def checkpoint_files(folder: Path, steps: int) -> CheckpointFiles:
    """SB3's names for a checkpoint's model and statistics, plus our curriculum state and the
    random generators' states."""
    return CheckpointFiles(folder / f"rl_model_{steps}_steps.zip",
                           folder / f"rl_model_vecnormalize_{steps}_steps.pkl",
                           folder / f"curriculum_state_{steps}_steps.json",
                           folder / f"random_state_{steps}_steps.pkl")


# -- random streams ----------------------------------------------------------------------

def capture_random_state(venv) -> dict[str, Any]:
    """Everything random that shapes the episodes and updates to come: each env's generator
    (task draws at reset), and the global python, numpy (minibatch order) and torch (action
    noise) generators."""
    import torch

    return {"envs": list(venv.get_attr("np_random")), "python": random.getstate(),
            "numpy": np.random.get_state(), "torch": torch.get_rng_state()}


def restore_random_state(venv, path: Path, fallback_seed: int) -> None:
    """Continue the streams saved at ``path``; without that file (an older checkpoint), seed
    every stream from ``fallback_seed`` instead, so a resume still draws new episodes. Either
    way the envs' next reset draws from their own generators, not from the run's seed."""
    import torch

    venv.venv._reset_seeds()  # drop the seeds SB3's load queued for the next reset
    if path.is_file():
        saved = pickle.loads(path.read_bytes())
        if len(saved["envs"]) == venv.num_envs:
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


def resumed_tensorboard_format(folder: str, purge_step: int):
    """SB3's TensorBoard writer, opened with ``purge_step``: TensorBoard then hides the events
    at or after that step from earlier event files (those a killed run logged after the
    checkpoint it is resumed from)."""
    from stable_baselines3.common.logger import TensorBoardOutputFormat
    from torch.utils.tensorboard import SummaryWriter

    output = TensorBoardOutputFormat.__new__(TensorBoardOutputFormat)  # its __init__ takes no purge_step
    output.writer = SummaryWriter(log_dir=folder, purge_step=purge_step)
    output._is_closed = False
    return output


def checkpoint_steps(folder: Path) -> list[int]:
    steps = []
    for path in folder.glob("rl_model_*_steps.zip"):
        try:
            steps.append(int(path.name[len("rl_model_"):-len("_steps.zip")]))
        except ValueError:
            continue
    return steps


def latest_checkpoint(run_dir: Path) -> CheckpointFiles | None:
    """The newest checkpoint whose three files all exist."""
    folder = Path(run_dir) / CHECKPOINT_DIR
    for steps in sorted(checkpoint_steps(folder), reverse=True):
        files = checkpoint_files(folder, steps)
        if files.complete():
            return files
    return None


def _episode_log_header(path: Path) -> list[str]:
    with path.open(newline="") as file:
        return next(csv.reader(file), [])


def _truncate_episode_log(path: Path, max_step: int) -> None:
    """Drop episodes logged after the checkpoint a resumed run restarts from, and a row that a
    kill cut short; the file is replaced in one rename."""
    if not path.exists():
        return
    with path.open(newline="") as file:
        rows = list(csv.reader(file))
    if not rows:
        path.unlink()
        return
    header = rows[0]

    def kept(row: list[str]) -> bool:
        try:
            return len(row) == len(header) and int(row[0]) <= max_step
        except ValueError:
            return False

    tmp = path.with_name(f".{path.name}.tmp")
    with tmp.open("w", newline="") as file:
        csv.writer(file).writerows([header] + [row for row in rows[1:] if kept(row)])
    os.replace(tmp, path)
