"""The same config on a two-node Ray cluster of this machine: one worker on each node."""

from __future__ import annotations

import pytest
from tiny_run import write_config

from myo_sds.curricula.schema import ConfigError
from myo_sds.curricula.state import RunStatus
from myo_sds.training import CurriculumTrainer

ray = pytest.importorskip("ray")
pytestmark = pytest.mark.slow  # a two-node cluster starts and stops


def test_a_two_node_cluster_trains_the_same_config_with_only_the_backend_keys_changed(tmp_path):
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    cluster.add_node(num_cpus=1)
    try:
        config = write_config(tmp_path, total=512)
        trainer = CurriculumTrainer.start(
            config, ("rollout.backend=ray", "rollout.workers=2", f"rollout.address={cluster.address}"),
            run_dir=tmp_path / "run", progress=False)
        nodes = {ray.get(worker.node_id.remote()) for worker in trainer.rollouts.workers}
        assert len(nodes) == 2 and len(ray.nodes()) == 2  # one worker on each node
        state = trainer.run()
        assert state.status is RunStatus.BUDGET_REACHED and state.num_timesteps == 512 and state.stage_index == 1
        trainer.close()
    finally:
        ray.shutdown()
        cluster.shutdown()


def test_an_unreachable_address_is_one_line_before_training(tmp_path):
    with pytest.raises(ConfigError, match="rollout.address: no Ray cluster answers at 127.0.0.1:9"):
        CurriculumTrainer.start(write_config(tmp_path, total=256),
                                ("rollout.backend=ray", "rollout.workers=1", "rollout.address=127.0.0.1:9"),
                                run_dir=tmp_path / "run", progress=False)
    assert not ray.is_initialized()
