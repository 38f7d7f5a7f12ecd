"""The side-by-side table ``evaluate.py`` prints."""

from __future__ import annotations

from collections.abc import Callable, Sequence

from myo_sds.evaluation.episodes import EvaluationReport


def format_table(reports: Sequence[EvaluationReport]) -> str:
    """Side-by-side table, one column per (checkpoint, env)."""
    summaries = [r.summary() for r in reports]
    columns = [f"{r.checkpoint.label} | {r.env.label}" for r in reports]
    directions = sorted({d for s in summaries for d in s["per_direction"]})
    rows = [("episodes", [str(s["episodes"]) for s in summaries]),
            ("score", [f"{s['score']:.3f} [{s['score_ci95'][0]:.3f}, {s['score_ci95'][1]:.3f}]" for s in summaries]),
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
            "per_start_phase", sector, lambda d: f"{d['score']:.3f} (n={d['episodes']}, drops {d['drop_rate']:.0%})")))
    sectors = sorted({k for s in summaries for k in s["per_target_phase"]}, key=lambda k: int(k.split("-")[0]))
    for sector in sectors:
        rows.append((f"solved, targets at {sector} deg", breakdown(
            "per_target_phase", sector, lambda d: f"{d['solved_fraction']:.3f} ({d['steps']} steps)")))
    width = max(len(name) for name, _ in rows)
    col_width = [max(len(c), *(len(cells[i]) for _, cells in rows)) for i, c in enumerate(columns)]
    lines = [" " * width + "  " + "  ".join(c.ljust(w) for c, w in zip(columns, col_width))]
    lines += [name.ljust(width) + "  " + "  ".join(v.ljust(w) for v, w in zip(cells, col_width)) for name, cells in rows]
    starts = {s["env"]: s["start"] for s in summaries if s.get("start")}
    lines += [""] + [f"{env}: {note}" for env, note in starts.items()]
    return "\n".join(lines)
