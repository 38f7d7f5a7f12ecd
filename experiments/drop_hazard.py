"""Where on the orbit a Baoding run's training episodes lose the balls, by direction.

From a run folder's ``episodes.csv`` alone: for each stage with a fixed period, the episodes
placed on their targets (and separately those begun from rest), the steps they spent with the
targets in each 45-degree sector of the orbit and the drops that happened there, as drops per
1,000 steps (the hazard). A policy that cannot carry the balls through one part of the orbit in
one direction shows a high hazard there for that direction only; one that cannot hold a
placement shows it in every direction, hold included.

    python experiments/drop_hazard.py ~/runs/baoding_sds-s0 [--stages rotate-30s rotate-25s] [--last 8000]
"""

from __future__ import annotations

import argparse
import csv
import math
from collections import Counter
from pathlib import Path

from myo_sds.curricula.run_config import load_run_config
from myo_sds.run_folder import RunFolder

CONTROL_DT = 0.025  # s per env step of the Baoding env (2.5 ms x 10 substeps; BaodingEnv().dt)
SIGN = {"ccw": 1, "cw": -1, "hold": 0}
SECTORS = 8


def sector(angle: float) -> int:
    return int(math.degrees(angle) % 360 // (360 / SECTORS))


def hazard(episodes: list[dict], periods: dict[str, float]) -> dict[str, tuple[Counter, Counter]]:
    """Per direction: steps spent with the targets in each sector, and drops in each sector."""
    table: dict[str, tuple[Counter, Counter]] = {d: (Counter(), Counter()) for d in SIGN}
    for row in episodes:
        direction, length = row["direction"], int(row["length"])
        speed = SIGN[direction] * 2 * math.pi * CONTROL_DT / periods[row["stage"]]
        start = float(row["start_phase"])
        steps, drops = table[direction]
        for step in range(length):
            steps[sector(start + speed * step)] += 1
        if row["dropped"] == "1":
            drops[sector(start + speed * length)] += 1
    return table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--stages", nargs="*", help="stage names (default: every stage with a fixed period)")
    parser.add_argument("--last", type=int, default=8000, help="the newest N episodes of each kind")
    args = parser.parse_args()

    run = RunFolder.require(args.run)
    stages = load_run_config(run.config_file).curriculum.stages
    periods = {}  # stage -> its one period (hold stages: any; ranges of periods are left out)
    for stage in stages:
        period = stage.distribution.period
        if period is None or stage.distribution.direction == "hold":
            periods[stage.name] = math.inf
        elif period.low == period.high:
            periods[stage.name] = period.low
    wanted = set(args.stages or periods)
    unknown = wanted - {s.name for s in stages}
    if unknown:
        raise SystemExit(f"error: no stage {sorted(unknown)} in {run.config_file}; stages: {[s.name for s in stages]}")
    with open(run.path / "episodes.csv", newline="") as file:
        rows = [r for r in csv.DictReader(file) if r["stage"] in wanted and r["stage"] in periods and r["direction"]]
    header = " ".join(f"{i * 45:>3}-{i * 45 + 45:<3}" for i in range(SECTORS))
    for kind in ("on_targets", "rest"):
        chosen = [r for r in rows if r["start"] == kind][-args.last:]
        if not chosen:
            continue
        stage_names = sorted({r["stage"] for r in chosen}, key=[s.name for s in stages].index)
        print(f"{kind}: {len(chosen)} episodes ({', '.join(stage_names)}); drops per 1,000 steps with the "
              f"targets in each sector (steps in thousands)")
        print(f"  {'':<5} {header}")
        for direction, (steps, drops) in hazard(chosen, periods).items():
            if steps:
                print(f"  {direction:<5} " + " ".join(f"{1000 * drops[i] / steps[i]:7.2f}" if steps[i] else "      -"
                                                      for i in range(SECTORS)))
                print(f"  {'':<5} " + " ".join(f"{steps[i] / 1000:7.1f}" for i in range(SECTORS)))


if __name__ == "__main__":
    main()
