"""The Ray rollout backend on a cluster of this machine: the same rollouts as the local backend
with one worker, training with two, a killed worker restarted, resumes across backends, and
one clear line for bad input."""

from __future__ import annotations

import os
import shutil
import signal
import tempfile
import threading
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from tiny_run import write_config

from myo_sds.curricula.schema import ConfigError
from myo_sds.curricula.state import RunStatus
from myo_sds.run_folder import RunFolder
from myo_sds.training import CurriculumTrainer

ray = pytest.importorskip("ray")
pytestmark = pytest.mark.slow  # a Ray cluster starts and stops
CAPTURED = ("observations", "actions", "rewards", "log_probs", "episode_starts", "values")


@pytest.fixture(scope="module", autouse=True)
def local_cluster():
    """A local cluster whose workers have a temporary folder of their own (``worker_tmp``).

    Short and under /tmp, not pytest's basetemp: Ray puts its sockets inside, and an AF_UNIX path
    may not exceed 107 bytes (pytest's numbered folders grow one digit at a time)."""
    worker_tmp = Path(tempfile.mkdtemp(prefix="ray-", dir="/tmp" if os.path.isdir("/tmp") else None))
    before = os.environ.get("TMPDIR")
    os.environ["TMPDIR"] = str(worker_tmp)  # the cluster's processes inherit it at start
    try:
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    finally:
        if before is None:
            del os.environ["TMPDIR"]
        else:
            os.environ["TMPDIR"] = before
    yield worker_tmp
    ray.shutdown()
    shutil.rmtree(worker_tmp, ignore_errors=True)


def train(folder: Path, total: int, overrides: tuple[str, ...] = ()) -> tuple[CurriculumTrainer, dict]:
    """A tiny two-stage run (stage 1 passes at step 256, stage 2 has shorter rollouts); returns
    the trainer and each update's rollout buffer."""
    folder.mkdir()
    trainer = CurriculumTrainer.start(write_config(folder, total=total), overrides + ("num_threads=1",),
                                      run_dir=folder / "run", progress=False)
    rollouts: dict[int, dict[str, np.ndarray]] = {}

    def capture(*args) -> None:
        step, buffer = int(trainer.model.num_timesteps), trainer.model.rollout_buffer
        rollouts.setdefault(step, {name: getattr(buffer, name).copy() for name in CAPTURED})

    trainer.model.policy.optimizer.register_step_pre_hook(capture)
    trainer.run()
    return trainer, rollouts


# Chained goals and a privileged critic: the same rollouts on either backend too.
EXTRAS = ("defaults.goal_chain={after_solved: 2}", "policy.critic_extra=[ball_spin, goal_phase]")


@pytest.mark.parametrize("extras", [(), EXTRAS], ids=["plain", "chained-goals-privileged-critic"])
def test_one_worker_collects_bit_identical_rollouts_to_the_local_backend(tmp_path, local_cluster, extras):
    local, expected = train(tmp_path / "local", 512, extras)
    remote, got = train(tmp_path / "ray", 512, extras + ("rollout.backend=ray", "rollout.workers=1"))
    if extras:
        assert remote.venv.observation_space.shape == (86 + 6 + 4,)
        assert any(e.goals for e in RunFolder(remote.run_dir).read_episodes())
    remote.close()
    # A worker logs nothing itself: no logger folder SB3 would make for it at every rollout.
    assert not list(local_cluster.glob("SB3-*"))
    assert sorted(got) == sorted(expected) == [128, 256, 320, 384, 448, 512]  # a stage change at 256
    for step, arrays in expected.items():
        for name, array in arrays.items():
            assert np.array_equal(got[step][name], array), (step, name)
    episodes = [RunFolder(t.run_dir).read_episodes() for t in (local, remote)]
    assert [replace(e, wall_s=0) for e in episodes[0]] == [replace(e, wall_s=0) for e in episodes[1]]
    assert remote.state.history == local.state.history
    # One VecNormalize is checkpointed, with the statistics the local backend has.
    assert np.array_equal(remote.venv.obs_rms.mean, local.venv.obs_rms.mean)


