"""Large trust-region updates (PKU-MARL's phase-1 die regime, experiments/configs/die_p1_pku_phase1.yaml):
an update's epochs stop once its approximate KL passes 1.5 x target_kl, and the update's LSTM
sequences are cut every ``ppo.sequence_length`` steps however long the rollout is."""

from __future__ import annotations

from tiny_run import write_config

from myo_sds.training import CurriculumTrainer

DIE = """
name: die-pku
task: die
defaults: {reward_weights: {pos_kernel: 3.0, rot_shaped: 1.0, die_speed: 1.0, tip_dist: 0.3, solved: 3.0, penalty: 1.0}}
stages:
  - name: p1
    advance: {metric: score, threshold: 0.99, window: 8}
"""


def _one_update(tmp_path, name: str, target_kl: str):
    from myo_sds.sb3_internals import start_training

    config = write_config(tmp_path, total=100_000, curriculum=DIE)
    # 2 envs x 256 steps, minibatches of 64: 8 per epoch, 10 epochs, at a rate that moves the policy fast.
    overrides = ("ppo.n_steps=256", "ppo.batch_size=64", "ppo.n_epochs=10", "ppo.learning_rate=0.01",
                 f"ppo.target_kl={target_kl}", "ppo.sequence_length=16", "ppo.gamma=0.995", "ppo.gae_lambda=0.97")
    trainer = CurriculumTrainer.start(config, overrides, run_dir=tmp_path / name, progress=False)
    model = trainer.model
    start_training(model, 100_000, trainer.episode_callback)
    assert trainer.rollouts.collect(model, trainer.episode_callback)
    lengths = {batch.observations.shape[0] // len(batch.lstm_states.pi[0][0]) for batch in model.rollout_buffer.get(64)}
    model.train()
    steps = max(int(s["step"]) for s in model.policy.optimizer.state_dict()["state"].values())
    epochs = model._n_updates
    trainer.close()
    return lengths, steps, epochs


def test_an_update_stops_its_epochs_at_the_kl_limit_and_its_sequences_are_cut(tmp_path):
    lengths, steps, epochs = _one_update(tmp_path, "free", "null")
    assert max(lengths) <= 16  # padded to at most the cut, though episodes run up to 150 steps
    assert (steps, epochs) == (80, 10)  # every minibatch of every epoch
    _, limited_steps, limited_epochs = _one_update(tmp_path, "limited", "1.0e-4")
    assert limited_epochs == 1 and 1 <= limited_steps < 8  # stopped within the first epoch
