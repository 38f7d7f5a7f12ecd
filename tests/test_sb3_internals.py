"""The fence around stable-baselines3's internals: every private member the trainer relies on
still exists under its name, and the installed libraries are within the tested ranges."""

from __future__ import annotations

import importlib
import re
from importlib.metadata import version
from pathlib import Path

import numpy as np
import pytest
import tomllib
from packaging.requirements import Requirement

from myo_sds import sb3_internals

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("owner", sorted(sb3_internals.PRIVATE_METHODS), ids=lambda o: o[1])
def test_private_methods_the_trainer_uses_exist(owner):
    cls = getattr(importlib.import_module(owner[0]), owner[1])
    missing = [name for name in sb3_internals.PRIVATE_METHODS[owner] if not callable(getattr(cls, name, None))]
    assert not missing, f"{owner[0]}.{owner[1]} no longer has {missing}: update myo_sds/sb3_internals.py"


def test_private_attributes_the_trainer_sets_exist_on_sb3s_own_objects(tmp_path):
    from sb3_contrib import RecurrentPPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.logger import TensorBoardOutputFormat

    model = RecurrentPPO("MlpLstmPolicy", make_vec_env("Pendulum-v1", n_envs=2), n_steps=8, batch_size=8,
                         policy_kwargs={"lstm_hidden_size": 8})

    class Noop(BaseCallback):
        def _on_step(self) -> bool:
            return True

    sb3_internals.start_training(model, 16, Noop())
    objects = {"RecurrentPPO": model, "TensorBoardOutputFormat": TensorBoardOutputFormat(str(tmp_path))}
    for (module, name), attributes in sb3_internals.PRIVATE_ATTRIBUTES.items():
        missing = [a for a in attributes if not hasattr(objects[name], a)]
        assert not missing, f"{module}.{name} objects no longer have {missing}: update myo_sds/sb3_internals.py"
    # What SB3 set up is what the trainer overwrites: one observation row and start flag per env.
    assert model._last_obs.shape == (2, 3) and model._last_episode_starts.shape == (2,)
    sb3_internals.set_last_observation(model, np.zeros((2, 3)))
    assert model._last_episode_starts.all()
    sb3_internals.resize_rollout_buffer(model, 4)
    assert model.rollout_buffer.buffer_size == 4 and model.rollout_buffer.hidden_states_pi.shape == (4, 1, 2, 8)
    model.collect_rollouts(model.get_env(), sb3_internals.start_training(model, 16, Noop()), model.rollout_buffer, 4)
    assert model.rollout_buffer.full
    purged = sb3_internals.tensorboard_output(str(tmp_path / "tb"), purge_step=5)
    purged.write({"x": 1.0}, {"x": None}, step=6)
    purged.close()


def test_installed_libraries_are_within_the_pinned_ranges():
    """The ranges in pyproject.toml are the tested ones; a library outside them (installed by
    hand or by another project) is reported by name before it breaks a run silently."""
    pins = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["dependencies"]
    checked = {"mujoco", "gymnasium", "stable-baselines3", "sb3-contrib", "myosuite", "torch"}
    for pin in map(Requirement, pins):
        if pin.name in checked:
            installed = re.sub(r"\+.*", "", version(pin.name))
            assert pin.specifier.contains(installed, prereleases=True), f"{pin.name} {installed} is not {pin.specifier}"
            assert pin.specifier, f"{pin.name} has no tested range in pyproject.toml"
    assert {Requirement(p).name for p in pins} >= checked


def sb3_private_names() -> set[str]:
    """The private members stable-baselines3 and sb3-contrib define or set on their objects."""
    import sb3_contrib
    import stable_baselines3

    names: set[str] = set()
    for package in (stable_baselines3, sb3_contrib):
        for path in Path(package.__file__).parent.rglob("*.py"):
            text = path.read_text()
            names |= set(re.findall(r"\bself\.(_[A-Za-z]\w*)", text)) | set(re.findall(r"\bdef (_[A-Za-z]\w*)", text))
    return {name for name in names if not name.startswith("__")}


def test_no_private_sb3_member_is_used_outside_the_fence():
    """Every attribute, method or attribute-name string of the product that is one of SB3's
    private members must be declared in myo_sds/sb3_internals.py (whose test above checks each
    still exists); a new one fails here by file, line and name."""
    import ast

    private, declared = sb3_private_names(), sb3_internals.declared_private_names()
    assert {"_last_obs", "_n_updates", "_setup_learn"} <= private  # the scan sees SB3's own
    undeclared = []
    # Every Python folder of the repository but the tests (which may poke at anything) and the
    # virtual environments.
    folders = sorted(p for p in REPO.iterdir() if p.is_dir() and not p.name.startswith(".")
                     and p.name not in ("tests", "models") and any(p.rglob("*.py")))
    assert {"myo_sds", "envs", "curricula", "benchmarks", "experiments"} <= {p.name for p in folders}
    files = [path for folder in folders for path in sorted(folder.rglob("*.py"))] + sorted(REPO.glob("*.py"))
    for path in files:
        if path.name == "sb3_internals.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Attribute):
                name = node.attr
            elif isinstance(node, ast.FunctionDef):
                name = node.name
            elif isinstance(node, ast.Constant) and isinstance(node.value, str):
                name = node.value
            else:
                continue
            if name in private and name not in declared:
                undeclared.append(f"{path.relative_to(REPO)}:{node.lineno}: {name}")
    assert not undeclared, "private SB3 members not declared in myo_sds/sb3_internals.py:\n" + "\n".join(undeclared)
