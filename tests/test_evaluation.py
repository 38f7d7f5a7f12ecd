"""Evaluation of a checkpoint from a tiny real training: official scores, our env vs the official
env, JSON, plots, video, and bad input."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from tiny_run import write_config

from myo_sds import evaluation as ev
from myo_sds.run_folder import RunFolder
from myo_sds.training import CurriculumTrainer

REPO = Path(__file__).resolve().parents[1]

@pytest.fixture(scope="module")
def run_dir(tiny_run) -> Path:
    """The shared tiny run (stage 1 "easy": hold at random phases; stage 2 "hard": rotate)."""
    return tiny_run.path


def test_resolve_checkpoint_variants(run_dir):
    final = ev.resolve_checkpoint(run_dir)
    assert final.model.name == "final_model.zip" and final.vecnormalize.name == "final_vecnormalize.pkl"
    last = ev.resolve_checkpoint(run_dir, last_checkpoint=True)
    assert last.model.name == "rl_model_2048_steps.zip"
    assert last.vecnormalize.name == "rl_model_vecnormalize_2048_steps.pkl"
    assert ev.resolve_checkpoint(run_dir, checkpoint_steps=1792).model.name == "rl_model_1792_steps.zip"
    direct = ev.resolve_checkpoint(run_dir / "checkpoints" / "rl_model_1792_steps.zip")
    assert direct.run_dir == run_dir and direct.vecnormalize.is_file()


def test_evaluation_reports_official_metrics(run_dir):
    ref = ev.resolve_checkpoint(run_dir)
    report = ev.evaluate(ref, ev.choose_env(ref, "stage:easy"), episodes=4, seed=3)
    summary = report.summary()
    assert summary["episodes"] == 4 and len(summary["per_episode"]) == 4
    scores = [e["solved_steps"] / 200 for e in summary["per_episode"]]
    assert summary["score"] == pytest.approx(np.mean(scores))
    assert summary["drop_rate"] == np.mean([e["dropped"] for e in summary["per_episode"]])
    assert summary["score_ci95"][0] <= summary["score"] <= summary["score_ci95"][1]
    assert set(summary["per_direction"]) == {"hold"}
    # Random start phases: each sector's score is the mean over the episodes that started in it.
    sectors = summary["per_start_phase"]
    assert sum(s["episodes"] for s in sectors.values()) == 4
    for name, sector in sectors.items():
        low, high = (float(v) for v in name.split("-"))
        inside = [e for e in summary["per_episode"] if low <= np.degrees(e["start_phase"]) < high]
        assert sector["episodes"] == len(inside)
        assert sector["score"] == pytest.approx(np.mean([e["solved_steps"] / 200 for e in inside]))
        drops = [e["length"] for e in inside if e["dropped"]]
        assert sector["drop_step"] == (pytest.approx(np.mean(drops)) if drops else None)
    table = ev.format_table([report])
    for name, sector in sectors.items():
        assert f"score, start {name} deg" in table and f"(n={sector['episodes']}, drops" in table
    assert "start A-B deg: the targets' start phase" in table
    # A hold stage: each episode's targets stay in its start sector, so by target phase the
    # steps and solved steps are those of the episodes that started there.
    for name, sector in summary["per_target_phase"].items():
        low, high = (float(v) for v in name.split("-"))
        inside = [e for e in summary["per_episode"] if low <= np.degrees(e["start_phase"]) < high]
        assert sector["steps"] == sum(e["length"] for e in inside)
        assert sector["solved_fraction"] == pytest.approx(sum(e["solved_steps"] for e in inside) / sector["steps"])
        assert f"solved, targets at {name} deg" in table
    assert sum(s["steps"] for s in summary["per_target_phase"].values()) == sum(e["length"] for e in summary["per_episode"])
    # Deterministic: the same seeds give the same numbers, with or without worker processes.
    again = ev.evaluate(ref, ev.choose_env(ref, "stage:easy"), episodes=4, seed=3, workers=2)
    assert again.summary()["per_episode"] == summary["per_episode"]


@pytest.mark.parametrize("preset", ["p1", "p2"])
def test_our_env_and_official_env_give_the_same_score(run_dir, preset):
    pytest.importorskip("myosuite")
    ref = ev.resolve_checkpoint(run_dir)
    ours = ev.evaluate(ref, ev.choose_env(ref, preset), episodes=5, seed=10)
    official = ev.evaluate(ref, ev.choose_env(ref, preset, official=True), episodes=5, seed=10)
    for a, b in zip(ours.episodes, official.episodes):
        assert (a.solved_steps, a.length, a.dropped, a.direction) == (b.solved_steps, b.length, b.dropped, b.direction)
        assert a.effort == pytest.approx(b.effort, rel=1e-9)
    assert ours.summary()["score"] == official.summary()["score"]
    assert len({e.direction for e in ours.episodes}) >= (2 if preset == "p2" else 1)


def test_start_noise_moves_the_hand_alike_on_both_envs_and_makes_episodes_differ(run_dir):
    pytest.importorskip("myosuite")
    from myo_sds.envs.baoding import N_HAND_JOINTS, BaodingEnv
    from myo_sds.evaluation.episodes import make_env, move_hand_joints, start_offsets

    ref = ev.resolve_checkpoint(run_dir)
    noisy = ev.choose_env(ref, "p1_2022", start_noise=0.02)
    # The offsets: one U(-0.02, 0.02) per hand joint, fixed by the episode's seed.
    offsets = start_offsets(7, 0.02, N_HAND_JOINTS)
    assert offsets.shape == (23,) and np.abs(offsets).max() <= 0.02 and np.abs(offsets).min() > 0
    assert np.array_equal(offsets, start_offsets(7, 0.02, N_HAND_JOINTS))
    assert not np.array_equal(offsets, start_offsets(8, 0.02, N_HAND_JOINTS))
    # After the move, each env's hand angles are its reset angles plus the offsets (unclipped),
    # the observation shows them, and the two envs' observations agree.
    ours, official = BaodingEnv("p1_2022"), make_env(ev.choose_env(ref, "p1_2022", official=True))
    ours.reset(seed=7)
    before = ours.data.qpos[:23].copy()
    obs = move_hand_joints(ours, noisy, offsets)
    assert np.array_equal(ours.data.qpos[:23], before + offsets)
    assert np.allclose(obs[:23], before + offsets, atol=1e-7)
    official.reset(seed=7)
    official_obs = move_hand_joints(official, ev.choose_env(ref, "p1_2022", official=True, start_noise=0.02), offsets)
    assert np.array_equal(official.unwrapped.data.qpos[:23], before + offsets)
    assert np.allclose(obs, official_obs, atol=1e-6)
    # Whole episodes: ours = official episode by episode, and the episodes differ from each other
    # (without noise the fixed P1 start replays one episode).
    plain = ev.evaluate(ref, ev.choose_env(ref, "p1_2022"), episodes=3, seed=0)
    assert len({(e.solved_steps, e.length, e.effort) for e in plain.episodes}) == 1
    mine = ev.evaluate(ref, noisy, episodes=3, seed=0)
    theirs = ev.evaluate(ref, ev.choose_env(ref, "p1_2022", official=True, start_noise=0.02), episodes=3, seed=0)
    for a, b in zip(mine.episodes, theirs.episodes):
        assert (a.solved_steps, a.length, a.dropped) == (b.solved_steps, b.length, b.dropped)
        assert a.effort == pytest.approx(b.effort, rel=1e-9)
    assert len({e.effort for e in mine.episodes}) == 3
    summary = mine.summary()
    assert summary["start_noise"] == 0.02 and noisy.label == "ours:p1_2022 noise 0.02"
    scores = [e.score for e in mine.episodes]
    assert summary["score_spread"]["std"] == pytest.approx(np.std(scores))
    assert (summary["score_spread"]["min"], summary["score_spread"]["max"]) == (min(scores), max(scores))
    with pytest.raises(ev.EvaluationError, match="radians >= 0"):
        ev.choose_env(ref, "p1", start_noise=-0.1)


def test_the_table_fits_120_columns(run_dir):
    ref = ev.resolve_checkpoint(run_dir)
    reports = [ev.evaluate(ref, ev.choose_env(ref, env, start_noise=noise), episodes=1)
               for env in ("p1", "p1_2022") for noise in (0.0, 0.02)]
    table = ev.format_table(reports)
    assert max(len(line) for line in table.splitlines()) <= 120
    for report in reports:
        assert report.env.label in table


@pytest.mark.slow  # renders video frames in software
def test_cli_writes_json_plots_and_video(run_dir, tmp_path):
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    result = subprocess.run(
        [sys.executable, str(REPO / "evaluate.py"), str(run_dir), "--env", "p1", "--episodes", "3",
         "--json", str(out / "e.json"), "--plots", str(out), "--video", str(out / "v.mp4"),
         "--video-episodes", "1"], capture_output=True, text=True, env=env, timeout=600)
    assert result.returncode == 0, result.stderr
    assert "score" in result.stdout and "drop rate" in result.stdout
    data = json.loads((out / "e.json").read_text())
    (report,) = data["reports"]
    for key in ("checkpoint", "env", "official_env", "seed", "start_noise", "episodes", "score", "score_ci95",
                "score_spread", "effort",
                "drop_rate", "mean_length", "per_direction", "per_start_phase", "per_episode"):
        assert key in report, key
    assert report["env"] == "p1" and report["episodes"] == 3
    assert report["per_start_phase"] == {}  # P1 starts every episode at the same phase
    for name in ("score_histogram.png", f"learning_curve_{run_dir.name}.png"):
        png = (out / name).read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000, name
    import imageio.v3 as iio

    # The run trained at random start phases: a second panel plots each phase sector's score.
    assert iio.imread(out / f"learning_curve_{run_dir.name}.png").shape[:2] == (800, 900)

    frames = iio.imread(out / "v.mp4")
    # The video replays the best of the 3 episodes (rendering is slow in software; the choice of
    # best and worst is tested below), then holds its last frame for 2 s at 40 fps.
    best = max(report["per_episode"], key=lambda e: (e["score"], e["length"]))
    assert frames.shape == (best["length"] + 80, 480, 640, 3)
    assert frames.std() > 10  # an actual picture, not a blank frame
    assert "best of 3" in result.stdout


def test_video_episodes_are_the_best_and_the_worst():
    from myo_sds.envs.metrics import EpisodeResult

    scores = [0.2, 0.9, 0.0, 0.5, 0.0]
    report = ev.EvaluationReport(None, None, seed=100, episodes=[
        EpisodeResult(solved_steps=int(s * 200), length=200 if s else 10 + i, horizon=200, dropped=not s, effort=0.0)
        for i, s in enumerate(scores)])
    # Best first; among equal scores the shorter episode is the worse one.
    assert ev.chosen_episodes(report, 2) == [(101, "best of 5"), (102, "worst of 5")]
    assert ev.chosen_episodes(report, 3) == [(101, "best of 5"), (103, "best of 5"), (102, "worst of 5")]
    assert [seed for seed, _ in ev.chosen_episodes(report, 10)] == [101, 103, 100, 104, 102]


def run_cli(capsys, *args: str) -> tuple[int, str]:
    """``evaluate.py`` in this process: its exit code and what it wrote to stderr."""
    from myo_sds.cli.evaluate import main

    code = main(list(args))
    return code, capsys.readouterr().err


def test_bad_input_gives_clear_errors(run_dir, tmp_path, capsys):
    code, err = run_cli(capsys, str(tmp_path / "nothing"))
    assert code == 2 and "no such run folder or checkpoint" in err
    corrupt = tmp_path / "rl_model_5_steps.zip"
    corrupt.write_bytes(b"not a zip at all")
    (tmp_path / "rl_model_vecnormalize_5_steps.pkl").write_bytes(b"x")
    code, err = run_cli(capsys, str(corrupt))
    assert code == 2 and "cannot load this checkpoint" in err
    code, err = run_cli(capsys, str(run_dir), "--env", "p3")
    assert code == 2 and "expected one of p1, p1_2022, p2 or stage:NAME" in err
    code, err = run_cli(capsys, str(run_dir), "--env", "stage:spin")
    assert code == 2 and "no stage named 'spin'" in err


def test_checkpoint_of_another_task_is_rejected(tmp_path, capsys):
    import pickle

    from sb3_contrib import RecurrentPPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    venv = VecNormalize(make_vec_env("Pendulum-v1", n_envs=1))
    RecurrentPPO("MlpLstmPolicy", venv, n_steps=8, batch_size=8,
                 policy_kwargs={"lstm_hidden_size": 8}).save(tmp_path / "rl_model_8_steps.zip")
    with (tmp_path / "rl_model_vecnormalize_8_steps.pkl").open("wb") as file:
        pickle.dump(venv, file)
    code, err = run_cli(capsys, str(tmp_path / "rl_model_8_steps.zip"))
    assert code == 2
    assert "observations of shape (3,)" in err and "trained on another task" in err


def test_die_checkpoint_scores_the_same_on_our_env_and_official(tmp_path):
    pytest.importorskip("myosuite")
    config = write_config(tmp_path, total=256,
                          curriculum="task: die\nstages:\n  - name: p1\n    advance: {threshold: 0.9, window: 8}\n")
    CurriculumTrainer.start(config, run_dir=tmp_path / "run", progress=False).run()
    ref = ev.resolve_checkpoint(tmp_path / "run")
    assert ev.run_task(ref) == "die"
    ours = ev.evaluate(ref, ev.choose_env(ref, "p2"), episodes=4, seed=0)
    official = ev.evaluate(ref, ev.choose_env(ref, "p2", official=True), episodes=4, seed=0)
    assert [(e.solved_steps, e.length, e.dropped) for e in ours.episodes] == \
        [(e.solved_steps, e.length, e.dropped) for e in official.episodes]
    summary = ours.summary()
    assert summary["score"] == np.mean([e["solved_steps"] > 5 for e in summary["per_episode"]])
    # Die episodes are split by how far the goal starts from the die (P2: up to pi per axis).
    assert sum(s["episodes"] for s in summary["per_start_phase"].values()) == 4
    assert summary["per_start_phase_of"] == "the goal's angle from the die at the start"
    assert "start A-B deg: the goal's angle from the die at the start" in ev.format_table([ours, official])


def test_run_summary_gives_each_stage_its_steps_time_and_measured_value(tiny_run, tmp_path, capsys):
    from myo_sds.cli.train import main

    summary = ev.summarize(tiny_run.path)
    first, second = summary.stages
    transition = tiny_run.state.history[0]
    assert (first.status, first.env_steps, first.episodes) == ("passed", transition.stage_steps, transition.stage_episodes)
    assert first.measured == transition.measured >= first.threshold
    assert second.status == "budget_reached" and second.env_steps == 2048 - transition.at_step
    assert first.wall_s + second.wall_s == pytest.approx(summary.wall_s)
    assert first.wall_s == pytest.approx(transition.wall_s) and 0 < transition.wall_s < tiny_run.state.wall_s
    # The trend ends at the stage's current measured value: the same window of episodes.
    assert second.trend[-1][1] == pytest.approx(second.measured) and len(second.trend) == 5
    # The current stage's logged episodes split by start phase, recomputed here from episodes.csv.
    logged = [r for r in tiny_run.path.joinpath("episodes.csv").read_text().splitlines()[1:]
              if r.split(",")[3] == "hard"]
    rows = [dict(zip(("score", "dropped", "phase"), (float(f[4]), f[7] == "1", math.degrees(float(f[10])))))
            for f in (r.split(",") for r in logged)]
    assert sum(s["episodes"] for s in second.by_start_phase.values()) == len(rows) > 1
    for name, sector in second.by_start_phase.items():
        low, high = map(float, name.split("-"))
        inside = [r for r in rows if low <= r["phase"] < high]
        assert sector["episodes"] == len(inside)
        assert sector["score"] == pytest.approx(np.mean([r["score"] for r in inside]))
        assert sector["drop_rate"] == pytest.approx(np.mean([r["dropped"] for r in inside]))
    assert first.by_start_phase == {}  # only the current stage is split
    # The newest checkpoint's action std; the tiny run's policy starts at exp(-1) and has learned.
    newest = RunFolder(tiny_run.path).latest_checkpoint().model
    from stable_baselines3.common.save_util import load_from_zip_file
    std = load_from_zip_file(newest, load_data=False)[1]["policy"]["log_std"].exp()
    assert summary.action_std == pytest.approx((float(std.mean()), float(std.min()), float(std.max())))
    assert summary.action_std[1] < summary.action_std[0] < summary.action_std[2]
    assert main(["--status", str(tiny_run.path), "--json", str(tmp_path / "s.json")]) == 0
    printed = capsys.readouterr().out
    assert f"action std of the newest saved policy: mean {summary.action_std[0]:.3f}" in printed
    # All the tiny run's updates: two rollouts of 2 x 64 env steps, then 28 of 2 x 32 to 2,048.
    sizes = summary.update_sizes
    assert (sizes.updates, sizes.first_step, sizes.last_step) == (30, 128, 2048)
    assert sizes.learning_rate == pytest.approx(1e-4)  # stage 2's rate
    assert f"updates, {sizes.describe()}" in printed
    assert "1 easy  passed" in printed and f"score {second.measured:.3f} / 0.9" in printed
    assert f"stage 2, its last {len(rows):,} episodes by the targets' start phase:" in printed
    assert json.loads((tmp_path / "s.json").read_text())["stages"][1]["trend"][-1][1] == pytest.approx(second.measured)


def test_run_summary_dates_a_running_status_by_its_last_checkpoint(tiny_run, tmp_path):
    # A run killed without warning still reads "running": the summary says how old that news is.
    copy = tmp_path / "run"
    shutil.copytree(tiny_run.path, copy)
    state_file = RunFolder(copy).state_file
    state = json.loads(state_file.read_text())
    state["status"] = "running"
    state_file.write_text(json.dumps(state))
    saved_at = 1_796_000_000.0  # 2026-11-30 00:53:20 UTC
    os.utime(state_file, (saved_at, saved_at))
    summary = ev.summarize(copy)
    assert summary.saved_at == saved_at
    first_line = ev.format_summary(summary, now=saved_at + 25 * 60).splitlines()[0]
    assert first_line.startswith(f"{copy}: running as of its last checkpoint (2026-11-30 00:53 UTC, 25 min ago), ")
    assert ev.format_summary(ev.summarize(tiny_run.path)).splitlines()[0].startswith(f"{tiny_run.path}: budget_reached, ")
    shutil.rmtree(copy / "checkpoints")  # what an exported model folder looks like
    assert ev.format_summary(ev.summarize(copy)).splitlines()[0].startswith(f"{copy}: exported while its run was running, ")


def test_an_exported_model_folder_evaluates_like_its_run(tiny_run, tmp_path, capsys):
    from myo_sds.cli.train import main

    assert main(["--export", str(tiny_run.path), "--to", str(tmp_path / "model")]) == 0
    assert sorted(p.name for p in (tmp_path / "model").iterdir()) == [
        "README.md", "command.txt", "config.yaml", "curriculum.yaml", "curriculum_state.json", "final_model.zip",
        "final_vecnormalize.pkl", "versions.json"]
    exported, original = ev.resolve_checkpoint(tmp_path / "model"), ev.resolve_checkpoint(tiny_run.path)
    for env_name in ("stage:hard", "p1"):
        a = ev.evaluate(exported, ev.choose_env(exported, env_name), episodes=2, seed=7)
        b = ev.evaluate(original, ev.choose_env(original, env_name), episodes=2, seed=7)
        assert a.summary()["per_episode"] == b.summary()["per_episode"]
    # Without the episode log, the export still knows each stage's wall time.
    run_summary, model_summary = ev.summarize(tiny_run.path), ev.summarize(tmp_path / "model")
    assert [(s.status, s.env_steps) for s in model_summary.stages] == [(s.status, s.env_steps) for s in run_summary.stages]
    assert [s.wall_s for s in model_summary.stages] == pytest.approx([s.wall_s for s in run_summary.stages])
    assert 0 < model_summary.stages[0].wall_s < model_summary.wall_s
    # Its model card: each stage's row, and the command lines that trained it.
    card = (tmp_path / "model" / "README.md").read_text()
    for s in run_summary.stages:
        assert f"| {s.index} {s.name} | {s.status} | {s.env_steps:,} | {s.wall_s / 3600:.2f} |" in card
    assert (tiny_run.path / "command.txt").read_text().strip() in card
    assert main(["--export", str(tmp_path / "nothing"), "--to", str(tmp_path / "x")]) == 2
    assert "nothing: no such file or folder" in capsys.readouterr().err


@pytest.mark.parametrize("curriculum, task", [("baoding_p1_2022", "p1_2022"), ("baoding_p1", "p1"),
                                              ("quickstart", "p1")])
def test_the_model_card_evaluates_on_the_task_the_curriculum_ends_on(tiny_run, tmp_path, curriculum, task):
    """Its last stage's preset whatever its rewards and knobs (p1_2022's with the winner's; p1 as it is;
    quickstart: p1 with start noise)."""
    from myo_sds.evaluation.model_card import model_card

    model = tmp_path / "model"
    shutil.copytree(tiny_run.path, model, ignore=shutil.ignore_patterns("checkpoints", "tb"))
    shutil.copy(Path(__file__).parents[1] / "curricula" / f"{curriculum}.yaml", RunFolder(model).curriculum_file)
    assert f"python evaluate.py {model} --env {task} --official --episodes 200" in model_card(model, tiny_run.path)


@pytest.mark.slow  # renders video frames in software
def test_cli_plots_and_video_of_folders_without_an_episode_log(tmp_path, capsys):
    """A shipped model folder has no episode log: its shipped curve is copied; a published
    policy has none, which is said; neither stops the histogram or the video."""
    from myo_sds.cli.evaluate import main

    shipped, published = REPO / "models" / "baoding_p1", REPO / "models" / "reference" / "stiff_fingers_2022_p1"
    out = tmp_path / "out"
    # The published policy drops the balls early in P1 (step 42-47, by the CPU): a short video.
    assert main([str(published), str(shipped), "--env", "p1", "--episodes", "1", "--plots", str(out),
                 "--video", str(out / "v.mp4"), "--video-episodes", "1", "--json", str(out / "e.json")]) == 0
    length = json.loads((out / "e.json").read_text())["reports"][0]["per_episode"][0]["length"]
    assert length < 60
    printed = capsys.readouterr().out
    assert (out / "learning_curve_baoding_p1.png").read_bytes() == (shipped / "learning_curve.png").read_bytes()
    assert f"no learning curve for {published / 'phase1_final.zip'}: it is not inside a run" in printed
    assert (out / "score_histogram.png").is_file()
    import imageio.v3 as iio

    assert iio.imread(out / "v.mp4").shape == (length + 80, 480, 640, 3)


def test_the_model_card_gives_the_scores_its_evaluation_json_records(tiny_run, tmp_path):
    from myo_sds.evaluation.model_card import model_card

    model = tmp_path / "model"
    shutil.copytree(tiny_run.path, model, ignore=shutil.ignore_patterns("checkpoints", "tb"))
    ref = ev.resolve_checkpoint(model)
    reports = [ev.evaluate(ref, ev.choose_env(ref, "p1_2022", start_noise=noise), episodes=2) for noise in (0.0, 0.02)]
    (model / "evaluation.json").write_text(json.dumps({"numerics": {"fingerprint": "abc", "cpu": "test"},
                                                       "reports": [r.summary() for r in reports]}))
    card = model_card(model, tiny_run.path)
    assert "## Scores" in card and "numerics `abc` (test)" in card
    for report in reports:
        s = report.summary()
        assert f"| `p1_2022` | {s['start_noise']:g} | 2 | {s['score']:.3f} | - |" in card


def test_runs_compared_by_env_steps_and_hours_in_one_figure(run_dir, tmp_path):
    import csv
    import shutil

    from myo_sds.cli.evaluate import _run_comparison

    # A second run: the same episodes, logged as if it had trained at half the speed.
    slower = tmp_path / "slower"
    shutil.copytree(run_dir, slower)
    with (slower / "episodes.csv").open(newline="") as file:
        rows = list(csv.DictReader(file))
    for row in rows:
        row["wall_s"] = str(2 * float(row["wall_s"]))
    with (slower / "episodes.csv").open("w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)

    curves = ev.plot_run_comparison([run_dir, slower], tmp_path / "compared.png", window=3)
    steps, hours, score = curves["slower"]
    scores = [float(r["score"]) for r in rows]
    expected = [np.mean(scores[max(0, i - 2):i + 1]) for i in range(len(scores))]  # the last 3 episodes
    np.testing.assert_allclose(score, expected)
    np.testing.assert_allclose(hours, [float(r["wall_s"]) / 3600 for r in rows])
    np.testing.assert_allclose(curves[run_dir.name][1] * 2, hours)
    assert list(steps) == [int(r["step"]) for r in rows] and len(rows) > 3
    assert (tmp_path / "compared.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    refs = [ev.resolve_checkpoint(folder) for folder in (run_dir, slower, run_dir)]
    assert _run_comparison(ev, refs, tmp_path / "plots").endswith("(2 runs by env steps and by hours)")
    assert (tmp_path / "plots" / "learning_curves_compared.png").is_file()
    assert "needs two or more run folders" in _run_comparison(ev, refs[:1], tmp_path / "plots")


def test_learning_curves_of_runs_with_the_same_folder_name_do_not_overwrite_each_other(tmp_path):
    from types import SimpleNamespace

    from myo_sds.cli.evaluate import _curve_names

    a, b = tmp_path / "a" / "run", tmp_path / "b" / "run"
    refs = [SimpleNamespace(run_dir=a), SimpleNamespace(run_dir=b), SimpleNamespace(run_dir=a / "checkpoints" / ".."),
            SimpleNamespace(run_dir=None)]
    a.mkdir(parents=True), b.mkdir(parents=True)
    # One curve per run (a run's checkpoints share it), each under its own name.
    assert _curve_names(refs) == {a.resolve(): "run", b.resolve(): "run-2"}


@pytest.mark.slow  # renders frames in software
def test_the_video_names_the_policy_and_the_task_it_shows(run_dir, tmp_path, monkeypatch):
    from myo_sds.evaluation import video

    shown: list[list[str]] = []
    real = video._overlay
    monkeypatch.setattr(video, "_overlay", lambda frame, lines: shown.append(lines) or real(frame, lines))
    ref = ev.resolve_checkpoint(run_dir)
    choice = ev.choose_env(ref, "p1", start_noise=0.02)
    video.record_video(ref, choice, tmp_path / "v.mp4", [(0, "best of 1")])
    assert shown and all(lines[0] == f"{run_dir.name}/final_model.zip on ours:p1 noise 0.02" for lines in shown)
