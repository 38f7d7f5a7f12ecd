"""What long runs rely on: resumed runs draw new episodes, a SIGKILL loses only what came after
the last checkpoint, Ctrl-C stops between minibatches, and config errors come before torch loads."""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest
from tiny_run import CONFIG, CURRICULUM, scalar_events, write_config

from myo_sds.run_folder import EpisodeRecord, RunFolder
from myo_sds.training import CurriculumTrainer

REPO = Path(__file__).resolve().parents[1]
# Stage 1 never passes here, so every episode draws a random start phase from the same knobs.
ONE_STAGE = CURRICULUM.replace("threshold: 0.01", "threshold: 0.99")


def episode_rows(run: Path) -> list[EpisodeRecord]:
    return RunFolder(run).read_episodes()


def without_wall_time(rows: list[EpisodeRecord]) -> list[EpisodeRecord]:
    return [replace(row, wall_s=0.0) for row in rows]


def test_resume_continues_the_random_streams_and_is_reproducible(tmp_path):
    config = write_config(tmp_path, total=512, curriculum=ONE_STAGE)
    first = tmp_path / "first"
    CurriculumTrainer.start(config, run_dir=first, progress=False).run()
    start_phases = {row.start_phase for row in episode_rows(first) if row.step <= 256}
    copies = [tmp_path / "a", tmp_path / "b"]
    for copy in copies:
        shutil.copytree(first, copy)
        CurriculumTrainer.resume(copy, progress=False, total_steps=1024).run()
    resumed = [[row for row in episode_rows(copy) if row.step > 512] for copy in copies]
    assert len(resumed[0]) >= 20
    # Resuming the same checkpoint twice gives the same episodes ...
    assert without_wall_time(resumed[0]) == without_wall_time(resumed[1])
    # ... and they are new ones: none starts where the run's first episodes started.
    assert not start_phases & {row.start_phase for row in resumed[0]}


def test_each_episode_row_has_its_own_wall_time(tiny_run):
    walls = [row.wall_s for row in episode_rows(tiny_run.path)]
    assert walls == sorted(walls)
    # One wall time per rollout would give at most one value per rollout.
    assert len(set(walls)) > 2 * len(tiny_run.trainer.timings)


