"""Real (tiny) curriculum training: stage transitions, run folder, checkpoints, interrupt + resume."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest
import torch
import yaml
from tiny_run import CONFIG, CURRICULUM, scalar_events, write_config

from myo_sds.curricula.schema import ConfigError
from myo_sds.curricula.state import RunStatus
from myo_sds.evaluation.checkpoints import load_policy, resolve_checkpoint
from myo_sds.run_folder import RunFolder
from myo_sds.training import CurriculumTrainer

REPO = Path(__file__).resolve().parents[1]


def test_two_stage_run_advances_and_records_everything(tiny_run):
    trainer, state, run = tiny_run.trainer, tiny_run.state, tiny_run.path
    assert state.status == "budget_reached" and state.num_timesteps >= 2048
    assert state.stage_index == 1
    (transition,) = state.history
    assert transition.stage == "easy" and transition.decision == "passed"
    assert transition.measured >= 0.01 and transition.stage_episodes >= 8
    folder = RunFolder(run)
    saved = folder.read_state()
    assert saved == state
    assert set(saved.steps_per_stage) == {"easy", "hard"}
    # Stage 2's PPO overrides took effect, including a rebuilt rollout buffer.
    model = trainer.model
    assert model.n_steps == 32 and model.rollout_buffer.buffer_size == 32
    from myo_sds.rollout_buffer import PaddedRolloutBuffer

    assert isinstance(model.rollout_buffer, PaddedRolloutBuffer)  # the faster padding, kept through the resize
    assert model.batch_size == 64 and model.learning_rate == 1e-4
    # Every worker env got the stage-2 knobs, in place.
    assert trainer.venv.get_attr("knobs")[0].direction == "ccw"
    assert trainer.venv.get_attr("knobs") == [trainer.config.curriculum.stages[1].distribution] * 2  # read once
    for path in (folder.config_file, folder.curriculum_file, folder.command_file, folder.versions_file, folder.episodes_file,
                 folder.final_model, folder.final_vecnormalize):
        assert path.is_file(), path
    assert list(folder.tensorboard_dir.glob("events.out.tfevents.*"))
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    logged = EventAccumulator(str(folder.tensorboard_dir), size_guidance={"scalars": 0})
    logged.Reload()
    std = model.policy.log_std.detach().exp()  # after the last update, which the last point logs
    assert logged.Scalars("policy/action_std_min")[-1].value == pytest.approx(float(std.min()), rel=1e-5)
    assert logged.Scalars("policy/action_std_mean")[-1].value == pytest.approx(float(std.mean()), rel=1e-5)
    episodes = folder.read_episodes()
    assert len(episodes) > 8 and {e.stage for e in episodes} == {"easy", "hard"}
    assert len(folder.checkpoint_steps()) == 2  # keep_checkpoints
    assert folder.latest_checkpoint() == folder.checkpoint(state.num_timesteps)


def test_ppo_warmup_trains_with_its_settings_then_hands_over_across_a_resume(tmp_path):
    # Stage 1 is not passed here, so the settings after the warm-up are the run config's.
    config = write_config(tmp_path, total=100_000, curriculum=CURRICULUM.replace("threshold: 0.01", "threshold: 0.99"))
    warmup = "warmup: {steps: 64, n_steps: 32, batch_size: 32, n_epochs: 3}"
    config.write_text(config.read_text().replace("n_epochs: 1}", f"n_epochs: 1, {warmup}}}"))
    run = tmp_path / "run"
    # The first rollout (2 envs x 32 steps) is the warm-up: 3 epochs of batches of 32.
    trainer = CurriculumTrainer.start(config, run_dir=run, progress=False)
    assert trainer.run(max_wall_s=1e-9).num_timesteps == 64
    model = trainer.model
    assert (model.n_steps, model.batch_size, model.n_epochs, model._n_updates) == (32, 32, 3, 3)
    # From step 64 on, the run's own settings: rollouts of 2 x 64 steps, one epoch of batches of 64.
    resumed = CurriculumTrainer.resume(run, progress=False)
    assert resumed.run(max_wall_s=1e-9).num_timesteps == 64 + 128
    model = resumed.model
    assert (model.n_steps, model.rollout_buffer.buffer_size, model.batch_size, model.n_epochs) == (64, 64, 64, 1)
    assert model._n_updates == 4


def test_target_kl_ends_an_update_at_the_first_minibatch_past_it(tmp_path):
    # 2 envs x 64 steps in minibatches of 64: two per epoch, 3 epochs. The first minibatch sees
    # the rollout's own policy (KL ~0); after its step the second one's KL is far above 1.5e-9,
    # so the update stops inside its first epoch. Without target_kl all three epochs run. The
    # epochs an update ran are logged as train/epochs_run.
    counts = {}
    for target_kl in (None, 1.0e-9):
        folder = tmp_path / str(target_kl)
        folder.mkdir()
        config = write_config(folder, total=100_000)
        setting = "" if target_kl is None else f", target_kl: {target_kl}"
        config.write_text(config.read_text().replace("n_epochs: 1}", f"n_epochs: 3{setting}}}"))
        trainer = CurriculumTrainer.start(config, run_dir=folder / "run", progress=False)
        assert trainer.run(max_wall_s=1e-9).num_timesteps == 128
        assert trainer.model.target_kl == target_kl
        epochs = scalar_events(RunFolder(folder / "run").tensorboard_dir, "train/epochs_run")
        counts[target_kl] = (trainer.model._n_updates, [event.value for event in epochs])
    assert counts == {None: (3, [3.0]), 1.0e-9: (1, [1.0])}


def test_crash_mid_write_leaves_previous_checkpoint_loadable(tmp_path):
    config = write_config(tmp_path, total=512)
    run = tmp_path / "run"
    CurriculumTrainer.start(config, run_dir=run, progress=False).run()
    good = RunFolder(run).latest_checkpoint()
    # A later checkpoint whose state file never got written (crash between files).
    partial = RunFolder(run).checkpoint(99999)
    partial.model.write_bytes(b"truncated")
    assert RunFolder(run).latest_checkpoint() == good
    from sb3_contrib import RecurrentPPO

    assert RecurrentPPO.load(good.model).num_timesteps == int(good.model.name.split("_")[2])


def test_time_limit_pauses_the_run_and_resume_continues_it(tmp_path):
    config = write_config(tmp_path, total=100_000)
    run = tmp_path / "run"
    # Any positive limit stops after the first rollout (2 envs x 64 steps), as a pause.
    state = CurriculumTrainer.start(config, run_dir=run, progress=False).run(max_wall_s=1e-9)
    assert state.status == "time_limit" and state.num_timesteps == 128 and state.wall_s > 0
    assert RunFolder(run).latest_checkpoint().model.name == "rl_model_128_steps.zip"
    assert not (run / "final_model.zip").exists()
    resumed = CurriculumTrainer.resume(run, progress=False)
    state = resumed.run(max_wall_s=1e-9)
    assert state.status == "time_limit" and state.num_timesteps == 256


def test_a_resumable_export_continues_the_same_run_elsewhere(tmp_path, capsys):
    """``--export RUN --to DIR --resumable``: one checkpoint, no logs; resumed on "another
    machine" it trains exactly as the original run resumed from the same checkpoint."""
    import shutil

    from myo_sds.cli.train import main

    config = write_config(tmp_path, total=100_000)
    run = tmp_path / "run"
    CurriculumTrainer.start(config, run_dir=run, progress=False).run(max_wall_s=1e-9)
    second = CurriculumTrainer.resume(run, progress=False)
    second.run(max_wall_s=1e-9)  # two checkpoints now, 128 and 256
    second.close()
    carried = tmp_path / "carried"
    (carried / "checkpoints").mkdir(parents=True)
    (carried / "checkpoints" / "rl_model_1_steps.zip").write_bytes(b"an older export's")
    assert main(["--export", str(run), "--to", str(carried), "--resumable"]) == 0
    assert "--resume" in capsys.readouterr().out
    assert sorted(p.name for p in (carried / "checkpoints").iterdir()) == [
        "curriculum_state_256_steps.json", "random_state_256_steps.pkl", "rl_model_256_steps.zip",
        "rl_model_vecnormalize_256_steps.pkl"]
    assert not (carried / "episodes.csv").exists() and not (carried / "tb").exists()
    status = (carried / "STATUS.txt").read_text()
    assert "1 easy" in status and status.startswith(f"{run.name}: ") and str(tmp_path) not in status
    elsewhere = tmp_path / "other_machine" / "run"
    shutil.copytree(carried, elsewhere)
    states = []
    for folder in (run, elsewhere):
        trainer = CurriculumTrainer.resume(folder, progress=False)
        states.append(trainer.run(max_wall_s=1e-9))
        trainer.close()
        weights = trainer.model.policy.state_dict()
        states.append(weights)
    (original, original_weights), (moved, moved_weights) = zip(states[::2], states[1::2])
    assert original.num_timesteps == moved.num_timesteps == 320  # stage 2 rolls out 64 steps
    assert replace(original, wall_s=0.0) == replace(moved, wall_s=0.0)  # the same schedule and window
    for name, tensor in original_weights.items():
        assert torch.equal(tensor, moved_weights[name]), name
    after = [(e.step, e.score, e.length) for e in RunFolder(run).read_episodes() if e.step > 256]
    assert after == [(e.step, e.score, e.length) for e in RunFolder(elsewhere).read_episodes()] and after


