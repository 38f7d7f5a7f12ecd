"""Building what the trainer trains: the worker envs under one VecNormalize, and the model
with the PPO settings in force."""

from __future__ import annotations

import multiprocessing
import signal
from collections.abc import Callable
from pathlib import Path
from typing import Any

from myo_sds.curricula.run_config import RunConfig
from myo_sds.curricula.schedule import PpoSettings
from myo_sds.curricula.schema import Stage
from myo_sds.envs.knobs import TaskKnobs
from myo_sds.envs.task_specs import TASK_SPECS
from myo_sds.sb3_internals import resize_rollout_buffer


def env_factory(task: str, distribution: TaskKnobs, seed: int, privileged: tuple[str, ...] = ()) -> Callable[[], Any]:
    """A picklable-enough factory (for SubprocVecEnv) of one env, reset once with ``seed``; its
    observation ends with the ``privileged`` features (``policy.critic_extra``)."""
    def build():
        if multiprocessing.current_process().name != "MainProcess":
            # Ctrl-C goes to the whole process group: let the main process save and stop
            # the workers, instead of the workers dying mid-step.
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        env = TASK_SPECS[task].env_class()(distribution=distribution, privileged=privileged)
        env.reset(seed=seed)
        return env
    return build


def build_vec_env(config: RunConfig, stage: Stage):
    """The training VecEnv (``n_envs`` workers, seeded ``seed + rank``) under VecNormalize."""
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    from myo_sds.vec_env import ThreadVecEnv

    factories = [env_factory(config.curriculum.task, stage.distribution, config.seed + rank, config.policy.critic_extra)
                 for rank in range(config.n_envs)]
    if config.vec_env == "subproc":
        venv = SubprocVecEnv(factories)
    elif config.vec_env == "thread":
        venv = ThreadVecEnv(factories, config.env_threads)
    else:
        venv = DummyVecEnv(factories)
    venv.seed(config.seed)
    return normalized(config, venv)


def normalized(config: RunConfig, venv):
    """``venv`` under the VecNormalize the run's ``normalize`` settings describe (the one
    builder of it: local envs, the Ray learner's stand-in and each Ray worker's envs)."""
    from stable_baselines3.common.vec_env import VecNormalize

    norm = config.normalize
    return VecNormalize(venv, norm_obs=norm.observations, norm_reward=norm.rewards,
                        clip_obs=norm.clip_obs, clip_reward=norm.clip_reward, gamma=config.ppo.gamma)


def build_training_venv(config: RunConfig, stage: Stage):
    """What the model trains on: the envs themselves (local backend), or on Ray the holder of
    the merged normalization statistics (the envs run on the workers)."""
    return build_vec_env(config, stage) if config.rollout.backend == "local" else build_statistics_venv(config, stage)


def build_statistics_venv(config: RunConfig, stage: Stage):
    """For the Ray backend: the envs' spaces and count under the VecNormalize that holds the
    merged statistics (the envs themselves run on the workers)."""
    from myo_sds.vec_env import StatisticsOnlyVecEnv

    probe = TASK_SPECS[config.curriculum.task].env_class()(distribution=stage.distribution,
                                                          privileged=config.policy.critic_extra)
    stand_in = StatisticsOnlyVecEnv(config.n_envs, probe.observation_space, probe.action_space)
    probe.close()
    return normalized(config, stand_in)


