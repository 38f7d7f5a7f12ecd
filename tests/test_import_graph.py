"""The package's import graph has no cycle, counting imports inside functions too (they hide a
cycle from Python, not from a reader): data flows one way, config -> curriculum -> envs ->
rollouts -> update -> run folder -> evaluation."""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# Installed names of the top-level folders (pyproject.toml's package-dir).
PACKAGES = {"myo_sds": REPO / "myo_sds", "myo_sds.envs": REPO / "envs", "myo_sds.curricula": REPO / "curricula"}


def modules() -> dict[str, Path]:
    found = {}
    for package, folder in PACKAGES.items():
        for path in folder.rglob("*.py"):
            if package == "myo_sds" and path.parent != folder and path.parent.name in ("envs", "curricula"):
                continue
            relative = path.relative_to(folder).with_suffix("")
            parts = [p for p in relative.parts if p != "__init__"]
            found[".".join([package, *parts])] = path
    return found


def import_graph() -> dict[str, set[str]]:
    known = modules()
    graph: dict[str, set[str]] = {name: set() for name in known}
    for name, path in known.items():
        for node in ast.walk(ast.parse(path.read_text())):
            targets = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [node.module] + [f"{node.module}.{alias.name}" for alias in node.names]
            for target in targets:
                if target in known and target != name and not name.startswith(target + "."):
                    # A package's __init__ re-exporting its own modules is not a cycle through them.
                    if not (path.name == "__init__.py" and target.startswith(name + ".")):
                        graph[name].add(target)
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


def test_the_graph_sees_the_package():
    graph = import_graph()
    assert "myo_sds.training.trainer" in graph and "myo_sds.envs.baoding" in graph
    assert "myo_sds.curricula.state" in graph["myo_sds.curricula.advancement"]
    # An import inside a function counts: the worker builds its model through the factory.
    assert "myo_sds.training.factory" in graph["myo_sds.training.rollout_worker"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]


def test_no_import_cycle():
    cycle = find_cycle(import_graph())
    assert cycle is None, " -> ".join(cycle)


# The folders a reader sees, from the bottom layer up: each imports only its own and lower layers.
LAYERS = {"envs": {"envs"}, "curricula": {"envs", "curricula"}, "myo_sds": {"envs", "curricula", "myo_sds"}}


def folder_of(module: str) -> str:
    for package, folder in (("myo_sds.envs", "envs"), ("myo_sds.curricula", "curricula")):
        if module == package or module.startswith(package + "."):
            return folder
    return "myo_sds"


def test_no_folder_imports_a_folder_above_it():
    """envs/ (the tasks) imports nothing of curricula/ or myo_sds/; curricula/ nothing of myo_sds/:
    no folder-level circle, so each layer can be read (and tested) without the ones above it."""
    graph = import_graph()
    crossings = sorted(f"{source} -> {target}" for source, targets in graph.items() for target in targets
                       if folder_of(target) not in LAYERS[folder_of(source)])
    assert crossings == []


def test_no_module_changes_its_search_path():
    for name, path in modules().items():
        assert "__path__" not in path.read_text(), f"{name} ({path}) changes a package's search path"


def test_importing_any_module_sets_no_environment_variable():
    """Only the entry points set the process environment; a library import leaves it alone."""
    import json
    import os
    import subprocess
    import sys

    names = sorted(modules())
    script = (
        "import json, os\n"
        # What the dependencies set on import themselves (gymnasium hides pygame's prompt).
        "import gymnasium, mujoco, numpy, stable_baselines3, sb3_contrib, torch, yaml\n"
        "before = dict(os.environ)\n"
        f"for name in {names!r}:\n"
        "    __import__(name)\n"
        "print(json.dumps({k: v for k, v in os.environ.items() if before.get(k) != v}))\n")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("MUJOCO_GL", "OMP_", "KMP_", "MKL_", "ATEN_"))}
    from myo_sds import process_environment

    for name in process_environment():
        env.pop(name, None)
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, cwd="/",
                         check=True).stdout
    assert json.loads(out.splitlines()[-1]) == {}


def test_no_product_module_is_over_400_lines():
    """Small modules a reader takes in at once (stable-baselines3's are the model)."""
    long = {name: n for name, path in modules().items() if (n := len(path.read_text().splitlines())) > 400}
    assert long == {}