def test_a_run_of_a_curriculum_with_a_base_keeps_the_merged_curriculum_and_resumes_elsewhere(tmp_path):
    import shutil

    (tmp_path / "base_curriculum.yaml").write_text(CURRICULUM)
    variant = "base: base_curriculum.yaml\ndefaults: {reward_weights: {pos_dist_1: 1.0, solved: 3.0}}\n"
    config = write_config(tmp_path, total=512, curriculum=variant)
    run = tmp_path / "run"
    trainer = CurriculumTrainer.start(config, run_dir=run, progress=False)
    trainer.run(max_wall_s=1e-9)
    trainer.close()
    copy = yaml.safe_load((run / "curriculum.yaml").read_text())
    assert "base" not in copy and copy["name"] == "curriculum"  # named after the variant's file
    assert copy["defaults"]["reward_weights"] == {"pos_dist_1": 1.0, "solved": 3.0}
    assert [stage["name"] for stage in copy["stages"]] == ["easy", "hard"]
    # Moved away from the base file, the run still resumes: its copy stands alone.
    elsewhere = tmp_path / "elsewhere" / "run"
    shutil.copytree(run, elsewhere)
    (tmp_path / "base_curriculum.yaml").unlink()
    resumed = CurriculumTrainer.resume(elsewhere, progress=False)
    assert resumed.config.curriculum.stages[0].distribution.reward_weights["solved"] == 3.0
    resumed.close()


def test_resumable_exports_under_experiments_are_tracked_and_run_folders_are_not():
    """A resumable export kept in experiments/runs/ must reach the repository; the default run
    folders (runs/ at the top) must not."""
    if not (REPO / ".git").exists():
        pytest.skip("not a git checkout")

    def ignored(path: str) -> bool:
        return subprocess.run(["git", "check-ignore", "-q", path], cwd=REPO).returncode == 0

    assert not ignored("experiments/runs/a-s0/checkpoints/rl_model_256_steps.zip")
    assert not ignored("experiments/runs/a-s0/curriculum_state.json")
    assert ignored("runs/quickstart-20261205-120000-s0/episodes.csv")


