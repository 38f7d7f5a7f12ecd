"""The README's Results table, made from the model folders' ``evaluation.json`` files.

    python -m myo_sds.evaluation.results_table            # print it
    python -m myo_sds.evaluation.results_table --write    # replace it in README.md

Each ``models/**/evaluation.json`` (as ``evaluate.py MODEL ... --json MODEL/evaluation.json``
writes it) gives one row: the official score with its 95% interval and the share of dropped
episodes on each evaluated env, without and with start noise, and whether our env and MyoSuite's
gave the same score. The README holds the table between two marker lines; a test checks that it
matches the files.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

BEGIN = "<!-- results table: made by `python -m myo_sds.evaluation.results_table --write` from models/*/evaluation.json -->"
END = "<!-- end of results table -->"
# Columns: (env, start noise); a model folder's reports fill the ones it was evaluated on.
COLUMNS = (("p1_2022", 0.0), ("p1_2022", 0.02), ("p1", 0.0), ("p1", 0.02))


def _cell(report: dict) -> str:
    low, high = report["score_ci95"]
    interval = f" [{low:.3f}, {high:.3f}]" if f"{low:.3f}" != f"{high:.3f}" else ""  # none: one episode replayed
    return f"{report['score']:.3f}{interval}, {report['drop_rate']:.0%} dropped"


def _task(reports: list[dict]) -> str:
    for report in reports:
        for episode in report.get("per_episode", [])[:1]:
            return episode.get("task") or "baoding"
    return "baoding"


def table_rows(models: Path) -> list[str]:
    """The table's lines for every model folder under ``models`` that has an evaluation.json."""
    header = ["policy", "task", *(f"`{env}`" + (f" +-{noise:g}" if noise else "") for env, noise in COLUMNS),
              "episodes", "ours = MyoSuite's"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for path in sorted(models.rglob("evaluation.json")):
        reports = json.loads(path.read_text())["reports"]
        ours = {(r["env"], float(r["start_noise"])): r for r in reports if not r["official_env"]}
        official = {(r["env"], float(r["start_noise"])): r for r in reports if r["official_env"]}
        cells = [_cell(ours[key]) if key in ours else "" for key in COLUMNS]
        compared = [key for key in ours if key in official]
        same = all(ours[k]["score"] == official[k]["score"] for k in compared)
        agree = "not run" if not compared else ("yes" if same else "no: " + ", ".join(
            f"{env} {noise:g}: {official[(env, noise)]['score']:.3f}" for env, noise in compared
            if ours[(env, noise)]["score"] != official[(env, noise)]["score"]))
        episodes = ", ".join(sorted({str(r["episodes"]) for r in reports}))
        folder = path.parent.relative_to(models.parent)
        lines.append("| " + " | ".join([f"`{folder}`", _task(reports), *cells, episodes, agree]) + " |")
    return lines


def replace_table(readme: str, lines: list[str]) -> str:
    """``readme`` with the text between the markers replaced by ``lines``."""
    if BEGIN not in readme or END not in readme:
        raise ValueError(f"the README has no results table markers ({BEGIN!r} ... {END!r})")
    before, rest = readme.split(BEGIN, 1)
    _, after = rest.split(END, 1)
    return before + BEGIN + "\n" + "\n".join(lines) + "\n" + END + after


def main(argv: list[str] | None = None) -> int:
    repo = Path(__file__).resolve().parents[2]
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", type=Path, default=repo / "models", help="the folder of model folders")
    parser.add_argument("--readme", type=Path, default=repo / "README.md")
    parser.add_argument("--write", action="store_true", help="replace the table in --readme")
    args = parser.parse_args(argv)
    lines = table_rows(args.models)
    if not args.write:
        print("\n".join(lines))
        return 0
    try:
        args.readme.write_text(replace_table(args.readme.read_text(), lines))
    except ValueError as error:
        print(f"error: {args.readme}: {error}", file=sys.stderr)
        return 2
    print(f"wrote the results table ({len(lines) - 2} policies) into {args.readme}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
