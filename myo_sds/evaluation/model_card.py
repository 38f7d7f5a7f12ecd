"""The model card (README.md) of an exported model folder: where the policy came from, how long
each stage took on which machine, and how to evaluate or fine-tune it."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from myo_sds.curricula.schema import load_curriculum
from myo_sds.envs.task_specs import TASK_SPECS
from myo_sds.evaluation.summary import RunSummary, stage_rows, summarize
from myo_sds.run_folder import RunFolder


def _stage_table(summary: RunSummary) -> list[str]:
    header, rows = stage_rows(summary)
    return ["| " + " | ".join(row) + " |" for row in (header, tuple("---" for _ in header), *rows)]


def _started_from(folder: RunFolder) -> list[str]:
    """A line naming the trained policy the run started from (``--init-from``), if it did."""
    if not folder.command_file.is_file():
        return []
    words = folder.command_file.read_text().split()
    if "--init-from" not in words[:-1]:
        return []
    source = words[words.index("--init-from") + 1]
    return ["", f"**The run did not start from scratch**: it started from `{source}` (`--init-from`: its "
            "weights, optimizer state and normalization statistics), then trained through the stages below."]


def _final_task(folder: RunFolder) -> str:
    """The preset the run's last stage trains on (what to evaluate it on; its rewards aside, which
    do not change the score); ``p1`` if none matches."""
    curriculum = load_curriculum(folder.curriculum_file)
    knobs = TASK_SPECS[curriculum.task].knobs
    last = curriculum.stages[-1].distribution
    return next((name for name in knobs.PRESETS
                 if replace(knobs.parse(name), reward_weights=last.reward_weights) == last), "p1")


def scores_table(evaluation: dict) -> list[str]:
    """Markdown rows of an ``evaluation.json``: per env and start noise, the score on our env and
    on MyoSuite's, the 95% interval and the drop rate (ours)."""
    rows: dict[tuple[str, float], dict[bool, dict]] = {}
    for report in evaluation["reports"]:
        rows.setdefault((report["env"], report.get("start_noise", 0.0)), {})[report["official_env"]] = report
    lines = ["| env | start noise (rad) | episodes | ours | MyoSuite's | 95% interval | dropped |",
             "|---|---|---|---|---|---|---|"]
    for (env, noise), pair in rows.items():
        ours, theirs = pair.get(False), pair.get(True)
        main = ours or theirs
        low, high = main["score_ci95"]
        lines.append(f"| `{env}` | {noise:g} | {main['episodes']} | {ours['score']:.3f} | " if ours else
                     f"| `{env}` | {noise:g} | {main['episodes']} | - | ")
        lines[-1] += (f"{theirs['score']:.3f} | " if theirs else "- | ") + f"[{low:.3f}, {high:.3f}] | " \
                     f"{main['drop_rate']:.0%} |"
    return lines


def _scores(folder: RunFolder) -> list[str]:
    path = folder.path / "evaluation.json"
    if not path.is_file():
        return []
    evaluation = json.loads(path.read_text())
    numerics = evaluation.get("numerics", {})
    return ["", "## Scores", "", *scores_table(evaluation), "",
            f"Deterministic episodes (`evaluation.json`), numerics `{numerics.get('fingerprint', '?')}` "
            f"({numerics.get('cpu', '?')}): start noise moves every hand joint by up to that much at reset."]


def _fine_tune_line(folder: RunFolder, model_dir: Path) -> str:
    """The fine-tuning command; a policy trained with a privileged critic keeps it (the new
    config must feed its critic the same extra inputs)."""
    from myo_sds.curricula.run_config import load_run_config

    extra = load_run_config(folder.config_file).policy.critic_extra if folder.config_file.is_file() else ()
    keep = f' --set "policy.critic_extra=[{", ".join(extra)}]"' if extra else ""
    return f"python train.py --config configs/<run>.yaml --init-from {model_dir}{keep}   # fine-tune on another curriculum"


def _best_of_stage(folder: RunFolder) -> str:
    """Whether the policy is its stage's best evaluated one (``--export --best``)."""
    state = folder.read_state()
    if state is None or state.best_evaluated_step is None or state.best_evaluated_step != state.num_timesteps:
        return ""
    reward = "" if state.best_evaluated_reward is None else f", return {state.best_evaluated_reward:.0f}"
    return f", the stage's best evaluated policy (score {state.best_evaluated:.3f}{reward})"


def model_card(model_dir: Path, source_run: Path) -> str:
    """The card's Markdown for the exported folder ``model_dir`` of the run ``source_run``."""
    folder = RunFolder(model_dir)
    summary = summarize(model_dir)
    current = next((s for s in summary.stages if s.status == "current"), None)
    where = f"in stage {current.index} ({current.name})" if current else f"run status: {summary.status}"
    lines = [f"# {folder.path.name}",
             "",
             f"RecurrentPPO policy exported from the run `{source_run.name}` at {summary.env_steps:,} env steps "
             f"({summary.wall_s / 3600:.2f} h of training, {where}){_best_of_stage(folder)}, with its optimizer "
             "state, its normalization statistics and its curriculum state.",
             *_started_from(folder),
             *_scores(folder),
             "",
             "## Stages",
             "",
             *_stage_table(summary),
             "",
             "Measured values are the advancement metric over the stage's last window of training "
             "episodes (stochastic actions).",
             "",
             "## Use it",
             "",
             "```bash",
             f"python evaluate.py {model_dir} --env {_final_task(folder)} --official --episodes 200",
             _fine_tune_line(folder, model_dir),
             "```"]
    if folder.command_file.is_file():
        lines += ["", "## How it was trained", "",
                  "Each session of the run (time, first env step, machine) and its command line:", "",
                  "```", folder.command_file.read_text().rstrip(), "```"]
    if folder.versions_file.is_file():
        versions = json.loads(folder.versions_file.read_text())
        lines += ["", "Packages: " + ", ".join(f"{name} {version}" for name, version in versions.items()) + "."]
    return "\n".join(lines) + "\n"


def write_model_card(model_dir: Path, source_run: Path) -> Path:
    path = RunFolder(model_dir).model_card
    path.write_text(model_card(Path(model_dir), Path(source_run)))
    return path