def test_a_run_that_spent_its_budget_resumes_with_a_larger_one(tmp_path):
    config = write_config(tmp_path, total=256)
    run = tmp_path / "run"
    state = CurriculumTrainer.start(config, run_dir=run, progress=False).run()
    assert state.status == "budget_reached" and state.num_timesteps == 256
    # Each episode's start phase is logged (random phases here), its return and how it began.
    episodes_file = RunFolder(run).episodes_file
    header, *rows = [line.split(",") for line in episodes_file.read_text().splitlines()]
    assert header[-4:] == ["start_phase", "reward", "start", "goals"]
    phase = header.index("start_phase")
    assert len({row[phase] for row in rows}) > 1 and all(0 <= float(row[phase]) < 6.2832 for row in rows)
    # A run begun by an older version logged no start phases: its rows keep matching its header.
    header, rows = header[:phase], [row[:phase] for row in rows]
    episodes_file.write_text("".join(",".join(r) + "\n" for r in [header, *rows]))
    with pytest.raises(ConfigError, match="budget_reached.*--total-steps"):
        CurriculumTrainer.resume(run, progress=False)
    with pytest.raises(ConfigError, match="total_steps 256 must exceed the 256 steps"):
        CurriculumTrainer.resume(run, progress=False, total_steps=256)
    resumed = CurriculumTrainer.resume(run, progress=False, total_steps=512)
    state = resumed.run()
    assert state.status == "budget_reached" and state.num_timesteps == 512
    assert yaml.safe_load(RunFolder(run).config_file.read_text())["total_steps"] == 512
    assert RunFolder(run).latest_checkpoint().model.name == "rl_model_512_steps.zip"
    lines = [line.split(",") for line in episodes_file.read_text().splitlines()]
    assert lines[0] == header and {len(line) for line in lines} == {len(header)}
    steps = [int(line[0]) for line in lines[1:]]
    assert steps == sorted(steps) and steps[-1] > 256


def test_a_stage_that_stops_gaining_ends_on_its_plateau_rule(tmp_path):
    # Stage 2 cannot gain 1.0 over its first full window: it ends 256 steps after that window.
    curriculum = CURRICULUM.replace("threshold: 0.9, window: 8}", "threshold: 0.9, window: 8, plateau_steps: 256, plateau_gain: 1.0}")
    state = CurriculumTrainer.start(write_config(tmp_path, total=100_000, curriculum=curriculum),
                                    run_dir=tmp_path / "run", progress=False).run()
    easy, hard = state.history
    assert (easy.decision, hard.decision) == ("passed", "plateaued")
    assert state.status == "completed" and hard.stage_steps < 2_000
    episodes = [e for e in RunFolder(tmp_path / "run").read_episodes() if e.stage == "hard"]
    window_full = episodes[7].step - easy.at_step  # the stage step of its 8th episode's rollout
    assert 256 <= hard.stage_steps - window_full <= 256 + 32 * 2  # within a rollout (32 steps x 2 envs)


def test_learning_rate_decay_follows_env_steps_across_stages_and_resume(tmp_path):
    run_decay = "{start: 1.0e-3, end: 1.0e-5, steps: 1024}"
    stage_decay = "{start: 2.0e-4, end: 2.0e-6, steps: 256}"
    curriculum = CURRICULUM.replace("learning_rate: 1.0e-4,", f"learning_rate: {stage_decay},")
    config = write_config(tmp_path, total=256, curriculum=curriculum)
    config.write_text(config.read_text().replace("learning_rate: 3.0e-4,", f"learning_rate: {run_decay},"))
    run = tmp_path / "run"
    trainer = CurriculumTrainer.start(config, run_dir=run, progress=False)
    state = trainer.run()
    # Rollouts of 2 envs x 64 steps: the last update (steps 128-256, stage 1) used the rate
    # at step 128, one eighth of the way down the run's decay.
    optimizer_rate = trainer.model.policy.optimizer.param_groups[0]["lr"]
    assert optimizer_rate == pytest.approx(1e-3 * 0.01 ** (128 / 1024))
    # Stage 1 passed after that update: stage 2's decay starts from its top.
    assert state.history[0].at_step == 256 and trainer.model.learning_rate == pytest.approx(2e-4)
    # Continued past stage 1's pass, the stage's own decay runs from the stage's first step.
    resumed = CurriculumTrainer.resume(run, progress=False, total_steps=2048)
    state = resumed.run()
    passed_at = state.history[0].at_step
    last_rollout_start = state.num_timesteps - 64  # stage 2's rollouts: 2 envs x 32 steps
    expected = 2e-4 * 0.01 ** min((last_rollout_start - passed_at) / 256, 1.0)
    assert state.stage_index == 1 and resumed.model.policy.optimizer.param_groups[0]["lr"] == pytest.approx(expected)


def _as_at_a_terminal() -> None:
    # A command started in the background of a non-interactive shell (as CI may start the suite)
    # inherits SIGINT ignored, and Python keeps it so until the trainer installs its handler; a
    # user's Ctrl-C reaches a foreground process whose SIGINT is the default.
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def run_train(args: list[str], cwd: Path, **kwargs) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.Popen([sys.executable, str(REPO / "train.py"), *args], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            preexec_fn=_as_at_a_terminal, **kwargs)


