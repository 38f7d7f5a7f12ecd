"""Step-by-step parity with myosuite's official ``myoChallengeBaodingP1-v1`` / ``P2-v1``.

Same seed (hence the same task instance: our presets draw in the official order), or the same
pinned task instance and state, plus the same actions must give the same observations,
rewards, solved flags and termination step, for whole episodes, drops included.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from myo_sds.envs.baoding import DIRECTIONS, BaodingEnv, BaodingTask

gym = pytest.importorskip("gymnasium")
pytest.importorskip("myosuite")

OFFICIAL = {"p1": "myoChallengeBaodingP1-v1", "p2": "myoChallengeBaodingP2-v1"}


def official_env(preset: str, **kwargs):
    import myosuite  # noqa: F401

    return gym.make(OFFICIAL[preset], **kwargs)


def official_task(env) -> BaodingTask:
    """The task instance the official env drew at its last reset, in our terms."""
    u = env.unwrapped
    model = u.model
    period = (2 * np.pi * 1 * u.dt) / u.goal[1, 0] if u.goal[1, 0] else math.inf
    bodies, geoms = (u.object1_bid, u.object2_bid), (u.object1_gid, u.object2_gid)
    return BaodingTask(
        direction=DIRECTIONS[u.which_task.value], period=abs(period),
        x_radius=float(u.x_radius), y_radius=float(u.y_radius),
        start_angle=float(u.ball_1_starting_angle),
        ball_size=tuple(float(model.geom_size[g, 0]) for g in geoms),
        ball_mass=tuple(float(model.body_mass[b]) for b in bodies),
        ball_friction=tuple(tuple(float(v) for v in model.geom_friction[g]) for g in geoms))


def compare_episode(ours, official, action_seed: int, steps: int = 200) -> tuple[int, bool]:
    """Step both envs with the same actions to the end; return (length, terminated)."""
    rng = np.random.default_rng(action_seed)
    for step in range(steps):
        action = np.clip(rng.normal(0.1, 0.5, 39), -1.2, 1.2).astype(np.float32)
        o_obs, o_rew, o_term, o_trunc, o_info = official.step(action)
        obs, rew, term, trunc, info = ours.step(action)
        assert np.abs(obs - o_obs).max() <= 1e-6, f"observation differs at step {step}"
        assert rew == pytest.approx(o_rew, abs=1e-6), f"reward differs at step {step}"
        assert bool(info["solved"]) == bool(o_info["solved"]), f"solved differs at step {step}"
        for key in ("pos_dist_1", "pos_dist_2", "act_reg", "sparse"):
            assert info[key] == pytest.approx(o_info[key], abs=1e-9), key
        assert term == o_term and trunc == o_trunc, f"termination differs at step {step}"
        if term or trunc:
            return step + 1, term
    return steps, False


@pytest.mark.parametrize("preset", ["p1", "p2"])
def test_same_seed_gives_same_task_and_episode(preset):
    official, ours = official_env(preset), BaodingEnv(preset)
    lengths = []
    for seed in range(4):
        o_obs, _ = official.reset(seed=seed)
        obs, info = ours.reset(seed=seed)
        expected = official_task(official)
        # The official env keeps only the trajectory, so its period is recovered to ~1e-15.
        assert info["task"].period == pytest.approx(expected.period, rel=1e-12)
        assert info["task"] == BaodingTask(**{**expected.__dict__, "period": info["task"].period})
        np.testing.assert_array_equal(obs, o_obs)
        length, terminated = compare_episode(ours, official, action_seed=seed)
        assert terminated  # random actions drop the balls: the drop step must agree
        lengths.append(length)
    assert min(lengths) > 5


@pytest.mark.parametrize("preset", ["p1", "p2"])
def test_full_200_step_episodes_match(preset):
    """With the drop height far below the hand the episodes run the whole horizon."""
    official = official_env(preset, drop_th=-100.0)
    ours = BaodingEnv(preset, drop_height=-100.0)
    for seed in (5, 6):
        official.reset(seed=seed)
        ours.reset(seed=seed)
        length, terminated = compare_episode(ours, official, action_seed=100 + seed)
        assert (length, terminated) == (200, False)


@pytest.mark.parametrize("preset", ["p1", "p2"])
def test_pinned_task_and_state_match(preset):
    """Our env pinned to the official env's task instance and a perturbed state."""
    official, ours = official_env(preset), BaodingEnv(preset)
    for seed in (21, 22):
        official.reset(seed=seed)
        u = official.unwrapped
        rng = np.random.default_rng(seed)
        qpos = u.data.qpos.copy()
        qpos[3:23] += rng.uniform(-0.1, 0.1, 20)
        qvel = rng.normal(0, 0.05, u.model.nv)
        act = rng.uniform(0, 0.3, u.model.na)
        u.data.qpos[:], u.data.qvel[:], u.data.act[:] = qpos, qvel, act
        import mujoco

        mujoco.mj_forward(u.model, u.data)
        obs, _ = ours.reset(seed=seed + 1000, options={
            "task": official_task(official).to_dict(),
            "state": {"qpos": qpos, "qvel": qvel, "act": act}})
        o_obs = u._obs_dict_to_vec(u.get_obs_dict(u._accessor)).astype(np.float32)
        np.testing.assert_allclose(obs, o_obs, atol=1e-6)
        compare_episode(ours, official, action_seed=seed)
