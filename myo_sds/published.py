"""Policies as their authors published them: a folder holding one RecurrentPPO ``.zip`` and its
VecNormalize pickle, possibly saved by stable-baselines3 1.x under ``gym`` (e.g. the 2022 Baoding
winner's, ``models/reference/stiff_fingers_2022_p1``).

Such files pickle ``gym`` classes (observation and action spaces), which cannot be imported
beside gymnasium. The model's weights and optimizer state are plain torch files and load as
they are; the pickled spaces are read by an unpickler that maps ``gym`` classes to plain stand-ins,
from which gymnasium spaces of the same bounds are rebuilt. The statistics pickle is read the
same way into a current ``VecNormalize`` (``obs_rms``, ``ret_rms``, ``clip_obs``, ``epsilon``).
"""

from __future__ import annotations

import base64
import io
import json
import pickle
import zipfile
from pathlib import Path
from typing import Any

import numpy as np


class _StandIn:
    """Absorbs the state of a pickled class that cannot be imported here."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.args = args

    def __setstate__(self, state: Any) -> None:
        self.__dict__.update(state if isinstance(state, dict) else {"state": state})


class _LegacyUnpickler(pickle.Unpickler):
    """``gym.*`` classes become stand-ins; stable-baselines3's VecNormalize and RunningMeanStd
    are today's classes (same attributes); everything else as usual."""

    def find_class(self, module: str, name: str) -> Any:
        if module == "stable_baselines3.common.vec_env.vec_normalize" and name == "VecNormalize":
            from stable_baselines3.common.vec_env import VecNormalize

            return VecNormalize
        if module == "stable_baselines3.common.running_mean_std" and name == "RunningMeanStd":
            from stable_baselines3.common.running_mean_std import RunningMeanStd

            return RunningMeanStd
        if module == "gym" or module.startswith("gym."):
            return type(name, (_StandIn,), {"__module__": module})
        return super().find_class(module, name)


def _legacy_loads(data: bytes) -> Any:
    return _LegacyUnpickler(io.BytesIO(data)).load()


def _gymnasium_box(stand_in: Any):
    """The gymnasium ``Box`` of a pickled gym ``Box``'s bounds and dtype."""
    from gymnasium import spaces

    state = stand_in.__dict__
    low, high = np.asarray(state["low"]), np.asarray(state["high"])
    dtype = state.get("dtype", low.dtype)
    return spaces.Box(low=low, high=high, shape=low.shape, dtype=np.dtype(dtype))


def saved_with_gym(model_file: Path) -> bool:
    """Whether a model archive pickles ``gym`` spaces (SB3 1.x), so SB3 2.x cannot read it alone."""
    try:
        with zipfile.ZipFile(model_file) as archive:
            data = json.loads(archive.read("data"))
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return False
    space = data.get("observation_space", {})
    return isinstance(space, dict) and "gym.spaces" in space.get(":type:", "") and "gymnasium" not in space.get(
        ":type:", "")


def _serialized(data: dict[str, Any], key: str) -> Any:
    return _legacy_loads(base64.b64decode(data[key][":serialized:"]))


def archive_spaces(model_file: Path):
    """(observation space, action space) of a model archive, as gymnasium spaces, whichever
    library saved it."""
    with zipfile.ZipFile(model_file) as archive:
        data = json.loads(archive.read("data"))
    spaces_ = [_serialized(data, key) for key in ("observation_space", "action_space")]
    return tuple(_gymnasium_box(s) if isinstance(s, _StandIn) else s for s in spaces_)


def load_gym_era_model(model_file: Path, policy_class: type, device: str = "cpu"):
    """A RecurrentPPO model from an SB3 1.x archive: its weights, optimizer state and PPO
    settings, with gymnasium spaces and the policy built as ``policy_class`` (same parameters).

    The pickled objects SB3 2.x cannot rebuild (spaces, schedules, the last rollout's
    observations and LSTM states) are handed over or dropped; the learning rate and clip range
    become constants of their saved values, which is what the trainer sets anyway.
    """
    from sb3_contrib import RecurrentPPO

    with zipfile.ZipFile(model_file) as archive:
        data = json.loads(archive.read("data"))
    observation_space, action_space = archive_spaces(model_file)
    policy_kwargs = dict(_serialized(data, "policy_kwargs"))
    net_arch = policy_kwargs.get("net_arch")
    if isinstance(net_arch, list) and net_arch and isinstance(net_arch[-1], dict):
        # SB3 1.x wrote [shared..., dict(pi=[...], vf=[...])]; 2.x takes the dict (no shared layers).
        if len(net_arch) > 1:
            raise ValueError(f"{model_file}: shared layers {net_arch[:-1]} before the actor and critic "
                             "are not supported by stable-baselines3 2.x")
        policy_kwargs["net_arch"] = net_arch[-1]
    learning_rate = float(data.get("learning_rate", 3e-4))
    clip_range = _constant_of(data.get("clip_range"), default=0.2)
    custom_objects = {
        "observation_space": observation_space, "action_space": action_space, "policy_class": policy_class,
        "policy_kwargs": policy_kwargs, "learning_rate": learning_rate,
        "lr_schedule": lambda _: learning_rate, "clip_range": lambda _: clip_range,
        "_last_lstm_states": None, "_last_obs": None, "_last_original_obs": None,
        "_last_episode_starts": None, "ep_info_buffer": None, "ep_success_buffer": None,
    }
    return RecurrentPPO.load(model_file, custom_objects=custom_objects, device=device)


def _constant_of(saved: Any, default: float) -> float:
    """A saved schedule's value: SB3 1.x pickled constant schedules as closures; read the
    number it returns, else ``default``."""
    if isinstance(saved, (int, float)):
        return float(saved)
    try:
        return float(_legacy_loads(base64.b64decode(saved[":serialized:"]))(1.0))
    except Exception:
        return default


def load_statistics(path: Path):
    """A VecNormalize's statistics (no venv attached) from its pickle, whether SB3 2.x wrote it
    or SB3 1.x under gym; its spaces are gymnasium spaces either way."""
    data = Path(path).read_bytes()
    try:
        normalizer = pickle.loads(data)
    except ModuleNotFoundError as error:
        if error.name != "gym" and not str(error.name).startswith("gym."):
            raise
        normalizer = _legacy_loads(data)
        for key in ("observation_space", "action_space"):
            if isinstance(getattr(normalizer, key, None), _StandIn):
                setattr(normalizer, key, _gymnasium_box(getattr(normalizer, key)))
    return normalizer


def published_files(folder: Path) -> tuple[Path, Path]:
    """(model, statistics) of a folder that holds one model ``.zip`` and one statistics ``.pkl``,
    as a policy's authors published them; ``FileNotFoundError`` saying what is there otherwise."""
    folder = Path(folder)
    zips, pickles = sorted(folder.glob("*.zip")), sorted(folder.glob("*.pkl"))
    if len(zips) == 1 and len(pickles) == 1:
        return zips[0], pickles[0]
    raise FileNotFoundError(
        f"{folder}: not a run or model folder (no config.yaml), nor a published policy (one model .zip "
        f"and its VecNormalize .pkl): found {len(zips)} .zip and {len(pickles)} .pkl file(s)")
