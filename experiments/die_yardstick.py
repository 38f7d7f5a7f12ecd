"""A die policy of ours beside PKU-MARL's 2022 phase-1 policy, episode for episode.

    python experiments/die_yardstick.py PATH/best_policy.pickle models/die_p1 --episodes 100 \\
        [--envs ours,official] [--actions mean,sampled] [--json out.json]

Each POLICY is one of ours (a model or run folder, or a checkpoint) or a PKU-MARL policy pickle
(``eval/agent/policies/die/best_policy.pickle`` of github PKU-MARL/MyoChallenge; commit cb992b2 is
their last phase-1 state). That repository has no licence: fetch the file yourself; nothing of it
is kept here. The pickle is read **without executing it**: a restricted unpickler allows only the
tensor and array constructors and records mjrl's and torch's module classes as plain attribute
holders, from which the 102-64-64-39 tanh MLP and its per-muscle log std are read.

Every policy plays the same seeds on our env and/or MyoSuite's (``myoChallengeDieReorientP1-v0``),
with its mean action and/or sampled actions (PKU-MARL's submission sampled: ``pi.get_action(obs)[0]``
is the mean plus its noise). Reported per run: the official score (solved on more than 5 steps)
with its 95% interval, drops, the score by the goal's angle from the die at the start (45-degree
bins), turns (the orientation error fell by more than 45 degrees during the episode), strokes
per episode and where the second began (``die_turns.py``'s stroke rule), and ``die_turns.py``'s
15-degree table; with two or more policies on the same env and action mode, how their episodes
agree (both solved, only one, neither).
"""

from __future__ import annotations

from myo_sds import set_process_environment

set_process_environment()  # before NumPy, torch and MuJoCo load: pinned kernels, short OpenMP spins

import argparse
import io
import json
import math
import pickle
import sys
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from die_turns import TurnRecord, print_turn_table, turn_record  # noqa: E402

from myo_sds.envs.metrics import mean_confidence_interval  # noqa: E402

ANGLE_BINS_DEG = (0, 45, 90, 135, 180)
TURNED_DEG = 45.0


# --- PKU-MARL's mjrl policy, read without executing the pickle --------------------------------

class _Record:
    """Stands in for every class the pickle names (mjrl's MLP and FCNetwork, torch's modules):
    it keeps the state the pickle sets and runs no code of theirs."""

    def __init__(self, *args, **kwargs):
        self.args = args

    def __setstate__(self, state):
        if isinstance(state, tuple):  # (dict, slots)
            state = {k: v for part in state if isinstance(part, dict) for k, v in part.items()}
        self.__dict__.update(state)

    def __getattr__(self, name: str):
        # A torch module keeps its submodules and parameters in these dicts of its state.
        for holder in ("_modules", "_parameters", "_buffers"):
            values = self.__dict__.get(holder) or {}
            if name in values:
                return values[name]
        raise AttributeError(name)


class _TorchFunction:
    """``getattr(torch._C._VariableFunctionsClass, name)``: the network's nonlinearity, by name only."""

    def __init__(self, name: str = ""):
        self.name = name


def _load_storage(data: bytes):
    return torch.load(io.BytesIO(data), weights_only=True)  # the tensor's bytes, as plain data


def _safe_getattr(owner, name: str):
    if owner is _TorchFunction and name in ("tanh", "relu"):
        return _TorchFunction(name)
    raise pickle.UnpicklingError(f"getattr({owner!r}, {name!r}) is not allowed")