@pytest.mark.slow  # real processes and signals
def test_sigint_saves_and_resume_continues_same_stage_and_counters(tmp_path):
    config = write_config(tmp_path, total=100_000)
    run = tmp_path / "run"
    process = run_train(["--config", str(config), "--run-dir", str(run), "--no-progress"], tmp_path)
    deadline = time.time() + 240
    while time.time() < deadline and RunFolder(run).latest_checkpoint() is None:
        time.sleep(0.5)
    assert RunFolder(run).latest_checkpoint() is not None, process.communicate()[0]
    time.sleep(1.0)
    process.send_signal(signal.SIGINT)
    output, _ = process.communicate(timeout=120)
    assert process.returncode == 130, output
    assert "SIGINT: saving a checkpoint" in output
    folder = RunFolder(run)
    state = folder.read_state()
    assert state.status is RunStatus.INTERRUPTED
    saved_steps, saved_stage = state.num_timesteps, state.stage_index
    assert folder.latest_checkpoint().steps == saved_steps
    assert not folder.final_model.exists()

    # Resume with a budget a little beyond the saved step count.
    config_text = folder.config_file.read_text().replace("total_steps: 100000", f"total_steps: {saved_steps + 512}")
    folder.config_file.write_text(config_text)
    resumed = run_train(["--resume", str(run), "--no-progress"], tmp_path)
    output, _ = resumed.communicate(timeout=300)
    assert resumed.returncode == 0, output
    state = folder.read_state()
    assert state.status in (RunStatus.BUDGET_REACHED, RunStatus.COMPLETED)
    assert saved_steps + 512 <= state.num_timesteps <= saved_steps + 512 + 128
    assert state.stage_index >= saved_stage
    from sb3_contrib import RecurrentPPO

    model = RecurrentPPO.load(folder.final_model)
    assert model.num_timesteps == state.num_timesteps
    assert len(list(folder.tensorboard_dir.glob("events.out.tfevents.*"))) == 2  # same folder, one curve


def test_bad_config_fails_before_training(tmp_path, capsys):
    from myo_sds.cli.train import main

    (tmp_path / "curriculum.yaml").write_text(CURRICULUM.replace("threshold: 0.01", "threshold: 2"))
    (tmp_path / "run.yaml").write_text(CONFIG.format(total=100))
    assert main(["--config", str(tmp_path / "run.yaml"), "--run-dir", str(tmp_path / "run")]) == 2
    assert capsys.readouterr().err == (f"error: {tmp_path / 'curriculum.yaml'}: stage 1 (easy) advance.threshold: "
                                       "must be in [0, 1] for score, got 2\n")
    assert not (tmp_path / "run").exists()


DIE_CURRICULUM = """
name: die-two-stage
task: die
defaults: {goal_position: 0.0}
stages:
  - name: hold-still
    env: {goal_rotation: 0.0}
    advance: {metric: score, threshold: 0.5, window: 8}
  - name: rotate
    env: {goal_rotation: [-0.5, 0.5]}
    advance: {metric: score, threshold: 0.99, window: 8}
"""


def test_die_curriculum_advances_a_stage(tmp_path):
    """The same engine trains the die: the goal on the resting die is solved from step one."""
    (tmp_path / "curriculum.yaml").write_text(DIE_CURRICULUM)
    (tmp_path / "run.yaml").write_text(CONFIG.format(total=1024))
    trainer = CurriculumTrainer.start(tmp_path / "run.yaml", run_dir=tmp_path / "run", progress=False)
    state = trainer.run()
    assert state.history and state.history[0].stage == "hold-still"
    assert state.history[0].decision == "passed" and state.stage_index == 1
    assert trainer.venv.get_attr("knobs")[0].goal_rotation[0].high == 0.5


def _train_with_stage_evaluation(tmp_path, advance_extra: str = "", evaluate_extra: str = ""):
    """The tiny run with stage 1 unpassable (threshold 1.0) and evaluated every 256 steps (3
    episodes, start noise 0.02), trained to its 1,024-step budget: (run folder, final state)."""
    curriculum = CURRICULUM.replace(
        "advance: {metric: score, threshold: 0.01, window: 8}",
        f"advance: {{metric: score, threshold: 1.0, window: 8{advance_extra}}}\n"
        f"    evaluate: {{every: 256, episodes: 3, env: stage, start_noise: 0.02{evaluate_extra}}}")
    run = tmp_path / "run"
    state = CurriculumTrainer.start(write_config(tmp_path, total=1024, curriculum=curriculum),
                                    run_dir=run, progress=False).run()
    return run, state


def _evaluated_again(policy, run, step: int) -> float:
    """The policy's score evaluated as ``run``'s stage evaluation at ``step`` did (stage 1, noise
    0.02, three episodes from the evaluation's first seed: new seeds at every evaluation)."""
    from myo_sds import evaluation as ev

    (record,) = [e for e in RunFolder(run).read_evaluations() if e.step == step and e.kind != "probe"]
    assert record.first_seed == step  # seeds: fresh
    ref = ev.resolve_checkpoint(policy)
    return ev.evaluate(ref, ev.choose_env(ref, "stage:easy", start_noise=0.02), episodes=3,
                       seed=record.first_seed).summary()["score"]


def test_a_stage_evaluates_periodically_and_hands_its_best_policy_to_the_next(tmp_path, capsys):
    from myo_sds.evaluation.summary import format_summary, summarize

    # Stage 1 cannot pass (threshold 1.0): it runs its 1,024 steps, evaluated every 256, and the
    # run's budget ends right at the transition, so the final model is the policy handed on.
    run, state = _train_with_stage_evaluation(tmp_path, ", max_steps: 1024", ", hand_off: best")
    (easy,) = state.history
    assert easy.decision == "timed_out" and easy.at_step == 1024
    scores = [e.value for e in scalar_events(RunFolder(run).tensorboard_dir, "eval/score")]
    assert len(scores) == 4  # at 256, 512, 768 and 1,024 stage steps
    assert easy.best_evaluated == pytest.approx(max(scores))
    assert easy.handed_off_step is None or easy.handed_off_step < easy.at_step
    # The final model is the best evaluated one: evaluated again the same way, it scores the best.
    best_step = easy.handed_off_step or easy.at_step
    assert _evaluated_again(run, run, best_step) == pytest.approx(easy.best_evaluated, abs=1e-12)
    text = format_summary(summarize(run))
    assert f"best {easy.best_evaluated:.3f}" in text and "handed on" in text
    # Older best policies are pruned once a checkpoint no longer names them.
    assert not list(RunFolder(run).checkpoint_dir.glob("best_model_*"))