def build_model(config: RunConfig, venv, settings: PpoSettings):
    """A new RecurrentPPO model over ``venv`` with the run's policy and ``settings``."""
    import torch
    from sb3_contrib import RecurrentPPO

    from myo_sds.policy import LatticeLstmPolicy, SequenceLstmPolicy

    activations = {"relu": torch.nn.ReLU, "tanh": torch.nn.Tanh, "elu": torch.nn.ELU,
                   "leaky_relu": torch.nn.LeakyReLU}
    policy, ppo = config.policy, config.ppo
    critic_layers = policy.net_arch if policy.critic_net_arch is None else policy.critic_net_arch
    policy_kwargs = {
        # Without memory the "LSTMs" pass the observation through, so their width is its size.
        "lstm_hidden_size": venv.observation_space.shape[0] if policy.memory == "none" else policy.lstm_hidden_size,
        "enable_critic_lstm": policy.enable_critic_lstm,
        "shared_lstm": False,
        "net_arch": {"pi": list(policy.net_arch), "vf": list(critic_layers)},
        "activation_fn": activations[policy.activation],
        "log_std_init": policy.log_std_init,
        "ortho_init": policy.ortho_init,
    }
    lattice = policy.exploration == "lattice"
    if policy.fast_lstm_update:
        policy_kwargs["action_mean_bound"] = policy.action_mean_bound
        policy_kwargs["action_head_lr_scale"] = policy.action_head_lr_scale
        policy_kwargs["log_std_min"] = policy.log_std_min
        policy_kwargs["memory"] = policy.memory
    if policy.critic_extra:  # the actor reads the official observation, the first part of the env's
        policy_kwargs["actor_observation_size"] = TASK_SPECS[config.curriculum.task].env_class().OBS_SIZE
    if lattice:
        policy_kwargs.update(lattice_alpha=policy.lattice_alpha, lattice_std_reg=policy.lattice_std_reg,
                             full_std=policy.lattice_full_std)
    policy_class = (LatticeLstmPolicy if lattice else SequenceLstmPolicy) if policy.fast_lstm_update else "MlpLstmPolicy"
    return RecurrentPPO(
        policy_class, venv, use_sde=lattice, sde_sample_freq=policy.noise_resample_every if lattice else -1,
        learning_rate=settings.learning_rate, n_steps=settings.n_steps, batch_size=settings.batch_size,
        n_epochs=settings.n_epochs, gamma=ppo.gamma, gae_lambda=ppo.gae_lambda, clip_range=settings.clip_range,
        ent_coef=settings.ent_coef, vf_coef=ppo.vf_coef, max_grad_norm=ppo.max_grad_norm,
        target_kl=ppo.target_kl, policy_kwargs=policy_kwargs, seed=config.seed, device=config.device, verbose=0)


def trained_policy_files(source: Path) -> tuple[Path, Path]:
    """(model, normalization statistics) of the trained policy that ``--init-from`` names: a
    model or run folder (its final model, else its newest checkpoint), a checkpoint ``.zip``, or
    a policy as its authors published it (a folder with one ``.zip`` and one ``.pkl``)."""
    from myo_sds.curricula.schema import ConfigError
    from myo_sds.published import published_files
    from myo_sds.run_folder import RunFolder, statistics_beside

    source = Path(source)
    try:
        if source.suffix == ".zip":
            if not source.is_file():
                raise FileNotFoundError(f"{source}: no such checkpoint")
            return source, statistics_beside(source)
        if not source.is_dir():
            raise FileNotFoundError(f"{source}: not a run folder: there is no such folder")
        run = RunFolder.containing(source)
        return run.newest_policy() if run is not None else published_files(source)
    except FileNotFoundError as error:
        raise ConfigError(f"--init-from: {error}") from None


