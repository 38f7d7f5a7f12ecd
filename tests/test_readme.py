"""The README says what the files and commands do: its results table is the model folders'
evaluation.json, its curriculum example runs as printed from another folder, and it stays short."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from myo_sds.evaluation.results_table import BEGIN, END, table_rows

REPO = Path(__file__).resolve().parents[1]
README = (REPO / "README.md").read_text()


def test_the_results_table_is_the_model_folders_evaluations():
    written = README.split(BEGIN, 1)[1].split(END, 1)[0].strip().splitlines()
    assert written == table_rows(REPO / "models"), "run: python -m myo_sds.evaluation.results_table --write"
    assert len(written) <= 30
    # Every shipped model folder with a policy has an evaluation behind its row.
    shipped = {p.parent for p in (REPO / "models").rglob("*.zip")}
    assert shipped == {p.parent for p in (REPO / "models").rglob("evaluation.json")}


def test_the_readme_is_documentation_of_at_most_160_lines_with_the_essentials_first():
    lines = README.splitlines()
    assert len(lines) <= 160
    first = "\n".join(lines[:80])
    for heading in ("## Two commands", "## Train", "## Evaluate", "## Write and run your own curriculum"):
        assert heading in first, heading
    for target in ("demo:", "test:"):
        assert re.search(rf"^{target}", (REPO / "Makefile").read_text(), re.M), target


@pytest.mark.slow
def test_the_readme_s_curriculum_example_runs_as_printed_from_another_folder(tmp_path):
    section = README.split("## Write and run your own curriculum", 1)[1]
    example = re.search(r"```yaml\n(.*?)```", section, re.S).group(1)
    name = re.search(r"as\s+`(\S+\.yaml)`", section).group(1)
    assert f"--config {name}" in section
    (tmp_path / name).write_text(example)  # as printed: its base is a bundled curriculum by name
    assert len(example.strip().splitlines()) == 3
    done = subprocess.run([sys.executable, str(REPO / "train.py"), "--config", name, "--set", "total_steps=1024",
                           "--run-dir", "run", "--no-progress"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    curriculum = yaml.safe_load((tmp_path / "run" / "curriculum.yaml").read_text())
    stages = {stage["name"]: stage for stage in curriculum["stages"]}
    assert list(stages) == ["p1-noise", "p1-noise-better"]  # the base's other stage kept
    assert stages["p1-noise"]["advance"]["threshold"] == 0.1
    config = yaml.safe_load((tmp_path / "run" / "config.yaml").read_text())
    assert Path(config["init_from"]).resolve() == (REPO / "models" / "baoding_p1_2022").resolve()  # quickstart's