def test_a_stage_s_best_evaluated_policy_exports_as_a_model_folder(tiny_run, tmp_path, capsys):
    """``--export RUN --to DIR --best``: the stage's best evaluated policy, not the newest
    checkpoint's, described at its own step."""
    from myo_sds.cli.train import main

    run, state = _train_with_stage_evaluation(tmp_path)
    assert state.stage_index == 0 and state.best_evaluated_step is not None
    # This seed's best evaluation is not the last one, so the export goes back in the stage.
    assert state.best_evaluated_step < state.num_timesteps == 1024
    assert main(["--export", str(run), "--to", str(tmp_path / "best"), "--best"]) == 0
    exported = RunFolder(tmp_path / "best").read_state()
    assert exported.num_timesteps == exported.steps_per_stage["easy"] == state.best_evaluated_step
    logged = [e for e in RunFolder(run).read_episodes() if e.step <= state.best_evaluated_step]
    assert exported.stage_episodes == len(logged) < state.stage_episodes
    assert exported.wall_s == logged[-1].wall_s
    # Evaluated again the same way, it scores the stage's best.
    assert _evaluated_again(tmp_path / "best", run, state.best_evaluated_step) == pytest.approx(
        state.best_evaluated, abs=1e-12)
    card = (tmp_path / "best" / "README.md").read_text()
    assert f"at {state.best_evaluated_step:,} env steps" in card
    assert f"the stage's best evaluated policy (score {state.best_evaluated:.3f}" in card
    # A run without stage evaluations has no best to export; with --resumable it is refused.
    assert main(["--export", str(tiny_run.path), "--to", str(tmp_path / "x"), "--best"]) == 2
    assert "no evaluated policy in its stage (stage 2" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["--export", str(run), "--to", str(tmp_path / "y"), "--best", "--resumable"])
    assert "--best exports a stage's best evaluated policy" in capsys.readouterr().err


def test_a_stage_evaluation_is_checked_when_read(tmp_path, capsys):
    for written, message in (("{episodes: 3}", "every: missing"),
                             ("{every: 256, env: p3}", "'p3' is not one of stage, stage:NAME, p1, p1_2022, p2"),
                             ("{every: 256, env: 'stage:nope'}", "evaluate.env: no stage named 'nope'; stages: easy, hard"),
                             ("{every: 256, hand_off: first}", "hand_off")):
        curriculum = CURRICULUM.replace("advance: {metric: score, threshold: 0.01, window: 8}",
                                        "advance: {metric: score, threshold: 0.01, window: 8}\n"
                                        f"    evaluate: {written}")
        with pytest.raises(ConfigError, match=message):
            CurriculumTrainer.start(write_config(tmp_path, total=1024, curriculum=curriculum),
                                    run_dir=tmp_path / "bad", overwrite=True, progress=False)


def test_a_run_folder_that_holds_anything_is_refused_unless_overwritten(tmp_path):
    from myo_sds.run_folder import RunFolder

    taken = tmp_path / "taken"
    taken.mkdir()
    (taken / "notes.txt").write_text("mine")
    with pytest.raises(ConfigError, match="run folder exists and is not empty; use --resume"):
        RunFolder.claim(taken)
    assert (taken / "notes.txt").read_text() == "mine"
    folder = RunFolder.claim(taken, overwrite=True)
    assert folder.path == taken and not any(taken.iterdir())
    folder.remove()
    assert not taken.exists()
    assert RunFolder.claim(tmp_path / "new" / "run").path.is_dir()


@pytest.mark.parametrize("exploration, sequence_length", [("gaussian", None), ("lattice", None), ("gaussian", 5)])
def test_the_update_recomputes_the_rollout_s_log_probabilities_before_any_step(tmp_path, exploration, sequence_length):
    """PPO's ratio starts at exactly 1: the update's minibatches (their LSTM states, episode
    starts and padding, and sequences cut every few steps) replay what the rollout computed. A
    mismatch would clip samples for nothing."""
    from myo_sds.sb3_internals import start_training

    overrides = (f"policy.exploration={exploration}", f"ppo.sequence_length={sequence_length or 'null'}")
    trainer = CurriculumTrainer.start(write_config(tmp_path, total=100_000), overrides,
                                      run_dir=tmp_path / "run", progress=False)
    model = trainer.model
    assert model.rollout_buffer.max_sequence_length == sequence_length
    start_training(model, 100_000, trainer.episode_callback)
    assert trainer.rollouts.collect(model, trainer.episode_callback)
    model.policy.set_training_mode(False)
    compared = 0
    with torch.no_grad():
        for batch in model.rollout_buffer.get(model.batch_size):
            mask = batch.mask > 1e-8
            _, log_prob, _ = model.policy.evaluate_actions(batch.observations, batch.actions, batch.lstm_states,
                                                           batch.episode_starts)
            torch.testing.assert_close(log_prob[mask], batch.old_log_prob[mask], rtol=1e-6, atol=1e-5)  # float32 roundoff
            compared += int(mask.sum())
    assert compared == model.n_steps * model.n_envs
    trainer.close()