@pytest.mark.slow  # a real process and SIGKILL
def test_resume_after_sigkill_continues_from_the_last_checkpoint_with_consistent_logs(tmp_path):
    config = write_config(tmp_path, total=1_000_000, curriculum=ONE_STAGE)
    config.write_text(config.read_text().replace("checkpoint_every: 256", "checkpoint_every: 1280"))
    run = tmp_path / "run"
    process = subprocess.Popen([sys.executable, str(REPO / "train.py"), "--config", str(config), "--run-dir", str(run),
                                "--no-progress"], cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        # Kill it once it has logged episodes past a checkpoint (every 10 rollouts of 128 steps).
        deadline = time.time() + 240
        while time.time() < deadline:
            checkpoint = RunFolder(run).latest_checkpoint()
            rows = episode_rows(run) if checkpoint is not None else []
            if rows and rows[-1].step > checkpoint.steps + 128:
                break
            time.sleep(0.05)
        process.send_signal(signal.SIGKILL)
    finally:
        process.wait(timeout=60)
    assert process.returncode == -signal.SIGKILL
    saved = RunFolder(run).latest_checkpoint().read_state()
    before = episode_rows(run)
    assert before[-1].step > saved.num_timesteps  # the kill lost episodes after the checkpoint
    # The run folder's state is the checkpoint's: nothing after it was recorded as done.
    assert RunFolder(run).read_state() == saved

    total = saved.num_timesteps + 512
    state = CurriculumTrainer.resume(run, progress=False, total_steps=total).run()
    assert state.status == "budget_reached" and state.num_timesteps == total
    after = episode_rows(run)
    kept = [row for row in before if row.step <= saved.num_timesteps]
    assert after[: len(kept)] == kept  # nothing lost up to the checkpoint
    new = after[len(kept):]
    assert new and all(row.step > saved.num_timesteps for row in new)  # no orphans from the killed run
    steps = [row.step for row in after]
    assert steps == sorted(steps)
    # command.txt keeps each session: the start, then the resume from the checkpoint's step.
    sessions = [line for line in (run / "command.txt").read_text().splitlines() if line.startswith("# ")]
    assert [line.split(", ")[1] for line in sessions] == ["from env step 0", f"from env step {saved.num_timesteps:,}"]
    assert state.stage_episodes == len(after)  # the curriculum counted exactly the logged episodes
    # TensorBoard shows one curve: the killed run's points after the checkpoint are purged.
    logged = [event.step for event in scalar_events(run / "tb", "curriculum/stage_steps")]
    assert logged == sorted(set(logged)) and logged[-1] == total


def test_a_stop_during_an_update_ends_it_before_the_next_minibatch(tmp_path):
    config = write_config(tmp_path, total=100_000, curriculum=ONE_STAGE)
    config.write_text(config.read_text().replace("n_epochs: 1", "n_epochs: 50"))
    run = tmp_path / "run"
    trainer = CurriculumTrainer.start(config, run_dir=run, progress=False)
    steps_taken = []

    def count_and_signal_after_the_third(*args) -> None:
        steps_taken.append(1)
        if len(steps_taken) == 3:
            trainer.episode_callback.stop_requested = "SIGINT"  # what the SIGINT handler does

    trainer.model.policy.optimizer.register_step_post_hook(count_and_signal_after_the_third)
    state = trainer.run()
    # 50 epochs of 2 minibatches were due; the stop came after the third.
    assert state.status == "interrupted" and len(steps_taken) == 3
    assert RunFolder(run).latest_checkpoint().steps == state.num_timesteps
    resumed = CurriculumTrainer.resume(run, progress=False, total_steps=state.num_timesteps + 128)
    assert resumed.run().status == "budget_reached"


@pytest.mark.slow  # a fresh interpreter, to see what it imported
def test_a_config_error_is_reported_before_torch_and_mujoco_load(tmp_path):
    (tmp_path / "curriculum.yaml").write_text(CURRICULUM)
    (tmp_path / "run.yaml").write_text(CONFIG.format(total=100))
    code = ("import sys, train; code = train.main(['--config', 'run.yaml', '--set', 'ppo.lerning_rate=1e-4']); "
            "print(code, 'torch' in sys.modules, 'mujoco' in sys.modules)")
    result = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=60,
                            env={"PYTHONPATH": str(REPO), "PATH": ""})
    assert result.stdout.split() == ["2", "False", "False"], result.stderr
    assert result.stderr.startswith("error: --set ppo.lerning_rate=1e-4: ppo.lerning_rate: unknown key "
                                    "(did you mean 'learning_rate'?)")


def test_a_run_resumes_with_the_stages_ahead_of_it_edited(tiny_run, tmp_path):
    """A user may change what comes next in a run's own curriculum.yaml: the current stage's
    settings and the stages after it. The stages it has trained in keep their names and places."""
    from myo_sds.curricula.schema import ConfigError

    run = tmp_path / "run"
    shutil.copytree(tiny_run.path, run)
    trained = RunFolder(run).latest_checkpoint().read_state()
    assert trained.trained_stages() == ["easy", "hard"]
    original = (run / "curriculum.yaml").read_text()

    (run / "curriculum.yaml").write_text(original.replace("name: easy", "name: warm-up"))
    with pytest.raises(ConfigError, match=r"curriculum\.yaml: stage 1 is 'warm-up' where the run trained in 'easy'"
                                          r".* only the stages after 'hard' may be added"):
        CurriculumTrainer.resume(run, progress=False, total_steps=4096)
    (run / "curriculum.yaml").write_text(original.split("  - name: hard")[0])  # 'hard' removed
    with pytest.raises(ConfigError, match="it has 1 stages, and the run has trained in 2 \\(easy, hard\\)"):
        CurriculumTrainer.resume(run, progress=False, total_steps=4096)

    # The current stage ends 64 steps from now, and a stage added after it takes over.
    ahead = trained.stage_steps + 64
    edited = original.replace("advance: {metric: score, threshold: 0.9, window: 8}",
                              f"advance: {{metric: score, threshold: 0.9, window: 8, max_steps: {ahead}}}")
    edited += ("  - name: turn-cw\n    env: {direction: cw, period: 20}\n"
               "    advance: {metric: score, threshold: 0.9, window: 8}\n")
    (run / "curriculum.yaml").write_text(edited)
    state = CurriculumTrainer.resume(run, progress=False, total_steps=3072).run()
    assert [t.stage for t in state.history] == ["easy", "hard"]
    assert state.history[-1].decision == "timed_out"
    assert state.trained_stages() == ["easy", "hard", "turn-cw"]
    assert {row.direction for row in episode_rows(run) if row.stage == "turn-cw"} == {"cw"}
