"""Starting a new run from a trained policy (`train.py --config ... --init-from MODEL`)."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import torch
from tiny_run import write_config

from myo_sds.curricula.schema import ConfigError
from myo_sds.training import CurriculumTrainer


def test_a_new_run_starts_from_the_trained_weights_optimizer_and_statistics(tiny_run, tmp_path):
    from myo_sds.cli.train import main

    assert main(["--export", str(tiny_run.path), "--to", str(tmp_path / "model")]) == 0
    trainer = CurriculumTrainer.start(write_config(tmp_path, total=256), run_dir=tmp_path / "tuned", progress=False,
                                      init_from=tmp_path / "model")
    trained = tiny_run.trainer.model
    for (name, mine), theirs in zip(trainer.model.policy.state_dict().items(), trained.policy.state_dict().values()):
        assert torch.equal(mine, theirs), name
    mine, theirs = trainer.model.policy.optimizer.state_dict(), trained.policy.optimizer.state_dict()
    assert mine["state"].keys() == theirs["state"].keys() and len(mine["state"]) > 0
    for key, moments in theirs["state"].items():
        assert torch.equal(mine["state"][key]["exp_avg_sq"], moments["exp_avg_sq"])
    with (tmp_path / "model" / "final_vecnormalize.pkl").open("rb") as file:
        statistics = pickle.load(file)
    assert np.array_equal(trainer.venv.obs_rms.mean, statistics.obs_rms.mean)
    assert trainer.venv.obs_rms.count == statistics.obs_rms.count > 1000
    # The new run starts at its own stage 1 and step 0, and trains.
    state = trainer.run()
    trainer.close()
    assert state.num_timesteps == 256 and state.history[0].stage == "easy"


def test_init_from_a_policy_of_another_shape_is_one_error_and_leaves_no_folder(tiny_run, tmp_path):
    config = write_config(tmp_path, total=256)
    config.write_text(config.read_text().replace("lstm_hidden_size: 16", "lstm_hidden_size: 32"))
    with pytest.raises(ConfigError, match="does not fit this config's `policy`") as error:
        CurriculumTrainer.start(config, run_dir=tmp_path / "tuned", progress=False, init_from=tiny_run.path)
    # The line says what differs (a parameter and both shapes), not only torch's heading.
    assert "size mismatch for" in str(error.value) and "the shape in current model is torch.Size" in str(error.value)
    assert not str(error.value).endswith(":")
    assert not (tmp_path / "tuned").exists()
    with pytest.raises(ConfigError, match="--init-from: .*nothing: not a run folder"):
        CurriculumTrainer.start(config, run_dir=tmp_path / "tuned", progress=False, init_from=tmp_path / "nothing")
    with pytest.raises(ConfigError, match="no such checkpoint"):
        CurriculumTrainer.start(config, run_dir=tmp_path / "tuned", progress=False, init_from=tmp_path / "x.zip")


def test_the_model_card_of_a_fine_tuned_run_names_the_policy_it_started_from(tiny_run, tmp_path, monkeypatch):
    import sys

    from myo_sds.cli.train import main

    assert main(["--export", str(tiny_run.path), "--to", str(tmp_path / "model")]) == 0
    assert "did not start from scratch" not in (tmp_path / "model" / "README.md").read_text()
    argv = ["train.py", "--config", str(write_config(tmp_path, total=128)), "--init-from", str(tmp_path / "model"),
            "--run-dir", str(tmp_path / "tuned"), "--no-progress"]
    monkeypatch.setattr(sys, "argv", argv)  # what the run's command.txt records
    assert main(argv[1:]) == 0
    assert main(["--export", str(tmp_path / "tuned"), "--to", str(tmp_path / "tuned_model")]) == 0
    card = (tmp_path / "tuned_model" / "README.md").read_text()
    assert f"it started from `{tmp_path / 'model'}` (`--init-from`" in card


def test_init_from_a_policy_of_another_task_names_the_observation_size(tmp_path):
    """The shipped die policy into a Baoding config: the cause is the task (102 observations, not
    86), not the network settings."""
    from pathlib import Path

    die_policy = Path(__file__).resolve().parents[1] / "models" / "die_p1"
    with pytest.raises(ConfigError, match="trained on observations of 102 values, this config's task has 86 "
                                          "\\(a policy of another task cannot start this one\\)"):
        CurriculumTrainer.start(write_config(tmp_path, total=256), run_dir=tmp_path / "run", progress=False,
                                init_from=die_policy)
    assert not (tmp_path / "run").exists()
