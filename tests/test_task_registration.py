"""A task is one module and one registration: a toy task declared in tests/toy_task.py is read
from a curriculum, trained for a few rollouts, logged and scored by the registered rule."""

from __future__ import annotations

import gymnasium as gym
import pytest
import toy_task
from tiny_run import write_config

from myo_sds.curricula.schema import ConfigError, load_curriculum
from myo_sds.envs.task_specs import TASK_SPECS, register_task
from myo_sds.run_folder import RunFolder
from myo_sds.training import CurriculumTrainer

CURRICULUM = """
name: wrist
task: wrist
defaults: {tolerance: 0.2}
stages:
  - name: narrow
    advance: {metric: score, threshold: 0.99, window: 4}
  - name: wide
    env: {preset: wide}
"""


def test_a_registered_task_trains_through_a_curriculum(tmp_path):
    register_task(toy_task.SPEC)
    try:
        (tmp_path / "c.yaml").write_text(CURRICULUM)
        assert load_curriculum(tmp_path / "c.yaml").stages[1].distribution.target.high == 0.6
        env = gym.make("myosds/ToyWristWIDE-v0")  # its gymnasium ids came with the registration
        obs, _ = env.reset(seed=0)
        assert obs.shape == (63,) and -0.6 <= env.unwrapped.task.target <= 0.6
        config = write_config(tmp_path, total=128, curriculum=CURRICULUM)
        trainer = CurriculumTrainer.start(config, run_dir=tmp_path / "run", progress=False)
        state = trainer.run()
        trainer.close()
        assert state.num_timesteps == 128
        episodes = RunFolder(tmp_path / "run").read_episodes()
        assert len(episodes) == 2 * (64 // 20) and all(e.length == 20 for e in episodes)  # 2 envs x 64 steps
        for e in episodes:  # the registered rule: solved steps over the 20-step horizon
            assert e.score == pytest.approx(e.solved_steps / 20)
    finally:
        TASK_SPECS.pop("wrist")
    with pytest.raises(ConfigError, match="task: 'wrist' is not one of baoding, die"):
        load_curriculum(tmp_path / "c.yaml")