def test_an_evaluation_gate_a_stage_end_probe_and_the_rest_start_log(tmp_path):
    """A stage that passes once an evaluation's mean return reaches its threshold, the winner's
    way; the policy each stage hands on is kept and probed on another stage's task; episodes begun
    with the balls at rest are counted by direction; all of it in evaluations.csv and --status."""
    from myo_sds.evaluation.summary import format_summary, summarize

    curriculum = CURRICULUM.replace(
        "defaults: {direction: hold, period: static, rsi_probability: 1.0, start_angle: uniform}",
        "defaults: {direction: hold, period: static, rsi_probability: 1.0, start_angle: uniform,\n"
        "           reward_weights: {alive: 1.0, solved: 5.0}}\n"
        "probe: {env: 'stage:hard', episodes: 6}").replace(
        "advance: {metric: score, threshold: 0.01, window: 8}",
        # An untrained policy's episodes earn a few alive steps: any return >= 1 passes.
        "advance: {metric: eval_reward, threshold: 1, window: 8, max_steps: 2048}\n"
        "    evaluate: {every: 128, episodes: 2, env: stage, select: reward}").replace(
        "env: {direction: ccw, period: 20}", "env: {direction: random, period: 20, rsi_probability: 0.5}").replace(
        "advance: {metric: score, threshold: 0.9, window: 8}",
        "advance: {metric: eval_reward, threshold: 5000, window: 8}\n"
        "    evaluate: {every: 256, episodes: 1, env: 'stage:easy'}")  # judged on another stage's task
    run = tmp_path / "run"
    state = CurriculumTrainer.start(write_config(tmp_path, total=640, curriculum=curriculum),
                                    run_dir=run, progress=False).run()
    easy = state.history[0]
    folder = RunFolder(run)
    evaluations = folder.read_evaluations()
    periodic = [e for e in evaluations if e.stage == "easy" and e.kind == "periodic"]
    # Passed at its first evaluation (after the first rollout of 128 steps), on its return.
    assert easy.decision == "passed" and easy.at_step == 128 and len(periodic) == 1
    assert periodic[0].reward >= 1 and periodic[0].best and easy.best_evaluated_reward == periodic[0].reward
    probes = [e for e in evaluations if e.kind == "probe"]
    assert [(p.stage, p.env, p.episodes, p.step) for p in probes] == [("easy", "stage:hard", 6, 128)]
    assert {(e.env, e.episodes) for e in evaluations if e.stage == "hard"} == {("stage:easy", 1)}
    by_direction = easy.probe.pop("by_direction")
    assert easy.probe.pop("env") == "stage:hard"
    assert easy.probe == pytest.approx({"episodes": 6, "score": probes[0].score, "reward": probes[0].reward,
                                        "drop_rate": probes[0].drop_rate,
                                        "median_solved_steps": probes[0].median_solved_steps,
                                        "first_seed": 0}, rel=1e-5)  # the probe replays seeds 0 ..
    assert probes[0].by_direction == by_direction  # evaluations.csv keeps them too
    # The probe's episodes by direction (the stage draws hold, cw or ccw): they add up.
    assert set(by_direction) <= {"hold", "cw", "ccw"} and len(by_direction) >= 2
    assert sum(v["episodes"] for v in by_direction.values()) == 6
    assert sum(v["drop_rate"] * v["episodes"] for v in by_direction.values()) == pytest.approx(6 * probes[0].drop_rate)
    assert all(path.is_file() for path in folder.stage_policy_files(0, "easy"))
    # The policy a stage handed on is a checkpoint like any other, to evaluate or start from.
    handed_on = resolve_checkpoint(folder.stage_policy_files(0, "easy")[0])
    assert handed_on.vecnormalize == run / "stages" / "01_easy_vecnormalize.pkl"
    assert load_policy(handed_on, "baoding").normalizer is not None
    episodes = [e for e in folder.read_episodes() if e.stage == "hard"]
    rest = [e for e in episodes if e.start == "rest"]
    assert rest and len(rest) < len(episodes) and {e.start for e in episodes} == {"rest", "on_targets"}
    assert all(e.reward is not None for e in episodes)
    summary = summarize(run)
    counted = summary.stages[1].rest_starts
    assert sum(v["episodes"] for v in counted.values()) == len(rest) and set(counted) <= {"hold", "cw", "ccw"}
    rest_sectors = summary.stages[1].rest_by_start_phase
    assert sum(v["episodes"] for v in rest_sectors.values()) == len([e for e in rest if e.step <= state.num_timesteps])
    text = format_summary(summary)
    assert "balls at rest" in text and "stage-end probe" in text and "eval return" in text
    first = next(iter(by_direction))
    assert (f"; by direction: {first} {by_direction[first]['episodes']}, return {by_direction[first]['reward']:.0f}, "
            f"median {by_direction[first]['median_solved_steps']:.0f}") in text
    assert f"stage 2, its {sum(v['episodes'] for v in rest_sectors.values())} episodes begun with the balls at rest" in text
    # The current stage passes on its evaluations; its trend is its training episodes' score.
    assert "stage 2 trend (training score over" in text
    assert scalar_events(folder.tensorboard_dir, "eval/reward")
    # A resumable export carries the evaluation log; a resume forgets evaluations past its checkpoint.
    copy = folder.export_resumable(tmp_path / "carry")
    assert copy.read_evaluations() == [e for e in evaluations if e.step <= state.num_timesteps]
    folder.append_evaluations([replace(evaluations[0], step=10**9)])
    CurriculumTrainer.resume(run, progress=False, total_steps=768).close()
    assert folder.read_evaluations() == evaluations