def initialize_from(model, venv, model_file: Path, statistics: Path) -> None:
    """Fine-tuning: give a new ``model`` the weights and optimizer state of a trained policy,
    and its VecNormalize the policy's normalization moments (this run's normalization
    settings stay). A policy trained without a privileged critic starts one with it: the critic's
    weights on the extra inputs start at zero (the same value function), their statistics fresh."""
    from stable_baselines3.common.save_util import load_from_zip_file

    from myo_sds.curricula.schema import ConfigError
    from myo_sds.published import load_statistics

    # The sizes its networks take and give (read from the weights: archives of other library
    # versions, the 2022 ones under gym included, keep them where their pickled spaces may not load).
    _, params, _ = load_from_zip_file(str(model_file), load_data=False, device=model.device)
    weights = params.get("policy", {})
    actor_size = getattr(model.policy, "actor_observation_size", None)
    # The task is what the actor reads; a privileged critic reads more (policy.critic_extra).
    sizes = {"observation": _input_size(weights, "lstm_actor"), "action": _output_size(weights)}
    ours = {"observation": actor_size or model.observation_space.shape[0], "action": model.action_space.shape[0]}
    for kind, trained in sizes.items():
        if trained is not None and trained != ours[kind]:
            raise ConfigError(f"--init-from {model_file}: it was trained on {kind}s of {trained} values, this "
                              f"config's task has {ours[kind]} (a policy of another task cannot start this one)")
    trained_critic, our_critic = _input_size(weights, "lstm_critic"), model.observation_space.shape[0]
    widen = trained_critic is not None and trained_critic != our_critic
    if widen and trained_critic != sizes["observation"]:
        raise ConfigError(f"--init-from {model_file}: its critic read {trained_critic} values where this config's "
                          f"reads {our_critic}: set `policy.critic_extra` as it was trained "
                          f"({_trained_critic_extra(model_file)})")
    try:
        if _gaussian_into_lattice(model, model_file):
            _load_mean_network(model, model_file)
        elif widen:
            model.set_parameters(_widened(params, model), exact_match=True, device=model.device)
        else:
            model.set_parameters(str(model_file), exact_match=True, device=model.device)
    except (RuntimeError, ValueError, KeyError) as error:
        raise ConfigError(f"--init-from {model_file}: its network does not fit this config's `policy` "
                          f"settings (lstm_hidden_size, enable_critic_lstm, net_arch, fast_lstm_update): "
                          f"{_first_difference(error)}") from None
    if statistics.is_file():
        trained = load_statistics(statistics)
        size = trained.obs_rms.mean.shape
        if widen and size == (actor_size,):
            venv.obs_rms.mean[:actor_size], venv.obs_rms.var[:actor_size] = trained.obs_rms.mean, trained.obs_rms.var
            venv.obs_rms.count, venv.ret_rms = trained.obs_rms.count, trained.ret_rms
            return
        if size != venv.obs_rms.mean.shape:
            raise ConfigError(f"--init-from {statistics}: observations of shape {size}, "
                              f"this task's are {venv.obs_rms.mean.shape}")
        venv.obs_rms, venv.ret_rms = trained.obs_rms, trained.ret_rms


def _input_size(weights: dict, lstm: str) -> int | None:
    """The observation size one of a policy's LSTMs reads (without a critic LSTM: the actor's)."""
    for name in (f"{lstm}.weight_ih_l0", "lstm_actor.weight_ih_l0"):
        if name in weights:
            return int(weights[name].shape[1])
    return None


def _trained_critic_extra(model_file: Path) -> str:
    """The ``policy.critic_extra`` of the run or model folder holding ``model_file``, as YAML."""
    from myo_sds.curricula.run_config import load_run_config
    from myo_sds.run_folder import RunFolder

    run = RunFolder.containing(model_file)
    try:
        extra = load_run_config(run.config_file).policy.critic_extra if run is not None else None
    except Exception:  # noqa: BLE001 (only a hint: any unreadable config gives the generic one)
        extra = None
    return f"critic_extra: [{', '.join(extra)}]" if extra else "its run's config.yaml names them"


def _output_size(weights: dict) -> int | None:
    return int(weights["action_net.weight"].shape[0]) if "action_net.weight" in weights else None


def _widened(params: dict, model) -> dict:
    """A trained policy's parameters and optimizer state for ``model``, whose critic reads more
    inputs: each tensor that is wider in ``model`` gets zero columns (weights and Adam moments
    alike), so the critic computes what it did and starts learning the new inputs."""
    import torch

    ours = model.policy.state_dict()
    weights = dict(params["policy"])
    widened = {}
    for index, (name, value) in enumerate(weights.items()):
        target = ours[name]
        if value.shape != target.shape:
            if value.shape[:-1] != target.shape[:-1] or value.shape[-1] > target.shape[-1]:
                raise RuntimeError(f"size mismatch for {name}: {tuple(value.shape)} in the checkpoint, "
                                   f"{tuple(target.shape)} here")
            widened[index] = target.shape[-1] - value.shape[-1]
            weights[name] = torch.nn.functional.pad(value, (0, widened[index]))
    optimizer = params["policy.optimizer"]
    names = list(params["policy"])
    parameter_index = {name: i for i, name in enumerate(n for n, _ in model.policy.named_parameters())}
    for index, extra in widened.items():
        slot = optimizer["state"].get(parameter_index.get(names[index]))
        for key in ("exp_avg", "exp_avg_sq"):
            if slot is not None and key in slot:
                slot[key] = torch.nn.functional.pad(slot[key], (0, extra))
    return {**params, "policy": weights, "policy.optimizer": optimizer}


