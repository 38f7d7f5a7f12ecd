"""The side-by-side table ``evaluate.py`` prints: one block per checkpoint, one column per env,
columns wrapped so no line is wider than the terminal's usual 120 characters."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from myo_sds.evaluation.episodes import EvaluationReport

TABLE_WIDTH = 120


def _rows(summaries: list[dict[str, Any]]) -> list[tuple[str, list[str]]]:
    directions = sorted({d for s in summaries for d in s["per_direction"]})
    rows = [("episodes", [str(s["episodes"]) for s in summaries]),
            ("score", [f"{s['score']:.3f} [{s['score_ci95'][0]:.3f}, {s['score_ci95'][1]:.3f}]" for s in summaries]),
            ("score std [min, max]", [f"{s['score_spread']['std']:.3f} [{s['score_spread']['min']:.3f}, "
                                      f"{s['score_spread']['max']:.3f}]" if s["score_spread"] else "-"
                                      for s in summaries]),
            ("effort", [f"{s['effort']:.4f}" for s in summaries]),
            ("drop rate", [f"{s['drop_rate']:.3f}" for s in summaries]),
            ("mean length", [f"{s['mean_length']:.1f}" for s in summaries])]

    def breakdown(key: str, group: str, text: Callable[[dict], str]) -> list[str]:
        return [text(s[key][group]) if group in s[key] else "-" for s in summaries]

    for direction in directions:
        rows.append((f"score {direction}",
                     breakdown("per_direction", direction, lambda d: f"{d['score']:.3f} (n={d['episodes']})")))
    sectors = sorted({k for s in summaries for k in s["per_start_phase"]}, key=lambda k: int(k.split("-")[0]))
    for sector in sectors:
        rows.append((f"score, start {sector} deg", breakdown(
            "per_start_phase", sector, _sector_cell)))
    sectors = sorted({k for s in summaries for k in s["per_target_phase"]}, key=lambda k: int(k.split("-")[0]))
    for sector in sectors:
        rows.append((f"solved, targets at {sector} deg", breakdown(
            "per_target_phase", sector, lambda d: f"{d['solved_fraction']:.3f} ({d['steps']} steps)")))
    return rows


def _block(columns: list[str], rows: list[tuple[str, list[str]]], width: int) -> list[str]:
    """The rows under ``columns``, the columns split into as many blocks as ``width`` needs."""
    name_width = max(len(name) for name, _ in rows)
    col_width = [max(len(c), *(len(cells[i]) for _, cells in rows)) for i, c in enumerate(columns)]
    groups: list[list[int]] = [[]]
    used = name_width
    for i, w in enumerate(col_width):
        if groups[-1] and used + 2 + w > width:
            groups.append([])
            used = name_width
        groups[-1].append(i)
        used += 2 + w
    lines: list[str] = []
    for group in groups:
        if lines:
            lines.append("")
        lines.append((" " * name_width + "  " + "  ".join(columns[i].ljust(col_width[i]) for i in group)).rstrip())
        lines += [(name.ljust(name_width) + "  " + "  ".join(cells[i].ljust(col_width[i]) for i in group)).rstrip()
                  for name, cells in rows]
    return lines


def format_table(reports: Sequence[EvaluationReport], width: int = TABLE_WIDTH) -> str:
    """One block per checkpoint (its label as a heading), one column per env it was evaluated on."""
    lines: list[str] = []
    labels = list(dict.fromkeys(r.checkpoint.label for r in reports))
    for label in labels:
        mine = [r for r in reports if r.checkpoint.label == label]
        summaries = [r.summary() for r in mine]
        if lines:
            lines.append("")
        lines.append(f"== {label}")
        lines += _block([r.env.label for r in mine], _rows(summaries), width)
    summaries = [r.summary() for r in reports]
    starts = {s["env"]: s["start"] for s in summaries if s.get("start")}
    lines += [""] + [f"{env}: {note}" for env, note in starts.items()]
    # What "start A-B deg" measures differs by task: say it when the table splits by it.
    measures = dict.fromkeys(s["per_start_phase_of"] for s in summaries if s["per_start_phase_of"] and s["per_start_phase"])
    lines += [f"start A-B deg: {', '.join(measures)}"] if measures else []
    return "\n".join(lines)


def _sector_cell(sector: dict[str, Any]) -> str:
    step = sector.get("drop_step")  # evaluation.json files written before it was recorded lack it
    at = "" if step is None else f" at step {step:.0f}"
    return f"{sector['score']:.3f} (n={sector['episodes']}, drops {sector['drop_rate']:.0%}{at})"