def test_an_evaluation_metric_needs_the_stage_evaluation_and_a_probe_a_known_env(tmp_path):
    for old, new, message in (
            ("advance: {metric: score, threshold: 0.01, window: 8}", "advance: {metric: eval_score, threshold: 0.5}",
             "stage 1 \\(easy\\) advance.metric: eval_score needs the stage's evaluate"),
            ("advance: {metric: score, threshold: 0.01, window: 8}", "advance: {metric: eval_score, threshold: 2}",
             "advance.threshold: must be in \\[0, 1\\] for eval_score"),
            ("stages:", "probe: {env: 'stage:nope'}\nstages:", "probe.env: no stage named 'nope'; stages: easy, hard"),
            ("stages:", "probe: {env: p3}\nstages:", "probe.env: 'p3' is not one of stage:NAME, p1, p1_2022, p2")):
        with pytest.raises(ConfigError, match=message):
            CurriculumTrainer.start(write_config(tmp_path, total=256, curriculum=CURRICULUM.replace(old, new)),
                                    run_dir=tmp_path / "bad", overwrite=True, progress=False)


@pytest.mark.slow  # real processes and signals
def test_ctrl_c_at_any_moment_leaves_a_resumable_run_or_none(tmp_path):
    """From the first import to the first updates: no traceback, the command stops, and the run
    folder is either gone or holds a checkpoint that --resume accepts. The signals in the first
    half second land while Python and NumPy load (a lost one left the run training)."""
    config = write_config(tmp_path, total=100_000)
    outcomes = []
    for delay in (0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 1.0, 2.0, 3.0, 4.5, 7.0):
        run = tmp_path / f"run-{delay}"
        process = run_train(["--config", str(config), "--run-dir", str(run), "--no-progress"], tmp_path)
        time.sleep(delay)
        process.send_signal(signal.SIGINT)
        output, _ = process.communicate(timeout=120)
        # Python's own start (its site module) answers with a traceback before train.py's first line.
        assert "Traceback" not in output or "<frozen site>" in output, output
        assert process.returncode in (130, 2) or (process.returncode == 1 and delay < 1), output
        if run.exists():
            folder = RunFolder(run)
            assert folder.latest_checkpoint() is not None, (delay, output, sorted(p.name for p in run.iterdir()))
            CurriculumTrainer.resume(run, progress=False).close()
            outcomes.append("resumable")
        else:
            outcomes.append("none")
    assert "resumable" in outcomes  # the later signals came after training began


def test_a_ctrl_c_while_the_compiled_libraries_load_is_held_then_raised():
    """Raised inside a compiled module's initialization, a KeyboardInterrupt becomes "ImportError:
    initialization failed" with a traceback (seen at 1.7 s into train.py, in MuJoCo's); the
    command lines hold it over those imports and raise it after, or drop it if SIGINT was ignored."""
    from myo_sds.cli import sigint_held

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        reached_end = False
        with pytest.raises(KeyboardInterrupt):
            with sigint_held():
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.05)  # the handler has run by now
                reached_end = True
        assert reached_end and signal.getsignal(signal.SIGINT) is signal.default_int_handler
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        with sigint_held():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)


def test_a_privileged_critic_sees_more_than_the_actor_and_the_policy_runs_on_the_official_observation(tmp_path):
    """policy.critic_extra: the envs append the named features, the critic reads them, the actor's
    LSTM only the official 86 values; evaluate.py and the resumed run use it as any policy; a policy
    trained without extras starts one with the same value function."""
    import numpy as np

    from myo_sds import evaluation as ev
    from myo_sds.envs.baoding import BaodingEnv

    plain_run, run = tmp_path / "plain", tmp_path / "run"
    plain = CurriculumTrainer.start(write_config(tmp_path, total=128), run_dir=plain_run, progress=False)
    plain.run()
    plain.close()
    extra = ("policy.critic_extra=[ball_spin, fingertips, physics, goal_phase]",)
    trainer = CurriculumTrainer.start(tmp_path / "run.yaml", extra, run_dir=run, progress=False,
                                      init_from=plain_run)
    policy, venv = trainer.model.policy, trainer.venv
    assert venv.observation_space.shape == (86 + 6 + 15 + 10 + 4,)
    assert (policy.lstm_actor.input_size, policy.lstm_critic.input_size) == (86, 121)
    # Started from the plain policy: the same value of the same (normalized) official observation,
    # whatever the extra inputs (the critic's weights on them are zero), and the same actions.
    from sb3_contrib.common.recurrent.type_aliases import RNNStates

    obs = np.random.default_rng(0).normal(size=(4, 121)).astype(np.float32)
    starts = torch.ones(4)

    def zeros(p):
        shape = (p.lstm_actor.num_layers, 4, p.lstm_actor.hidden_size)
        return RNNStates((torch.zeros(shape), torch.zeros(shape)), (torch.zeros(shape), torch.zeros(shape)))

    with torch.no_grad():
        values_plain = plain.model.policy.predict_values(torch.as_tensor(obs[:, :86]), zeros(plain.model.policy).vf, starts)
        values = policy.predict_values(torch.as_tensor(obs), zeros(policy).vf, starts)
        torch.testing.assert_close(values, values_plain)
        # The actor ignores the extra inputs.
        mean = policy.get_distribution(torch.as_tensor(obs), zeros(policy).pi, starts)[0].distribution.mean
        shuffled = obs.copy()
        shuffled[:, 86:] = 3.0
        again = policy.get_distribution(torch.as_tensor(shuffled), zeros(policy).pi, starts)[0].distribution.mean
        torch.testing.assert_close(mean, again)
    state = trainer.run()
    trainer.close()
    assert state.num_timesteps == 128
    CurriculumTrainer.resume(run, progress=False, total_steps=256).run()
    # Evaluated on the official observation (86 values), the policy's own env: the same episodes.
    ref = ev.resolve_checkpoint(run)
    report = ev.evaluate(ref, ev.choose_env(ref, "stage:easy"), episodes=2)
    assert len(report.episodes) == 2 and BaodingEnv().observation_space.shape == (86,)
    # Its model card's fine-tuning command keeps the critic's inputs.
    from myo_sds.evaluation.model_card import model_card
    assert (f'--init-from {run} --set "policy.critic_extra=[ball_spin, fingertips, physics, goal_phase]"'
            in model_card(run, run))
    # Back into a config without the extras: the same task, so the error names the setting.
    with pytest.raises(ConfigError, match=r"its critic read 121 values where this config's reads 86: set "
                                          r"`policy.critic_extra` as it was trained \(critic_extra: "
                                          r"\[ball_spin, fingertips, physics, goal_phase\]\)"):
        CurriculumTrainer.start(tmp_path / "run.yaml", run_dir=tmp_path / "back", progress=False, init_from=run)
    assert not (tmp_path / "back").exists()
    for bad, message in (("policy.critic_extra=[die_velocity]", "'die_velocity' is not a privileged feature of "
                                                                 "the baoding task; allowed: ball_spin"),
                         ("policy.critic_extra=[physics, physics]", "listed twice")):
        with pytest.raises(ConfigError, match=message):
            CurriculumTrainer.start(tmp_path / "run.yaml", (bad,), run_dir=tmp_path / "bad", progress=False)