def _first_difference(error: Exception) -> str:
    """The first concrete line of torch's state-dict error (its first line is only a heading:
    "Error(s) in loading state_dict for ...:"), e.g. a size mismatch with both shapes."""
    lines = [line.strip() for line in str(error).strip().splitlines() if line.strip()]
    concrete = [line for line in lines if not line.endswith(":")]
    return (concrete or lines or [type(error).__name__])[0].rstrip(".")


def _gaussian_into_lattice(model, model_file: Path) -> bool:
    """Whether a Lattice model is initialized from a Gaussian policy's checkpoint."""
    from stable_baselines3.common.save_util import load_from_zip_file

    from myo_sds.policy import LatticeLstmPolicy

    if not isinstance(model.policy, LatticeLstmPolicy):
        return False
    _, params, _ = load_from_zip_file(str(model_file), load_data=False, device="cpu")
    return params["policy"]["log_std"].shape != model.policy.log_std.shape


def _load_mean_network(model, model_file: Path) -> None:
    """Every network of a Gaussian checkpoint but its ``log_std`` (Lattice's has another shape
    and keeps its initial value); the optimizer starts afresh, its moments being of other
    parameters. The Lattice policy then acts as the Gaussian one on average (the same mean)."""
    from stable_baselines3.common.save_util import load_from_zip_file

    _, params, _ = load_from_zip_file(str(model_file), load_data=False, device=model.device)
    weights = {k: v for k, v in params["policy"].items() if k != "log_std"}
    missing, unexpected = model.policy.load_state_dict(weights, strict=False)
    if missing != ["log_std"] or unexpected:
        raise RuntimeError(f"networks differ: missing {missing}, unexpected {unexpected}")


def use_padded_buffer(model) -> None:
    """The model's rollout buffer as :class:`~myo_sds.rollout_buffer.PaddedRolloutBuffer` (the
    same minibatches, padded faster); with ``fast_lstm_update: false`` sb3-contrib's own stays,
    to reproduce the reference setup's speed."""
    from myo_sds.policy import SequenceLstmPolicy
    from myo_sds.rollout_buffer import PaddedRolloutBuffer

    if isinstance(model.policy, SequenceLstmPolicy) and not isinstance(model.rollout_buffer, PaddedRolloutBuffer):
        resize_rollout_buffer(model, model.n_steps, PaddedRolloutBuffer)


def apply_ppo_settings(model, settings: PpoSettings) -> None:
    """Set learning rate, clip range, entropy coefficient, batch size, epochs and rollout length."""
    from stable_baselines3.common.utils import ConstantSchedule

    # The trainer runs one rollout and one update at a time, so SB3's progress-based schedules
    # would restart every rollout: the rate is set from the env step count instead.
    model.learning_rate = settings.learning_rate
    model.lr_schedule = ConstantSchedule(settings.learning_rate)
    model.clip_range = ConstantSchedule(settings.clip_range)
    model.ent_coef = settings.ent_coef
    model.batch_size = settings.batch_size
    model.n_epochs = settings.n_epochs
    model.target_kl = settings.target_kl
    if settings.n_steps != model.n_steps:
        resize_rollout_buffer(model, settings.n_steps)
    use_padded_buffer(model)
    if hasattr(model.rollout_buffer, "max_sequence_length"):
        model.rollout_buffer.max_sequence_length = settings.sequence_length