class RestrictedUnpickler(pickle.Unpickler):
    """Only data constructors; every module class becomes a :class:`_Record`."""

    DATA = {("collections", "OrderedDict"), ("torch._utils", "_rebuild_parameter"),
            ("torch._utils", "_rebuild_tensor_v2"), ("numpy.core.multiarray", "_reconstruct"),
            ("numpy._core.multiarray", "_reconstruct"), ("numpy", "ndarray"), ("numpy", "dtype"),
            ("numpy.core.multiarray", "scalar"), ("numpy._core.multiarray", "scalar")}
    RECORDED = ("mjrl.", "torch.nn.modules.")

    def find_class(self, module: str, name: str):
        if (module, name) in self.DATA:
            if module.startswith("numpy.core"):  # NumPy 2 moved numpy.core to numpy._core
                module = module.replace("numpy.core", "numpy._core")
            return getattr(sys.modules.get(module) or __import__(module, fromlist=[name]), name)
        if module == "torch.storage" and name == "_load_from_bytes":
            return _load_storage
        if (module, name) == ("torch._C", "_VariableFunctionsClass"):
            return _TorchFunction
        if (module, name) == ("builtins", "getattr"):
            return _safe_getattr
        if module.startswith(self.RECORDED):
            return type(name, (_Record,), {"__module__": "recorded." + module})
        raise pickle.UnpicklingError(f"{module}.{name} is not allowed in a policy pickle")


class PkuPolicy:
    """PKU-MARL's mjrl Gaussian MLP: ``mean = W3 f(W2 f(W1 (x - s) / c))`` (f: tanh), std per muscle."""

    def __init__(self, path: Path, sampled: bool, seed: int = 0):
        with path.open("rb") as file:
            record = RestrictedUnpickler(file).load()
        network = record.model
        linear = list(network.fc_layers._modules.values())
        self.weights = [(layer.weight.detach().double().numpy(), layer.bias.detach().double().numpy())
                        for layer in linear]
        self.in_shift = np.asarray(network.in_shift, dtype=np.float64)
        self.in_scale = np.asarray(network.in_scale, dtype=np.float64)
        self.out_shift = np.asarray(network.out_shift, dtype=np.float64)
        self.out_scale = np.asarray(network.out_scale, dtype=np.float64)
        self.nonlinearity = np.tanh if getattr(network.nonlinearity, "name", "tanh") == "tanh" else (
            lambda x: np.maximum(x, 0.0))
        self.std = np.exp(np.asarray(record.log_std_val, dtype=np.float64))
        self.sampled, self.rng = sampled, np.random.default_rng(seed)
        self.label = f"PKU-MARL {path.name} ({'sampled' if sampled else 'mean'})"

    def mean(self, obs: np.ndarray) -> np.ndarray:
        out = (np.float32(obs).astype(np.float64) - self.in_shift) / (self.in_scale + 1e-8)
        for weight, bias in self.weights[:-1]:
            out = self.nonlinearity(out @ weight.T + bias)
        weight, bias = self.weights[-1]
        return (out @ weight.T + bias) * self.out_scale + self.out_shift

    def act(self, obs, state, episode_start):
        mean = self.mean(obs)
        return (mean + self.std * self.rng.standard_normal(len(mean)) if self.sampled else mean), state


def ours(target: str, sampled: bool, seed: int = 0):
    """One of our policies as an ``act`` callable, mean or sampled actions."""
    from myo_sds.evaluation.checkpoints import load_policy, resolve_checkpoint

    ref = resolve_checkpoint(target)
    policy = load_policy(ref, "die")
    torch.manual_seed(seed)

    class Ours:
        label = f"{ref.label} ({'sampled' if sampled else 'mean'})"

        @staticmethod
        def act(obs, state, episode_start):
            batch = obs[None]
            full = policy.model.observation_space.shape[0]
            if batch.shape[1] < full:
                batch = np.concatenate([batch, np.zeros((1, full - batch.shape[1]), batch.dtype)], axis=1)
            if policy.normalizer is not None:
                batch = policy.normalizer.normalize_obs(batch)
            action, state = policy.model.predict(batch, state=state, episode_start=np.array([episode_start]),
                                                 deterministic=not sampled)
            return action[0], state

    return Ours


def make_die_env(official: bool):
    if official:
        import gymnasium as gym
        import myosuite  # noqa: F401  (registers the official ids)

        return gym.make("myoChallengeDieReorientP1-v0")
    from myo_sds.envs.die import DieEnv

    return DieEnv("p1")


