"""Die reorientation env: spaces, determinism, presets, pinned tasks, drops, bad input, and
step-by-step parity with myosuite's ``myoChallengeDieReorientP1-v0`` / ``P2-v0``."""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import myo_sds.envs  # noqa: F401  (registers the ids)
from myo_sds.envs.die import DieEnv, DieKnobs, DieTask
from myo_sds.envs.metrics import EpisodeResult
from myo_sds.envs.physics import euler_to_quat, mat_to_euler

OFFICIAL = {"p1": "myoChallengeDieReorientP1-v0", "p2": "myoChallengeDieReorientP2-v0"}


def test_spaces_and_ids():
    env = gym.make("myosds/DieP2-v0").unwrapped
    assert env.preset == "p2" and env.observation_space.shape == (102,)
    assert env.action_space.shape == (39,) and env.dt == pytest.approx(0.01)
    obs, info = env.reset(seed=0)
    assert obs.dtype == np.float32 and isinstance(info["task"], DieTask)
    obs, reward, *_ , info = env.step(env.action_space.sample())
    assert reward == pytest.approx(100 * info["pos_dist"] + info["rot_dist"])


def test_same_seed_same_episode():
    a, b = DieEnv("p2"), DieEnv("p2")
    for env in (a, b):
        env.reset(seed=3)
    assert a.task == b.task
    rng = np.random.default_rng(0)
    for _ in range(20):
        action = rng.uniform(-1, 1, 39).astype(np.float32)
        np.testing.assert_array_equal(a.step(action)[0], b.step(action)[0])


def test_presets_equal_official_ranges():
    p1, p2 = DieKnobs.parse("p1"), DieKnobs.parse("p2")
    assert (p1.goal_position.low, p1.goal_position.high) == (-0.010, 0.010)
    assert all((r.low, r.high) == (-1.57, 1.57) for r in p1.goal_rotation)
    assert p1.size_change == 0 and (p1.mass.low, p1.mass.high) == (0.108, 0.108)
    assert (p2.goal_position.low, p2.goal_position.high) == (-0.020, 0.020)
    assert all((r.low, r.high) == (-3.14, 3.14) for r in p2.goal_rotation)
    assert p2.size_change == 0.007 and (p2.mass.low, p2.mass.high) == (0.050, 0.250)
    assert p2.friction_change == (0.2, 0.001, 0.00002)
    assert (p1.position_threshold, p1.rotation_threshold, p1.drop_threshold) == (0.025, 0.262, 0.2)
    assert dict(p1.reward_weights) == {"pos_dist": 100.0, "rot_dist": 1.0, "bonus": 0.0,
                                       "act_reg": 0.0, "penalty": 0.0}


def test_goal_rotation_per_axis_and_pinned_goal():
    env = DieEnv(goal_rotation=[[0, 0], [0.5, 0.5], [-1, 1]], goal_position=0.0)
    env.reset(seed=1)
    assert env.task.goal_euler[:2] == (0.0, 0.5) and -1 <= env.task.goal_euler[2] <= 1
    assert env.task.goal_offset == (0.0, 0.0, 0.0)
    task = {**env.task.to_dict(), "goal_euler": [0.3, -0.2, 1.0]}
    obs, _ = env.reset(seed=2, options={"task": task})
    np.testing.assert_allclose(obs[57:60], [0.3, -0.2, 1.0], atol=1e-6)  # goal Euler angles observed


def test_euler_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(20):
        euler = rng.uniform(-1.4, 1.4, 3)
        matrix = np.zeros(9)
        mujoco.mju_quat2Mat(matrix, euler_to_quat(euler))
        np.testing.assert_allclose(mat_to_euler(matrix.reshape(3, 3)), euler, atol=1e-9)


def test_drop_terminates_and_scores_as_official():
    env = DieEnv()
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for step in range(150):
        _, _, terminated, truncated, info = env.step(rng.uniform(-1, 1, 39).astype(np.float32))
        if terminated or truncated:
            break
    assert terminated and info["dropped"] and info["penalty"] == -1.0
    result = info["episode_result"]
    assert result.task == "die" and result.length == step + 1 and result.horizon == 150
    # Official die score: an episode succeeds when solved on more than 5 steps.
    assert EpisodeResult(6, 150, 150, False, 0.1, task="die").score == 1.0
    assert EpisodeResult(5, 150, 150, False, 0.1, task="die").score == 0.0


