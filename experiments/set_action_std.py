"""Widen (or narrow) a run's action noise at its newest checkpoint, for a branch that explores more.

    python experiments/set_action_std.py ~/runs/BRANCH --mean 0.08

Multiplies every action dimension's std by one factor, so that their mean becomes ``--mean``
(the relative noise between muscles is kept), in the newest checkpoint's model file, in place.
Resume the branch with ``train.py --resume``. Use it on a copy of a run folder: the checkpoint's
original std is printed, not kept.

Why: the 2022 winner's policy kept a mean std of 0.089 -> 0.072 through its rotation and fixed-start
stages (their TensorBoard, ``winner_2022/training.csv``); ours had fallen to 0.067 by 11M env
steps and 0.058 by 25.9M (experiments/RESULTS.md, session of 2026-12-07 (II)).
"""

from __future__ import annotations

import argparse
import io
import math
import shutil
import tempfile
import zipfile
from pathlib import Path

import torch

from myo_sds.run_folder import RunFolder


def rescale_log_std(model_zip: Path, target_mean: float) -> tuple[float, float]:
    """Rewrite ``model_zip`` with its policy's std scaled to mean ``target_mean``; returns the
    (old, new) mean std."""
    with zipfile.ZipFile(model_zip) as archive:
        members = {info.filename: archive.read(info.filename) for info in archive.infolist()}
    policy = torch.load(io.BytesIO(members["policy.pth"]), map_location="cpu")
    old_mean = float(policy["log_std"].exp().mean())
    policy["log_std"] = policy["log_std"] + math.log(target_mean / old_mean)
    buffer = io.BytesIO()
    torch.save(policy, buffer)
    members["policy.pth"] = buffer.getvalue()
    with tempfile.NamedTemporaryFile(dir=model_zip.parent, suffix=".zip", delete=False) as file:
        with zipfile.ZipFile(file, "w", compression=zipfile.ZIP_DEFLATED) as archive:
            for name, data in members.items():
                archive.writestr(name, data)
    shutil.move(file.name, model_zip)
    return old_mean, float(policy["log_std"].exp().mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", type=Path, help="a run folder (a copy: its newest checkpoint is changed in place)")
    parser.add_argument("--mean", type=float, required=True, help="the mean action std to set")
    args = parser.parse_args()
    if not args.mean > 0:
        parser.error(f"--mean must be positive, got {args.mean}")
    checkpoint = RunFolder(args.run).latest_checkpoint()
    if checkpoint is None:
        parser.error(f"{args.run} has no complete checkpoint")
    old, new = rescale_log_std(checkpoint.model, args.mean)
    print(f"{checkpoint.model}: mean action std {old:.4f} -> {new:.4f}")


if __name__ == "__main__":
    main()
