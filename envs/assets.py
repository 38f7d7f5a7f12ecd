"""Locate and compile the MyoHand task models shipped with the ``myosuite`` package.

The task XML files live in ``myosuite/envs/myo/assets/hand/`` but refer to the scene,
meshes and textures of the separate ``myo-sim`` package through relative paths
(``../myo_sim/...``) that do not exist next to them. We rewrite those paths to the
installed ``myo_sim/models`` folder in memory and compile with ``mujoco.MjSpec``, so
nothing is written to disk and no myosuite code runs.
"""

from __future__ import annotations

import copy
import functools
import importlib.util
import re
from pathlib import Path

import mujoco

_INSTALL_HINT = "install it with `pip install myosuite==3.0.0` (it brings myo-sim)"


def _package_dir(name: str) -> Path:
    spec = importlib.util.find_spec(name)
    if spec is None or not spec.submodule_search_locations:
        raise FileNotFoundError(
            f"The Python package '{name}' is not installed, but the MyoHand model files "
            f"come from it: {_INSTALL_HINT}."
        )
    return Path(next(iter(spec.submodule_search_locations)))


def hand_model_path(file_name: str) -> Path:
    """Path of a MyoHand task model (e.g. ``myohand_baoding.xml``) inside myosuite.

    Raises:
        FileNotFoundError: naming the missing file and how to install it.
    """
    path = _package_dir("myosuite") / "envs" / "myo" / "assets" / "hand" / file_name
    if not path.is_file():
        raise FileNotFoundError(f"MyoHand model file not found: {path}; {_INSTALL_HINT}.")
    return path


def _myo_sim_models_dir() -> Path:
    models = _package_dir("myo_sim") / "models"
    if not (models / "scene").is_dir():
        raise FileNotFoundError(f"myo-sim scene assets not found under {models}; {_INSTALL_HINT}.")
    return models


def _resolved_xml(path: Path) -> str:
    """The model's XML with every relative include, asset folder and local file made absolute."""
    text = path.read_text()
    myo_sim = _myo_sim_models_dir().as_posix()
    text = text.replace("../myo_sim/", myo_sim + "/").replace("'../myo_sim'", f"'{myo_sim}'")

    def absolute_file(match: re.Match) -> str:
        element, target = match.group(1), match.group(3)
        if Path(target).is_absolute():
            return match.group(0)
        if element == "include":
            target = (path.parent / target).resolve().as_posix()
        elif (path.parent / Path(target).name).is_file():
            # Files shipped beside the model (the die texture) are named relative to
            # an old asset layout; they sit next to the XML.
            target = (path.parent / Path(target).name).as_posix()
        else:
            return match.group(0)
        return f"<{element}{match.group(2)}{target}{match.group(4)}"

    return re.sub(r"<(\w+)([^>]*?\sfile=[\"'])([^\"']+)([\"'])", absolute_file, text)


@functools.lru_cache(maxsize=None)
def _compiled(file_name: str) -> tuple[mujoco.MjModel, mujoco.MjSpec]:
    spec = mujoco.MjSpec.from_string(_resolved_xml(hand_model_path(file_name)))
    return spec.compile(), spec


def load_hand_model(file_name: str) -> tuple[mujoco.MjModel, mujoco.MjSpec]:
    """A private compiled copy of a MyoHand task model and the spec it came from.

    Every env edits its model (target sites, ball sizes), so each gets its own copy;
    the XML is parsed and compiled once per process.
    """
    model, spec = _compiled(file_name)
    return copy.copy(model), spec