@pytest.mark.parametrize("knobs,message", [
    ({"goal_rotaton": 1}, "did you mean 'goal_rotation'"),
    ({"goal_rotation": [2, 1]}, "reversed"),
    ({"mass": 0}, "must be > 0"),
    ({"size_change": -0.01}, "must be >= 0"),
    ({"friction_change": [0.1, 0.2]}, "expected 3 numbers"),
    ({"reward_weights": {"distance": 1}}, "unknown reward term"),
])
def test_bad_knobs(knobs, message):
    with pytest.raises(ValueError, match=message):
        DieEnv(**knobs)


def test_nan_action_rejected():
    env = DieEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(np.full(39, np.nan, np.float32))


# -- parity with the official env ----------------------------------------------------------

def official_env(preset: str, **kwargs):
    pytest.importorskip("myosuite")
    return gym.make(OFFICIAL[preset], **kwargs)


def compare_episode(ours, official, action_seed: int) -> tuple[int, bool]:
    rng = np.random.default_rng(action_seed)
    for step in range(150):
        action = np.clip(rng.normal(0.0, 0.6, 39), -1.3, 1.3).astype(np.float32)
        o_obs, o_rew, o_term, o_trunc, o_info = official.step(action)
        obs, rew, term, trunc, info = ours.step(action)
        assert np.abs(obs - o_obs).max() <= 1e-6, f"observation differs at step {step}"
        assert rew == pytest.approx(o_rew, abs=1e-6), f"reward differs at step {step}"
        assert bool(info["solved"]) == bool(o_info["solved"])
        assert (term, trunc) == (o_term, o_trunc), f"termination differs at step {step}"
        if term or trunc:
            return step + 1, term
    return 150, False


@pytest.mark.parametrize("preset", ["p1", "p2"])
def test_parity_same_seed(preset):
    official, ours = official_env(preset), DieEnv(preset)
    for seed in range(3):
        o_obs, _ = official.reset(seed=seed)
        obs, _ = ours.reset(seed=seed)
        np.testing.assert_array_equal(obs, o_obs)
        u = official.unwrapped
        for field in ("body_pos", "body_quat", "body_mass", "body_inertia", "geom_size", "geom_pos",
                      "geom_friction", "geom_aabb", "geom_rbound", "bvh_aabb", "dof_invweight0"):
            np.testing.assert_array_equal(getattr(ours.model, field), getattr(u.model, field), err_msg=field)
        length, terminated = compare_episode(ours, official, action_seed=seed)
        assert terminated and length > 5


@pytest.mark.parametrize("preset", ["p1", "p2"])
def test_parity_full_episodes_and_pinned_state(preset):
    official, ours = official_env(preset, drop_th=10.0), DieEnv(preset, drop_threshold=10.0)
    official.reset(seed=7)
    ours.reset(seed=7)
    assert compare_episode(ours, official, action_seed=70) == (150, False)
    # Pinned: our env given the official env's task instance and a perturbed state.
    official.reset(seed=8)
    u = official.unwrapped
    rng = np.random.default_rng(8)
    qpos = u.data.qpos.copy()
    qpos[3:23] += rng.uniform(-0.1, 0.1, 20)
    qvel = rng.normal(0, 0.05, u.model.nv)
    u.data.qpos[:], u.data.qvel[:] = qpos, qvel
    mujoco.mj_forward(u.model, u.data)
    task = DieTask(goal_offset=tuple(u.model.body_pos[u.goal_bid] - u.goal_init_pos),
                   goal_euler=tuple(mat_to_euler(u.data.site_xmat[u.goal_sid].reshape(3, 3))),
                   friction=tuple(map(tuple, u.model.geom_friction[u.object_gid0:u.object_gidn])),
                   mass=float(u.model.body_mass[u.object_bid]),
                   size_change=float(u.model.geom_size[u.target_gid, 0] - u.target_default_size[0]))
    obs, _ = ours.reset(seed=1234, options={"task": task, "state": {"qpos": qpos, "qvel": qvel}})
    o_obs = u._obs_dict_to_vec(u._get_obs_dict(u._accessor)).astype(np.float32)
    np.testing.assert_allclose(obs, o_obs, atol=1e-6)
    compare_episode(ours, official, action_seed=80)


def test_recorded_starts_restore_the_hand_and_die_of_earlier_episodes_with_a_goal_drawn_as_usual():
    recorded = {"probability": 1.0, "every": 1, "solved_only": False, "capacity": 50}
    env = DieEnv("p1", recorded_start=recorded)
    reference = DieEnv("p1")  # the same knobs without recorded starts: the goals drawn at each reset
    env.reset(seed=3)
    seen = []
    rng = np.random.default_rng(0)
    for _ in range(30):
        _, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, 39).astype(np.float32))
        if not terminated:
            seen.append((env.data.qpos.copy(), env.data.qvel.copy(), env.data.act.copy()))
        if terminated or truncated:
            break
    assert env.state_bank.size == min(50, len(seen)) > 0
    _, info = env.reset(seed=11)
    assert env.recorded_start
    assert any(np.array_equal(env.data.qpos, q) and np.array_equal(env.data.qvel, v) and np.array_equal(env.data.act, a)
               for q, v, a in seen)
    # The goal is drawn first, as without recorded starts (draw order: envs/die.py).
    _, expected = reference.reset(seed=11)
    assert info["task"] == expected["task"]


