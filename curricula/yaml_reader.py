"""Reading values out of YAML files with errors that say where: the file (or the ``--set``
override) and the key path, the bad value, and what is allowed.

PyYAML reads ``1e-3`` as a string and ``yes`` as a boolean, so numbers and booleans are
checked and converted here, never assumed.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml


class ConfigError(ValueError):
    """A curriculum or run config that cannot be used; the message says where and why."""


class YamlReader:
    """Reads values out of one YAML file, raising errors that name the file and key path, or
    the ``--set`` override a bad value came from."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.overrides: dict[str, str] = {}  # dotted key -> the --set assignment that set it
        self.origins: dict[str, Path] = {}  # dotted key -> the ``base:`` file its value came from
        self.own_leaves: set[str] = set()  # dotted keys the file itself writes

    def error(self, key: str, message: str) -> ConfigError:
        for dotted, assignment in self.overrides.items():
            if key and _related(key, dotted):
                return ConfigError(f"--set {assignment}: {key}: {message}")
        path = next((origin for dotted, origin in self.origins.items() if key and _related(key, dotted)), self.path)
        where = f"{path}: {key}: " if key else f"{path}: "
        return ConfigError(where + message)

    def read_with_bases(self, what: str) -> dict[str, Any]:
        """The file's mapping with its ``base:`` chain merged under it (see :func:`merge_bases`),
        each value its own object (YAML anchors and aliases share one; a ``--set`` changes one)."""
        merged, self.origins = merge_bases(self.path, what)
        raw = load_yaml(self.path, what)
        self.own_leaves = set(_leaves(raw)) if isinstance(raw, Mapping) else set()
        return _unshared(merged)

    def origin(self, dotted: str) -> str:
        """Where the value at ``dotted`` came from: a ``--set`` assignment, a base file or this file."""
        if dotted in self.overrides:
            return f"--set {self.overrides[dotted]}"
        for key, assignment in self.overrides.items():
            if _related(dotted, key):
                return f"--set {assignment}"
        return str(self.origins.get(dotted, self.path))

    def stage_reader(self, name: str, label: str) -> YamlReader:
        """A reader for stage ``name`` (called ``label`` in errors, e.g. ``stage 2 (rotate)``)
        whose errors name the file that last wrote the stage (a base's, when the variant does not
        touch it), or the ``--set`` that set the value."""
        prefix = f"stages.{name}."
        written = [origin for key, origin in self.origins.items() if key.startswith(prefix)]
        own = any(key.startswith(prefix) for key in self.own_leaves)
        reader = YamlReader(self.path if own or not written else written[-1])
        reader.overrides = {f"{label} {key[len(prefix):]}": value for key, value in self.overrides.items()
                            if key.startswith(prefix)}
        return reader

    def set_value(self, raw: dict[str, Any], assignment: str, allowed: tuple[str, ...]) -> None:
        """Apply one ``--set a.b=value`` (value read as YAML) to ``raw``, a mapping whose top keys
        are ``allowed``; in a curriculum, ``stages.NAME.key...`` reaches the stage called NAME."""
        if "=" not in assignment:
            raise ConfigError(f"--set {assignment}: expected key=value, e.g. ppo.learning_rate=3e-4")
        dotted, text = assignment.split("=", 1)
        keys = dotted.strip().split(".")
        self.overrides[".".join(keys)] = assignment
        self.mapping("", {keys[0]: None}, allowed)
        node: Any = raw
        if keys[0] == "stages" and isinstance(raw.get("stages"), list):
            if len(keys) < 3:
                raise ConfigError(f"--set {assignment}: expected stages.NAME.key=value, e.g. "
                                  "stages.hold-rsi.advance.threshold=0.7")
            names = [stage.get("name") for stage in raw["stages"] if isinstance(stage, Mapping)]
            if keys[1] not in names:
                raise ConfigError(f"--set {assignment}: no stage named {keys[1]!r}; stages: {', '.join(map(str, names))}")
            node, keys = raw["stages"][names.index(keys[1])], keys[2:]
        for depth, key in enumerate(keys[:-1]):
            if node.get(key) is None:
                node[key] = {}
            node = node[key]
            if not isinstance(node, dict):
                raise ConfigError(f"--set {assignment}: {'.'.join(keys[:depth + 1])} is not a mapping")
        try:
            node[keys[-1]] = yaml.safe_load(text)
        except yaml.YAMLError as error:
            raise ConfigError(f"--set {assignment}: not a valid YAML value: {error}") from None

    def mapping(self, key: str, value: Any, allowed: Mapping[str, Any] | tuple[str, ...]) -> Mapping[str, Any]:
        from myo_sds.envs.declare import check_keys, split_message

        if value is None:
            return {}
        try:
            check_keys(key, value, tuple(allowed))
        except ValueError as error:
            raise self.error(*split_message(key, str(error))) from None
        return value

    def read(self, key: str, value: Any, parse) -> Any:
        """``parse(key, value)`` (a :mod:`myo_sds.envs.declare` parser), its ``ValueError`` turned into
        this file's ``ConfigError`` at the key it names."""
        from myo_sds.envs.declare import split_message

        try:
            return parse(key, value)
        except ValueError as error:
            raise self.error(*split_message(key, str(error))) from None