def test_resume_of_a_folder_that_is_no_run_says_so(tmp_path, capsys):
    from myo_sds.cli.train import main

    (tmp_path / "empty").mkdir()
    assert main(["--resume", str(tmp_path / "empty")]) == 2
    assert capsys.readouterr().err == (f"error: {tmp_path / 'empty'}: not a run folder (no config.yaml with "
                                       "checkpoints/ or final_model.zip inside)\n")
    assert main(["--resume", str(tmp_path / "gone")]) == 2
    assert capsys.readouterr().err == f"error: {tmp_path / 'gone'}: no such file or folder\n"


def test_status_before_the_first_checkpoint_shows_the_episode_log_so_far(tmp_path, capsys):
    """A run whose first checkpoint has not come yet has no state to tabulate, but its episodes:
    --status says when the checkpoint comes and what the last 100 episodes scored."""
    from myo_sds.cli.train import main
    from myo_sds.episode_log import EpisodeRecord

    trainer = CurriculumTrainer.start(write_config(tmp_path, total=100_000), ("checkpoint_every=90000",),
                                      run_dir=tmp_path / "run", progress=False)
    trainer.close()
    assert main(["--status", str(tmp_path / "run")]) == 0
    assert capsys.readouterr().out == (f"{tmp_path / 'run'}: no checkpoint yet (the first at 90,000 env steps); "
                                       "no episode has ended yet\n")
    # 150 episodes: the last 100 are episodes 50..149; every 4th scores 1, every 5th dropped,
    # solved steps = index % 7 (median of 50..149 % 7: 3).
    trainer.folder.append_episodes(
        EpisodeRecord(step=64 * (i + 1), wall_s=float(i), stage_index=0, stage="easy", score=float(i % 4 == 0),
                      solved_steps=i % 7, length=50, dropped=i % 5 == 0, effort=0.1, direction="ccw", start_phase=0.0)
        for i in range(150))
    assert main(["--status", str(tmp_path / "run"), "--json", str(tmp_path / "status.json")]) == 0
    expected = (f"{tmp_path / 'run'}: no checkpoint yet (the first at 90,000 env steps); its episode log: 150 "
                "episodes up to env step 9,600, stage 1 (easy); the last 100: score 0.250, 20% dropped, "
                "median solved steps 3")
    assert capsys.readouterr().out == expected + "\n"
    assert json.loads((tmp_path / "status.json").read_text())["message"] == expected


@pytest.mark.slow
def test_a_python_without_the_package_is_told_in_one_line_which_to_use_and_that_command_works(tmp_path):
    """train.py / evaluate.py run by an interpreter that cannot import what they need (here this
    one without its site-packages) print one line naming the checkout's environment, and the
    command printed there runs as printed."""
    import shlex

    for script in ("train.py", "evaluate.py"):
        args = ["--config", "quickstart", "--print-config"] if script == "train.py" else ["models/die_p1", "--episodes",
                                                                                            "1", "--env", "p1"]
        done = subprocess.run([sys.executable, "-S", script, *args], cwd=REPO, capture_output=True, text=True, timeout=120)
        assert done.returncode == 2, done.stderr
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and "cannot import" in lines[0] and "Traceback" not in done.stderr, done.stderr
        command = lines[0].split("run it with the checkout's environment: ", 1)[1]
        assert command.startswith(".venv/bin/python " + script), command
        again = subprocess.run(shlex.split(command), cwd=REPO, capture_output=True, text=True, timeout=600)
        assert again.returncode == 0, again.stderr


def test_a_hint_to_resume_names_the_command_as_it_was_run(monkeypatch):
    from myo_sds.cli import train_command

    monkeypatch.setattr(sys, "argv", ["/usr/local/bin/myo-sds-train", "--config", "x"])
    assert train_command() == "myo-sds-train"
    monkeypatch.setattr(sys, "argv", ["train.py", "--config", "x"])
    monkeypatch.chdir(REPO)
    python = os.path.relpath(sys.executable) if os.path.abspath(sys.executable).startswith(str(REPO) + os.sep) \
        else sys.executable
    assert train_command() in (f"{python} train.py", "python train.py")
    # The printed command runs: the interpreter it names is this one.
    program = train_command().split()[0]
    assert os.path.realpath(shutil.which(program) or program) == os.path.realpath(sys.executable)