def test_episodes_report_the_goal_angle_at_their_start():
    # The die rests at Euler angles (0, 0, 0), so the start's orientation error is the goal's angles' norm.
    env = DieEnv("p1")
    task = {**env.reset(seed=0)[1]["task"].to_dict(), "goal_euler": [0.3, -0.2, 1.0]}
    env.reset(seed=2, options={"task": task})
    rng = np.random.default_rng(0)
    terminated = truncated = False
    while not (terminated or truncated):
        _, _, terminated, truncated, info = env.step(rng.uniform(-1, 1, 39).astype(np.float32))
    # The episode keeps its start's error, not its end's (the die has moved since).
    assert info["episode_result"].start_phase == pytest.approx(np.sqrt(0.3**2 + 0.2**2 + 1.0**2))
    assert -info["rot_dist"] != pytest.approx(np.sqrt(1.13))
    # A recorded start turns the die: the error is measured from where the restored die points.
    recorded = DieEnv("p1", recorded_start={"probability": 1.0, "every": 1, "solved_only": False, "capacity": 5})
    recorded.reset(seed=3)
    for _ in range(10):
        recorded.step(rng.uniform(-1, 1, 39).astype(np.float32))
    recorded.reset(seed=4)
    assert recorded.recorded_start
    die_euler = mat_to_euler(recorded.data.site_xmat[recorded.model.site("object_o").id].reshape(3, 3))
    expected = np.linalg.norm(np.asarray(recorded.task.goal_euler) - die_euler)
    terminated = truncated = False
    while not (terminated or truncated):
        _, _, terminated, truncated, info = recorded.step(rng.uniform(-1, 1, 39).astype(np.float32))
    assert info["episode_result"].start_phase == pytest.approx(expected) and expected > 0


def test_shaping_terms_match_hand_computed_values_and_leave_the_score_alone():
    """rot_kernel = w / (d^2 + w) of the rotation error d; tip_dist = -(sum of the five fingertips'
    distances to the die); die_speed = -|the die's linear velocity|; the reward is the weighted sum
    of the terms; the score is the official one whatever the weights."""
    weights = {"rot_kernel": 0.3, "tip_dist": 2.0, "die_speed": 0.5, "solved": 25.0, "pos_dist": 10.0}
    env = DieEnv(rotation_kernel_width=0.5, reward_weights=weights)
    official = DieEnv()
    env.reset(seed=4), official.reset(seed=4)
    rng = np.random.default_rng(1)
    for _ in range(30):
        action = rng.uniform(-1, 1, 39)
        obs, reward, terminated, truncated, info = env.step(action)
        official_obs, *_, official_info = official.step(action)
        np.testing.assert_array_equal(obs, official_obs)
        d = np.linalg.norm(obs[60:63])
        assert info["rot_kernel"] == pytest.approx(0.5 / (d**2 + 0.5))
        data = env.data
        tips = [data.site(name).xpos for name in ("THtip", "IFtip", "MFtip", "RFtip", "LFtip")]
        die = data.site("object_o").xpos
        assert info["tip_dist"] == pytest.approx(-sum(np.linalg.norm(t - die) for t in tips))
        assert info["die_speed"] == pytest.approx(-np.linalg.norm(data.qvel[-6:-3]))
        assert reward == pytest.approx(sum(w * info[k] for k, w in weights.items()))
        assert info["solved"] == official_info["solved"]
        if terminated or truncated:
            break