def _unshared(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {key: _unshared(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_unshared(item) for item in value]
    return value


def _related(key: str, dotted: str) -> bool:
    return key == dotted or key.startswith(dotted + ".") or dotted.startswith(key + ".")


def _leaves(mapping: Mapping[str, Any], prefix: str = "") -> list[str]:
    """The dotted keys of a mapping's leaves; a curriculum's stages (a list of named stages, or a
    mapping of stage changes by name) count as ``stages.NAME.<key>``."""
    keys = []
    for name, value in mapping.items():
        dotted = f"{prefix}{name}"
        if not prefix and name == "stages" and isinstance(value, list):
            value = {stage.get("name", f"#{i + 1}"): stage for i, stage in enumerate(value) if isinstance(stage, Mapping)}
        keys += _leaves(value, dotted + ".") if isinstance(value, Mapping) and value else [dotted]
    return keys


def _deep_merge(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    merged = dict(base)
    for name, value in over.items():
        if isinstance(value, Mapping) and isinstance(merged.get(name), Mapping):
            merged[name] = _deep_merge(merged[name], value)
        else:
            merged[name] = value
    return merged


PATH_KEYS = ("curriculum", "init_from")  # run-config values that are paths
PLACEMENT = ("after", "before")  # where a stage added by name goes (a curriculum's stage mapping)


def merge_stages(base: Any, over: Any, path: Path, replace: bool = False, base_path: Path | None = None) -> list[Any]:
    """A curriculum variant's ``stages`` over its base's.

    A list is the whole stage order: a listed stage named like a base stage is merged over it
    (key by key, so a partial stage keeps the base stage's other settings), others stand alone.
    A list that leaves out base stages is an error naming them, unless the variant says
    ``replace_stages: true`` (then they are dropped). A mapping changes stages by name and keeps the rest:
    ``NAME: {advance: {threshold: 0.7}}`` merges into that stage, ``NAME: null`` removes it, and a
    new name adds a stage placed with ``after: OTHER`` or ``before: OTHER``; an existing stage
    moves the same way."""
    base = list(base) if isinstance(base, list) else []
    by_name = {stage["name"]: stage for stage in base if isinstance(stage, Mapping) and "name" in stage}
    if isinstance(over, list):
        listed = {stage.get("name") for stage in over if isinstance(stage, Mapping)}
        left_out = [name for name in by_name if name not in listed]
        if left_out and not replace:
            first = next((stage for stage in over if isinstance(stage, Mapping) and stage.get("name")), None)
            changed = ", ".join(f"{k}: ..." for k in first if k != "name") if first else ""
            example = f"{first['name']}: {{{changed or 'advance: ...'}}}" if first else f"{left_out[0]}: null"
            raise ConfigError(
                f"{path}: stages: this list leaves out {', '.join(left_out)} of its base {base_path or 'file'} (a list is "
                f"the whole stage order); to change stages by name and keep the others, write a mapping "
                f"(stages: {{{example}}}), or add replace_stages: true to drop them on purpose")
        return [_deep_merge(by_name[stage["name"]], stage)
                if isinstance(stage, Mapping) and stage.get("name") in by_name else stage for stage in over]
    if not isinstance(over, Mapping):
        raise ConfigError(f"{path}: stages: expected a list of stages or a mapping of changes by stage name, "
                          f"got {type(over).__name__}")
    stages = list(base)
    names = lambda: [stage.get("name") for stage in stages]  # noqa: E731
    for name, change in over.items():
        where = f"{path}: stages.{name}"
        if change is None:
            if name not in names():
                raise ConfigError(f"{where}: null removes a stage, but the base has none of that name; "
                                  f"stages: {', '.join(map(str, names()))}")
            del stages[names().index(name)]
            continue
        if not isinstance(change, Mapping):
            raise ConfigError(f"{where}: expected a mapping of the stage's settings to change, or null to remove it")
        placement = {key: change[key] for key in PLACEMENT if key in change}
        change = {key: value for key, value in change.items() if key not in PLACEMENT}
        if len(placement) > 1:
            raise ConfigError(f"{where}: give after or before, not both")
        if "name" in change and change["name"] != name:
            raise ConfigError(f"{where}.name: a stage changed by name keeps it (got {change['name']!r})")
        if name in names():
            index = names().index(name)
            stage = _deep_merge(stages.pop(index), change)
            if not placement:
                stages.insert(index, stage)
                continue
        elif not placement:
            raise ConfigError(f"{where}: no base stage of that name; to add one, say where with after: NAME or "
                              f"before: NAME; stages: {', '.join(map(str, names()))}")
        else:
            stage = {"name": name, **change}
        (key, anchor), = placement.items()
        if anchor not in names():
            raise ConfigError(f"{where}.{key}: no stage named {anchor!r}; stages: {', '.join(map(str, names()))}")
        stages.insert(names().index(anchor) + (key == "after"), stage)
    return stages


def resolve_base(path: Path, base: str, what: str) -> Path:
    """The file ``base:`` names in ``path``: relative to ``path``'s folder, or, a bare name that is
    no file there, the bundled curriculum (``what == "curriculum"``) or run config of that name."""
    base_path = (path.parent / base).resolve()
    if not base_path.is_file() and "/" not in base:
        from myo_sds import bundled_path

        base_path = bundled_path("curricula" if what == "curriculum" else "configs", base) or base_path
    return base_path


def merge_bases(path: Path, what: str, _seen: tuple[Path, ...] = ()) -> tuple[dict[str, Any], dict[str, Path]]:
    """A YAML mapping with ``base: OTHER.yaml`` (relative to the file; a bare name that is no file
    there names a bundled curriculum or config, e.g. ``base: quickstart.yaml``) read first and this file's
    keys merged over it, mapping by mapping (a value that is not a mapping replaces the base's;
    a curriculum's ``stages`` merge by stage name, :func:`merge_stages`); bases may have bases. A
    relative ``curriculum`` path stays relative to the file that wrote it. Also returns, for each
    dotted key whose value came from a base, that base's path."""
    path = Path(path).resolve()
    raw = load_yaml(path, what)
    if raw is None:
        raw = {}
    if not isinstance(raw, Mapping):
        raise ConfigError(f"{path}: expected a mapping of settings, got {type(raw).__name__}")
    raw = dict(raw)
    for key in PATH_KEYS:  # a relative path stays relative to the file that wrote it
        if isinstance(raw.get(key), str) and not Path(raw[key]).is_absolute():
            raw[key] = str((path.parent / raw[key]).resolve()) if _seen else raw[key]
    base = raw.pop("base", None)
    replace = raw.pop("replace_stages", False)
    if replace not in (True, False):
        raise ConfigError(f"{path}: replace_stages: expected true or false, got {replace!r}")
    if base is None:
        if replace:
            raise ConfigError(f"{path}: replace_stages: only a variant (a file with base:) replaces stages")
        return raw, {}
    if not isinstance(base, str) or not base:
        raise ConfigError(f"{path}: base: expected the path of another {what} file, got {base!r}")
    base_path = resolve_base(path, base, what)
    if base_path in (*_seen, path):
        raise ConfigError(f"{path}: base: {base} leads back to {base_path} (a cycle of bases)")
    if not base_path.is_file():
        raise ConfigError(f"{path}: base: {what} file not found: {base_path}")
    parent, parent_origins = merge_bases(base_path, what, (*_seen, path))
    own = set(_leaves(raw))
    origins = {key: parent_origins.get(key, base_path) for key in _leaves(parent)
               if not any(_related(key, mine) for mine in own)}
    merged = _deep_merge(parent, {k: v for k, v in raw.items() if k != "stages"})
    if "stages" in raw:
        merged["stages"] = merge_stages(parent.get("stages"), raw["stages"], path, replace, base_path)
    return merged, origins


def load_yaml(path: Path, what: str) -> Any:
    if not path.is_file():
        raise ConfigError(f"{path}: {what} file not found")
    try:
        with path.open() as file:
            return yaml.safe_load(file)
    except yaml.YAMLError as error:
        raise ConfigError(f"{path}: not valid YAML: {error}") from None
