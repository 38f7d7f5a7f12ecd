"""Extract the 2022 Baoding winner's chain (team stiff_fingers) into small CSV files: the yardstick
our runs of `configs/baoding_sds.yaml` are judged against.

Source: github amathislab/myochallenge (MIT licence, LICENSE beside this file),
`trained_models/curriculum_steps_complete_baoding_winner/`: per stage `config.json` (the env's
settings), `evaluations.npz` (SB3's EvalCallback: deterministic episodes on the stage's own env;
the best one's model started the next stage) and TensorBoard events (training episode means and
the PPO settings the stage ran with). Writes, beside this file:

- `stages.csv`: per stage its env settings, env steps, PPO settings and evaluation first/best/last;
- `evaluations.csv`: every evaluation (stage, env step in the stage, mean/std/min/max return, mean
  episode length);
- `training.csv`: the training episodes' mean return and length (SB3's 100-episode window), the
  action std and the update's approximate KL and clip fraction, every ~40k env steps.

    python experiments/winner_2022/extract.py /work/.mirror/amathislab+myochallenge/repo
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import subprocess
import tempfile
from pathlib import Path

import numpy as np

CHAIN = "trained_models/curriculum_steps_complete_baoding_winner"
HERE = Path(__file__).resolve().parent
STAGES_OF_PHASE_1 = 12  # stages 01-12: hold, rotation from random phases, then the fixed 2022 start
TRAINING_EVERY = 40_000  # env steps between the rows of training.csv


def _git_show(repo: Path, path: str) -> bytes:
    return subprocess.run(["git", "--git-dir", str(repo), "show", f"HEAD:{path}"], check=True,
                          capture_output=True).stdout


def _git_ls(repo: Path, path: str) -> list[str]:
    out = subprocess.run(["git", "--git-dir", str(repo), "ls-tree", "--name-only", f"HEAD:{path}"], check=True,
                         capture_output=True, text=True).stdout
    return out.split()


def _events(data: bytes) -> dict[str, list[tuple[int, float]]]:
    from tensorboard.backend.event_processing import event_file_loader

    with tempfile.NamedTemporaryFile(suffix=".tfevents") as file:
        file.write(data)
        file.flush()
        scalars: dict[str, list[tuple[int, float]]] = {}
        for event in event_file_loader.EventFileLoader(file.name).Load():
            for value in event.summary.value:  # the loader turns simple values into scalar tensors
                number = value.simple_value if value.HasField("simple_value") else (
                    value.tensor.float_val[0] if value.tensor.float_val else None)
                if number is not None:
                    scalars.setdefault(value.tag, []).append((event.step, number))
    return scalars


def _period(config: dict) -> str:
    low, high = config["goal_time_period"]
    if low >= 1e99:
        return "static"
    return f"{low:g}" if low == high else f"{low:g}-{high:g}"


def _start(config: dict) -> str:
    if config.get("enable_rsi"):
        p = config.get("rsi_probability", 1)
        return "random phase; balls on targets" if p >= 1 else f"random phase; balls on targets w.p. {p:g}"
    return "the 2022 start (targets on the resting balls)"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("repo", type=Path, help="the git directory of an amathislab/myochallenge clone")
    parser.add_argument("--stages", type=int, default=STAGES_OF_PHASE_1, help="the first N stages")
    args = parser.parse_args()
    commit = subprocess.run(["git", "--git-dir", str(args.repo), "rev-parse", "HEAD"], check=True,
                            capture_output=True, text=True).stdout.strip()
    stage_rows, eval_rows, train_rows = [], [], []
    for number, folder in enumerate(sorted(_git_ls(args.repo, CHAIN))[:args.stages], start=1):
        base = f"{CHAIN}/{folder}"
        config = json.loads(_git_show(args.repo, f"{base}/config.json"))
        evaluations = np.load(io.BytesIO(_git_show(args.repo, f"{base}/evaluations.npz")))
        steps, returns = evaluations["timesteps"], evaluations["results"]
        lengths = evaluations["ep_lengths"]
        means = returns.mean(axis=1)
        events_dir = f"{base}/RecurrentPPO_1"
        scalars = _events(_git_show(args.repo, f"{events_dir}/{_git_ls(args.repo, events_dir)[0]}"))
        rollouts = [step for step, _ in scalars["rollout/ep_rew_mean"]]
        weights = config["weighted_reward_keys"]
        stage_rows.append({
            "stage": number, "folder": folder, "direction": config.get("task") or "hold",
            "period_s": _period(config), "start": _start(config),
            "rsi_probability": config.get("rsi_probability", 1) if config.get("enable_rsi") else 0,
            "drop_height": config.get("drop_th", 1.25),
            "reward_weights": " ".join(f"{k}={v}" for k, v in weights.items() if v),
            "env_steps": int(rollouts[-1]),
            "rollout_steps": int(rollouts[1] - rollouts[0]),
            "learning_rate": f"{scalars['train/learning_rate'][-1][1]:.4g}",
            "clip_range": f"{scalars['train/clip_range'][-1][1]:.3g}",
            "eval_every": int(steps[1] - steps[0]), "eval_episodes": returns.shape[1],
            "eval_first": round(float(means[0]), 1), "eval_best": round(float(means.max()), 1),
            "eval_best_at": int(steps[means.argmax()]), "eval_last": round(float(means[-1]), 1),
        })
        for step, row, length in zip(steps, returns, lengths):
            eval_rows.append({"stage": number, "step": int(step), "mean_return": round(float(row.mean()), 2),
                              "std_return": round(float(row.std()), 2), "min_return": round(float(row.min()), 2),
                              "max_return": round(float(row.max()), 2),
                              "mean_length": round(float(length.mean()), 1)})
        series = {key: dict(scalars[key]) for key in ("rollout/ep_rew_mean", "rollout/ep_len_mean", "train/std",
                                                      "train/approx_kl", "train/clip_fraction") if key in scalars}
        next_row = 0
        for step in rollouts:
            if step < next_row:
                continue
            next_row = step + TRAINING_EVERY
            row = {"stage": number, "step": int(step)}
            for key, values in series.items():
                value = values.get(step)
                row[key.split("/")[1]] = "" if value is None else f"{value:.5g}"
            train_rows.append(row)
    for name, rows in (("stages.csv", stage_rows), ("evaluations.csv", eval_rows), ("training.csv", train_rows)):
        with (HERE / name).open("w", newline="") as file:
            writer = csv.DictWriter(file, fieldnames=list({k: None for row in rows for k in row}))
            writer.writeheader()
            writer.writerows(rows)
    (HERE / "source.json").write_text(json.dumps({
        "repository": "https://github.com/amathislab/myochallenge", "commit": commit, "path": CHAIN,
        "licence": "MIT (LICENSE)", "stages": len(stage_rows)}, indent=2) + "\n")
    print(f"{len(stage_rows)} stages, {len(eval_rows)} evaluations, {len(train_rows)} training rows from {commit[:12]}")


if __name__ == "__main__":
    main()