def test_two_workers_train_through_a_killed_worker_and_resume_on_either_backend(tmp_path):
    overrides = ("rollout.backend=ray", "rollout.workers=2", "rollout.envs_per_worker=1")
    folder = tmp_path / "run2"
    folder.mkdir()
    trainer = CurriculumTrainer.start(write_config(folder, total=1024), overrides, run_dir=folder / "run",
                                      progress=False)
    pid = ray.get(trainer.rollouts.workers[1].pid.remote())
    rollout_start = trainer.episode_callback._on_rollout_start

    def kill_workers_during_rollouts() -> None:
        rollout_start()
        if trainer.model.num_timesteps == 256:  # the OS process of worker 1, mid-rollout
            threading.Timer(0.05, os.kill, (pid, signal.SIGKILL)).start()
        if trainer.model.num_timesteps == 512:  # worker 0, through Ray
            threading.Timer(0.05, ray.kill, (trainer.rollouts.workers[0],), {"no_restart": False}).start()

    trainer.episode_callback._on_rollout_start = kill_workers_during_rollouts
    state = trainer.run()
    assert state.status is RunStatus.BUDGET_REACHED and state.num_timesteps == 1024
    assert trainer.rollouts.restarts == 2
    assert ray.get(trainer.rollouts.workers[1].pid.remote()) != pid  # a new process
    episodes = RunFolder(trainer.run_dir).read_episodes()
    steps = [e.step for e in episodes]
    assert steps == sorted(steps) and steps[-1] <= 1024 and state.stage_episodes + 13 >= len(episodes) - 13
    trainer.close()  # its workers hold the cluster's two CPUs
    # A Ray run resumes on the local backend, and back.
    config = RunFolder(trainer.run_dir).config_file
    config.write_text(config.read_text().replace("backend: ray", "backend: local"))
    assert CurriculumTrainer.resume(trainer.run_dir, progress=False, total_steps=1280).run().num_timesteps == 1280
    config.write_text(config.read_text().replace("backend: local", "backend: ray"))
    resumed = CurriculumTrainer.resume(trainer.run_dir, progress=False, total_steps=1536)
    assert resumed.run().num_timesteps == 1536 and resumed.rollouts.restarts == 0
    resumed.close()


def test_bad_ray_settings_stop_before_training_with_one_line(tmp_path, monkeypatch):
    config = write_config(tmp_path, total=256)
    with pytest.raises(ConfigError, match="rollout.workers: 3 workers of one CPU each, but the Ray cluster has 2 CPUs"):
        CurriculumTrainer.start(config, ("rollout.backend=ray", "rollout.workers=3", "rollout.envs_per_worker=1"),
                                run_dir=tmp_path / "a", progress=False)
    with pytest.raises(ConfigError, match=r"rollout.envs_per_worker: must be >= 1 \(n_envs 2 over 4 workers gives 0\)"):
        CurriculumTrainer.start(config, ("rollout.backend=ray", "rollout.workers=4"), run_dir=tmp_path / "b",
                                progress=False)
    monkeypatch.setitem(__import__("sys").modules, "ray", None)  # as if ray were not installed
    with pytest.raises(ConfigError, match="rollout.backend: ray needs the ray package"):
        CurriculumTrainer.start(config, ("rollout.backend=ray", "rollout.workers=1"), run_dir=tmp_path / "c",
                                progress=False)


def test_a_worker_that_keeps_dying_stops_the_run_with_a_checkpoint(tmp_path, capsys):
    overrides = ("rollout.backend=ray", "rollout.workers=1", "rollout.max_restarts=0")
    trainer = CurriculumTrainer.start(write_config(tmp_path, total=100_000), overrides, run_dir=tmp_path / "run",
                                      progress=False)
    rollout_start = trainer.episode_callback._on_rollout_start

    def kill_at_the_third_rollout() -> None:
        rollout_start()
        if trainer.model.num_timesteps == 256:
            threading.Timer(0.05, ray.kill, (trainer.rollouts.workers[0],), {"no_restart": False}).start()

    trainer.episode_callback._on_rollout_start = kill_at_the_third_rollout
    state = trainer.run()
    trainer.close()
    assert state.status is RunStatus.INTERRUPTED and state.num_timesteps == 256
    assert "rollout worker 0 died 1 times in a row" in capsys.readouterr().out
    assert RunFolder(trainer.run_dir).latest_checkpoint().steps == 256  # nothing of the lost rollout counted
