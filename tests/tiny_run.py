"""A tiny two-stage Baoding run (2 envs, 16-unit LSTM) that trains in seconds, for tests."""

from __future__ import annotations

from pathlib import Path

# Stage 1 is easy: with the balls started on their targets and a 3 cm solved radius, even the
# untrained policy scores ~0.04 > 0.01. Stage 2 (the official radius, score 0.9) is not passed.
CURRICULUM = """
name: two-stage
task: baoding
defaults: {direction: hold, period: static, rsi_probability: 1.0, start_angle: uniform}
stages:
  - name: easy
    env: {solved_radius: 0.03}
    advance: {metric: score, threshold: 0.01, window: 8}
  - name: hard
    env: {direction: ccw, period: 20}
    advance: {metric: score, threshold: 0.9, window: 8}
    ppo: {learning_rate: 1.0e-4, n_steps: 32, batch_size: 64}
"""

CONFIG = """
curriculum: curriculum.yaml
seed: 5
n_envs: 2
total_steps: {total}
checkpoint_every: 256
keep_checkpoints: 2
output_dir: runs
policy: {{lstm_hidden_size: 16, net_arch: [16], log_std_init: -1.0}}
ppo: {{learning_rate: 3.0e-4, n_steps: 64, batch_size: 64, n_epochs: 1}}
"""


def write_config(folder: Path, total: int, curriculum: str = CURRICULUM) -> Path:
    (folder / "curriculum.yaml").write_text(curriculum)
    path = folder / "run.yaml"
    path.write_text(CONFIG.format(total=total))
    return path


def scalar_events(tensorboard_dir: Path, tag: str) -> list:
    """A run's TensorBoard events of one scalar tag (each has .step and .value), in order."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    accumulator = EventAccumulator(str(tensorboard_dir), size_guidance={"scalars": 0})
    accumulator.Reload()
    return accumulator.Scalars(tag)