def summarize(rows: list[TurnRecord]) -> dict:
    score, low, high = mean_confidence_interval([r.score for r in rows])
    angles = np.degrees([r.start_error for r in rows])
    by_angle = {}
    for a, b in zip(ANGLE_BINS_DEG[:-1], ANGLE_BINS_DEG[1:]):
        group = [r for r, angle in zip(rows, angles) if a <= angle < b]
        if group:
            by_angle[f"{a}-{b}"] = {"episodes": len(group), "score": float(np.mean([r.score for r in group]))}
    turned = [math.degrees(r.start_error - r.smallest_error) > TURNED_DEG for r in rows]
    second = [r.second_stroke_at for r in rows if r.second_stroke_at is not None]
    return {"episodes": len(rows), "score": score, "ci95": [low, high],
            "dropped": float(np.mean([r.dropped for r in rows])), "by_goal_angle": by_angle,
            "turned_past_45deg": float(np.mean(turned)), "strokes_per_episode": float(np.mean([r.strokes for r in rows])),
            "episodes_with_a_second_stroke": float(np.mean([r.strokes > 1 for r in rows])),
            "second_stroke_median_step": float(np.median(second)) if second else None}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("policies", nargs="+", help="PKU-MARL .pickle files and/or our model folders, runs, checkpoints")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0, help="episode i is reset with seed + i")
    parser.add_argument("--envs", default="ours,official", help="ours, official or both")
    parser.add_argument("--actions", default="mean,sampled", help="mean, sampled or both")
    parser.add_argument("--at-step", type=int, default=64, help="die_turns.py's error at this step")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    envs, actions = args.envs.split(","), args.actions.split(",")
    if bad := [e for e in envs if e not in ("ours", "official")]:
        parser.error(f"--envs: {', '.join(bad)}: allowed ours, official")
    if bad := [a for a in actions if a not in ("mean", "sampled")]:
        parser.error(f"--actions: {', '.join(bad)}: allowed mean, sampled")
    for target in args.policies:
        if not Path(target).exists():
            parser.error(f"{target}: no such file or folder")

    def build(target: str, sampled: bool):
        if target.endswith(".pickle"):
            return PkuPolicy(Path(target), sampled, args.seed)
        return ours(target, sampled, args.seed)

    report: dict[str, dict] = {}
    for env_name in envs:
        env = make_die_env(env_name == "official")
        for mode in actions:
            results: dict[str, list[TurnRecord]] = {}
            for target in args.policies:
                policy = build(target, mode == "sampled")
                act: Callable = policy.act
                rows = [turn_record(env, act, args.seed + i, args.at_step) for i in range(args.episodes)]
                results[policy.label] = rows
                summary = summarize(rows)
                report[f"{env_name}/{policy.label}"] = {**summary, "per_episode": [asdict(r) for r in rows]}
                print(f"\n== {policy.label} on {env_name} env, {args.episodes} P1 episodes: score {summary['score']:.3f} "
                      f"[{summary['ci95'][0]:.3f}, {summary['ci95'][1]:.3f}], dropped {summary['dropped']:.0%}, "
                      f"turned past 45 deg {summary['turned_past_45deg']:.0%}, strokes {summary['strokes_per_episode']:.2f}"
                      f" (a second in {summary['episodes_with_a_second_stroke']:.0%}, median step "
                      f"{summary['second_stroke_median_step']})")
                print("   by goal angle: " + ", ".join(f"{k} deg {v['score']:.2f} (n={v['episodes']})"
                                                     for k, v in summary["by_goal_angle"].items()))
                print_turn_table(rows, args.at_step)
            labels = list(results)
            for i, a in enumerate(labels):
                for b in labels[i + 1:]:
                    pairs = [(x.score > 0, y.score > 0) for x, y in zip(results[a], results[b])]
                    counts = {k: sum(p == k for p in pairs) for k in ((True, True), (True, False), (False, True),
                                                                      (False, False))}
                    print(f"\n{a} vs {b} ({env_name}): both solved {counts[(True, True)]}, only the first "
                          f"{counts[(True, False)]}, only the second {counts[(False, True)]}, neither {counts[(False, False)]}")
        env.close()
    if args.json:
        args.json.write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