def test_pku_phase_one_terms_match_hand_computed_values():
    """PKU-MARL's 2022 phase-1 reward (reorient_v0.py at cb992b2): pos 3 x 1/(1 + d^2), rot
    1 x (-0.5 r + 0.5/(1 + r^2)), die speed 1 x -|v|, fingertips 0.3 x -(sum of distances), solved
    3, drop 1 x -1; checked at hand-picked errors and along an episode."""
    weights = {"pos_kernel": 3.0, "rot_shaped": 1.0, "die_speed": 1.0, "tip_dist": 0.3, "solved": 3.0, "penalty": 1.0}
    env = DieEnv(reward_weights=weights)
    obs, _ = env.reset(seed=2)
    # By hand: at d = 0.1 m, 1/(1 + 0.01) = 0.990099; at r = 1 rad, -0.5 + 0.5/2 = -0.25.
    env._obs[51:54], env._obs[60:63] = (0.1, 0.0, 0.0), (0.6, 0.8, 0.0)
    terms = env._reward_terms()
    assert terms["pos_kernel"] == pytest.approx(0.990099, abs=1e-6)
    assert terms["rot_shaped"] == pytest.approx(-0.25)
    env._obs[51:54], env._obs[60:63] = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    terms = env._reward_terms()
    assert (terms["pos_kernel"], terms["rot_shaped"]) == (1.0, 0.5)  # on the goal: the most either pays
    env.reset(seed=2)
    rng = np.random.default_rng(3)
    for _ in range(40):
        obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, 39))
        d, r = np.linalg.norm(obs[51:54]), np.linalg.norm(obs[60:63])
        assert info["pos_kernel"] == pytest.approx(1 / (1 + d**2))
        assert info["rot_shaped"] == pytest.approx(-0.5 * r + 0.5 / (1 + r**2))
        assert info["penalty"] == -float(d > 0.2)
        assert reward == pytest.approx(sum(w * info[k] for k, w in weights.items()))
        if terminated or truncated:
            break


def test_alive_is_one_on_each_step_the_die_is_held_and_zero_on_the_drop():
    """alive = 1 while the die is within drop_threshold of the goal, 0 on the step it is dropped
    (the episode ends there); a tight threshold makes the hand drop it within a few steps."""
    weights = {"alive": 2.0, "rot_dist": 1.0}
    env = DieEnv(goal_position=0.0, drop_threshold=0.004, reward_weights=weights)
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    alive = []
    for _ in range(150):
        obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, 39))
        held = np.linalg.norm(obs[51:54]) <= 0.004
        assert info["alive"] == float(held)
        assert reward == pytest.approx(2.0 * info["alive"] - np.linalg.norm(obs[60:63]))
        alive.append(info["alive"])
        if terminated or truncated:
            break
    assert terminated and alive[-1] == 0.0 and len(alive) > 1 and all(a == 1.0 for a in alive[:-1])


def test_chained_goals_turn_the_goal_on_from_the_current_one_and_count_the_goals_reached():
    """After 2 solved steps the goal turns by a random rotation composed onto the current one (a
    goal on the resting die is solved at once, so the chain starts at step 2), seeded; the
    official score rule counts the solved steps of every goal."""
    def play(seed):
        env = DieEnv(goal_position=0.0, goal_rotation=0.0, goal_chain={"after_solved": 2, "offset": [-0.3, 0.3]},
                     horizon=6)
        env.reset(seed=seed)
        goals = [env.model.body_quat[env.model.body("target").id].copy()]
        for _ in range(6):
            *_, info = env.step(np.zeros(39))
            goals.append(env.model.body_quat[env.model.body("target").id].copy())
        return env, np.array(goals), info

    env, goals, info = play(2)
    assert np.allclose(goals[0], [1, 0, 0, 0]) and np.allclose(goals[1], goals[0])
    changed = [i for i in range(1, len(goals)) if not np.allclose(goals[i], goals[i - 1])]
    assert changed[0] == 2  # the second solved step draws the next goal
    # The new goal is the old one turned by at most 0.3 rad about each axis: its angle from it.
    turn = np.empty(4)
    mujoco.mju_mulQuat(turn, np.array([goals[1][0], *-goals[1][1:]]), goals[2])
    assert 0 < 2 * np.arccos(min(1.0, abs(turn[0]))) <= np.sqrt(3) * 0.3 + 1e-9
    # The task records the goal; the observation shows it the step it is drawn.
    np.testing.assert_allclose(euler_to_quat(np.array(env.task.goal_euler)), goals[-1], atol=1e-9)
    result = info["episode_result"]  # the 6-step episode: its goals and its solved steps on all of them
    assert result.goals_reached == len(changed) >= 1 and result.solved_steps >= 2 * len(changed)
    assert result.score == (1.0 if result.solved_steps > 5 else 0.0)
    _, again, _ = play(2)
    np.testing.assert_array_equal(goals, again)  # seeded: the same chain
    _, other, _ = play(3)
    assert not np.allclose(goals, other)
    env = DieEnv(goal_chain={"after_solved": 1})
    assert env.knobs.goal_chain.offset is None  # null: the stage's goal_rotation
    with pytest.raises(ValueError, match="goal_chain.after_solved: expected a whole number >= 1"):
        DieEnv(goal_chain={"after_solved": 0})
    with pytest.raises(ValueError, match="goal_chain.afer: unknown key"):
        DieEnv(goal_chain={"afer": 2})
