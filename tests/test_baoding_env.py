"""Behaviour of our Baoding env on its own: spaces, determinism, targets, RSI, drops, bad input."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import myo_sds.envs  # noqa: F401  (registers the ids)
from myo_sds.envs.baoding import (
    OFFICIAL_START_ANGLE,
    ORBIT_CENTER,
    BaodingEnv,
    BaodingKnobs,
    BaodingTask,
)


def rollout(env: BaodingEnv, seed: int, steps: int, action_seed: int = 0):
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(action_seed)
    observations, rewards = [obs], []
    for _ in range(steps):
        obs, reward, terminated, truncated, _ = env.step(rng.uniform(-1, 1, 39).astype(np.float32))
        observations.append(obs)
        rewards.append(reward)
        if terminated or truncated:
            break
    return np.array(observations), np.array(rewards)


def test_spaces_and_dtypes():
    env = BaodingEnv()
    assert env.action_space.shape == (39,) and env.action_space.dtype == np.float32
    assert np.all(env.action_space.low == -1) and np.all(env.action_space.high == 1)
    assert env.observation_space.shape == (86,) and env.observation_space.dtype == np.float32
    obs, info = env.reset(seed=0)
    assert obs.dtype == np.float32 and obs.shape == (86,)
    assert isinstance(info["task"], BaodingTask)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert obs.shape == (86,) and isinstance(reward, float)
    for term in ("pos_dist_1", "pos_dist_2", "act_reg", "solved", "alive", "done", "sparse",
                 "dropped", "unstable", "task"):
        assert term in info
    # The reward is the weighted sum of the named terms (official weights: 5, 5).
    assert reward == pytest.approx(5 * info["pos_dist_1"] + 5 * info["pos_dist_2"])


def test_gymnasium_ids_and_checker():
    from gymnasium.utils.env_checker import check_env

    for env_id, preset in (("myosds/BaodingP1-v0", "p1"), ("myosds/BaodingP2-v0", "p2")):
        env = gym.make(env_id)
        assert env.unwrapped.preset == preset
    env = gym.make("myosds/Baoding-v0", direction="hold", period="static")
    assert env.unwrapped.knobs.direction == "hold" and env.unwrapped.knobs.period is None
    check_env(BaodingEnv(), skip_render_check=True)


def test_observation_layout_matches_state():
    env = BaodingEnv()
    obs, _ = env.reset(seed=3)
    obs, *_ = env.step(np.zeros(39, np.float32))
    data = env.data
    np.testing.assert_allclose(obs[:23], data.qpos[:23], atol=1e-6)
    np.testing.assert_allclose(obs[23:26], data.qpos[23:26], atol=1e-6)  # ball 1 centre
    np.testing.assert_allclose(obs[26:29], data.qvel[23:26] * 0.025, atol=1e-6)
    np.testing.assert_allclose(obs[41:44], obs[35:38] - obs[23:26], atol=1e-6)
    np.testing.assert_allclose(obs[47:], data.act, atol=1e-6)


def test_same_seed_same_episode_and_different_seed_differs():
    env_a, env_b = BaodingEnv("p2"), BaodingEnv("p2")
    obs_a, rew_a = rollout(env_a, seed=11, steps=40)
    obs_b, rew_b = rollout(env_b, seed=11, steps=40)
    np.testing.assert_array_equal(obs_a, obs_b)
    np.testing.assert_array_equal(rew_a, rew_b)
    assert env_a.task == env_b.task
    env_b.reset(seed=12)
    assert env_b.task != env_a.task


@pytest.mark.parametrize("direction,sign", [("ccw", 1), ("cw", -1), ("hold", 0)])
def test_target_trajectory_formula(direction, sign):
    period, rx, ry, start = 4.0, 0.024, 0.030, 0.3
    task = BaodingTask(direction, period, rx, ry, start, (0.022,) * 2, (0.043,) * 2,
                       ((1.0, 0.005, 0.0001),) * 2)
    env = BaodingEnv(drop_height=-10.0)  # never drop, so the episode runs long enough
    env.reset(seed=0, options={"task": task})
    target_1, target_2 = env._target_sites
    for step in range(60):
        if step in (0, 1, 17, 59):
            # During step t the targets sit at angle(t) = start + sign 2 pi t dt / T.
            angle = start + sign * 2 * math.pi * step * 0.025 / period
            expected_1 = (rx * math.cos(angle) - 0.0125, ry * math.sin(angle) - 0.07)
            expected_2 = (rx * math.cos(angle - math.pi) - 0.0125, ry * math.sin(angle - math.pi) - 0.07)
            env._place_targets(step)
            np.testing.assert_allclose(env.model.site_pos[target_1, :2], expected_1, atol=1e-12)
            np.testing.assert_allclose(env.model.site_pos[target_2, :2], expected_2, atol=1e-12)
        env.step(np.zeros(39, np.float32))
    assert ORBIT_CENTER == (-0.0125, -0.07)


def test_static_targets_never_move_in_the_palm():
    env = BaodingEnv(direction="ccw", period="static", drop_height=-10.0)
    env.reset(seed=0)
    assert math.isinf(env.task.period)
    target_1, target_2 = env._target_sites
    first = env.model.site_pos[[target_1, target_2]].copy()
    for _ in range(100):
        env.step(np.full(39, 0.5, np.float32))
        np.testing.assert_array_equal(env.model.site_pos[[target_1, target_2]], first)


def test_rsi_puts_balls_on_targets():
    env = BaodingEnv(rsi_probability=1.0, start_angle="uniform", finger_noise=0.1, palm_noise=0.05)
    for seed in range(5):
        obs, _ = env.reset(seed=seed)
        assert np.linalg.norm(obs[41:44]) < 1e-3 and np.linalg.norm(obs[44:47]) < 1e-3
        _, _, _, _, info = env.step(np.zeros(39, np.float32))
        assert info["solved"] == 1.0  # still on target after one step
    # Without RSI the official start leaves the targets 2.5 and 3.7 cm from the balls.
    obs, _ = BaodingEnv().reset(seed=0)
    assert np.linalg.norm(obs[41:44]) == pytest.approx(0.025, abs=2e-3)
    assert np.linalg.norm(obs[44:47]) == pytest.approx(0.037, abs=2e-3)


def _deepest_ball_contact(env: BaodingEnv) -> float:
    import mujoco
    mujoco.mj_fwdPosition(env.model, env.data)
    touching = (np.isin(env.data.contact.geom, env._ball_geoms)).any(axis=1)
    return float(-env.data.contact.dist[touching].min(initial=0.0))


def test_rsi_heights_place_the_balls_as_documented():
    # At a start angle of 0 the target orbit passes through the thumb and the fifth finger:
    # balls at their targets' height sit 3.5 and 7.1 mm inside the hand.
    kwargs = dict(direction="hold", period="static", start_angle=0.0, rsi_probability=1.0)
    on_target = BaodingEnv(rsi_height="target", **kwargs)
    obs, _ = on_target.reset(seed=0)
    assert np.linalg.norm(obs[41:44]) < 1e-9 and np.linalg.norm(obs[44:47]) < 1e-9
    assert _deepest_ball_contact(on_target) == pytest.approx(0.0071, abs=5e-4)

    clear = BaodingEnv(rsi_height="clear", **kwargs)
    obs, _ = clear.reset(seed=0)
    assert _deepest_ball_contact(clear) <= 1e-4
    # moved out along the contact normal by about the depth, so still well inside the solved radius
    assert np.linalg.norm(obs[41:44]) == pytest.approx(0.0035, abs=5e-4)
    assert np.linalg.norm(obs[44:47]) == pytest.approx(0.0071, abs=5e-4)

    rest = BaodingEnv(rsi_height="rest", **kwargs)
    obs, _ = rest.reset(seed=0)
    resting_height = rest.model.qpos0[[rest._ball_qpos[0] + 2, rest._ball_qpos[1] + 2]]
    np.testing.assert_allclose(obs[[25, 31]], resting_height)  # each ball's height as at rest
    np.testing.assert_allclose(obs[[41, 42, 44, 45]], 0.0, atol=1e-12)  # x and y on the targets


def test_rsi_height_rejects_unknown_values():
    with pytest.raises(ValueError, match="rsi_height.*clear.*target.*rest"):
        BaodingEnv(rsi_height="floating")


def test_rsi_probability_is_a_probability_over_episodes():
    env = BaodingEnv(rsi_probability=0.5)
    on_target = [np.linalg.norm(env.reset(seed=s)[0][41:44]) < 1e-3 for s in range(60)]
    assert 15 < sum(on_target) < 45


def test_on_balls_start_angle_puts_targets_near_balls():
    obs, _ = BaodingEnv(start_angle="on_balls").reset(seed=0)
    assert np.linalg.norm(obs[41:44]) < 0.015 and np.linalg.norm(obs[44:47]) < 0.015


def test_drop_terminates_with_episode_result():
    env = BaodingEnv()
    env.reset(seed=0)
    for step in range(200):
        obs, reward, terminated, truncated, info = env.step(np.zeros(39, np.float32))
        if terminated:
            break
    assert terminated and not truncated and step < 60
    assert info["dropped"] and info["alive"] == 0.0 and info["solved"] == 0.0
    assert min(obs[25], obs[31]) < 1.25
    result = info["episode_result"]
    assert result.length == step + 1 and result.dropped and result.horizon == 200
    assert result.score == result.solved_steps / 200
    assert result.start_phase == pytest.approx(OFFICIAL_START_ANGLE)  # P1's fixed start, pi / 4


def test_episode_result_records_the_random_start_phase():
    env = BaodingEnv(start_angle="uniform", horizon=2)
    phases = []
    for seed in range(3):
        env.reset(seed=seed)
        start = env.task.start_angle
        for _ in range(2):
            *_, info = env.step(np.zeros(39, np.float32))
        phases.append(info["episode_result"].start_phase)
        assert phases[-1] == pytest.approx(start % (2 * math.pi)) and 0 <= phases[-1] < 2 * math.pi
    assert len(set(phases)) == 3


def test_start_angle_list_draws_one_of_its_angles_per_reset():
    # Both placements of the balls across the palm (0 and pi: the same positions, the balls
    # swapped), plus an offset: every start lies within the offset of one of the two.
    env = BaodingEnv(start_angle=[0.0, math.pi], start_offset=[-0.1, 0.1], horizon=2)
    centres = []
    for seed in range(40):
        env.reset(seed=seed)
        start = env.task.start_angle
        centre = min((0.0, math.pi), key=lambda c: abs(start - c))
        assert abs(start - centre) <= 0.1
        centres.append(centre)
    assert 10 <= centres.count(0.0) <= 30  # both drawn, about evenly
    env.reset(seed=7)
    again = env.task.start_angle
    env.reset(seed=7)
    assert env.task.start_angle == again  # seeded
    with pytest.raises(ValueError, match=r"start_angle\[1\]"):
        BaodingEnv(start_angle=[0.0, "across"])
    with pytest.raises(ValueError, match="empty list"):
        BaodingEnv(start_angle=[])


def test_direction_list_draws_only_its_members():
    # The 2022 winner's `task: random` drew cw or ccw (MyoSuite had no hold before v1.2.3).
    env = BaodingEnv(direction=["cw", "ccw"], period=20.0, start_angle="uniform", horizon=2)
    drawn = []
    for seed in range(60):
        env.reset(seed=seed)
        drawn.append(env.task.direction)
    assert set(drawn) == {"cw", "ccw"} and 20 <= drawn.count("cw") <= 40
    env.configure(direction="random", period=20.0, start_angle="uniform")
    assert {env.reset(seed=seed) and env.task.direction for seed in range(30)} == {"hold", "cw", "ccw"}


def test_truncates_at_horizon():
    env = BaodingEnv(drop_height=-10.0, horizon=30)
    env.reset(seed=0)
    for step in range(30):
        _, _, terminated, truncated, info = env.step(np.zeros(39, np.float32))
        assert not terminated
        assert truncated == (step == 29)
    assert info["episode_result"].length == 30


def test_episode_steps_knob_lengthens_the_episode_and_the_score_counts_over_it():
    env = BaodingEnv(drop_height=-10.0, horizon=30, episode_steps=45, rsi_probability=1.0)
    env.reset(seed=0)
    solved = 0
    for step in range(45):
        _, _, terminated, truncated, info = env.step(np.zeros(39, np.float32))
        solved += int(info["solved"])
        assert not terminated
        assert truncated == (step == 44)  # not at the constructor's 30
    result = info["episode_result"]
    assert (result.length, result.horizon, result.solved_steps) == (45, 45, solved)
    assert solved > 0 and result.score == pytest.approx(solved / 45)
    env.configure(episode_steps=None)  # back to the constructor's horizon
    env.reset(seed=0)
    for step in range(30):
        _, _, _, truncated, info = env.step(np.zeros(39, np.float32))
    assert truncated and info["episode_result"].horizon == 30
    assert BaodingKnobs.parse("p1", episode_steps="4e2").episode_steps == 400


def test_presets_equal_official_ranges():
    p1 = BaodingKnobs.parse("p1")
    assert p1.direction == "ccw" and (p1.period.low, p1.period.high) == (5.0, 5.0)
    assert (p1.x_radius.low, p1.y_radius.low) == (0.025, 0.028)
    assert p1.start_angle == "fixed" and OFFICIAL_START_ANGLE == pytest.approx(math.pi / 4)
    assert p1.ball_size is None and p1.ball_mass is None and p1.ball_friction is None
    assert p1.drop_height == 1.25 and p1.solved_radius == 0.015
    assert dict(p1.reward_weights) == {"pos_dist_1": 5.0, "pos_dist_2": 5.0}
    p2 = BaodingKnobs.parse("p2")
    assert p2.direction == "random" and p2.start_angle == "uniform"
    assert (p2.period.low, p2.period.high) == (4.0, 6.0)
    assert (p2.x_radius.low, p2.x_radius.high) == (0.020, 0.030)
    assert (p2.y_radius.low, p2.y_radius.high) == (0.022, 0.032)
    assert (p2.ball_size.low, p2.ball_size.high) == (0.018, 0.024)
    assert (p2.ball_mass.low, p2.ball_mass.high) == (0.030, 0.300)
    np.testing.assert_allclose(p2.ball_friction[0], (0.8, 0.004, 0.00008))
    np.testing.assert_allclose(p2.ball_friction[1], (1.2, 0.006, 0.00012))
    env = BaodingEnv()
    assert env.model.geom_size[env._ball_geoms[0], 0] == 0.022
    assert env.model.body_mass[env._ball_bodies[0]] == pytest.approx(0.043)


def test_configure_replaces_distribution_from_preset():
    env = BaodingEnv("p2")
    env.configure(direction="hold", period="static", rsi_probability=1.0)
    assert env.knobs.direction == "hold" and env.knobs.ball_mass is not None  # p2 kept
    env.configure(preset="p1", period=[10, 12])
    assert env.knobs.direction == "ccw" and env.knobs.ball_mass is None
    env.reset(seed=1)
    assert 10 <= env.task.period <= 12


@pytest.mark.parametrize("knobs,message", [
    ({"directon": "cw"}, "did you mean 'direction'"),
    ({"direction": "sideways"}, "not one of hold, cw, ccw, random"),
    ({"direction": ["cw", "hold", "cw"]}, "repeats a direction"),
    ({"direction": ["cw", "random"]}, "direction[1]: 'random' is not one of hold, cw, ccw"),
    ({"direction": []}, "empty list"),
    ({"period": [6, 4]}, "reversed"),
    ({"period": []}, "a range is [low, high]"),
    ({"period": -1}, "must be > 0"),
    ({"x_radius": "wide"}, "expected a number"),
    ({"rsi_probability": 1.5}, "probability must be in [0, 1]"),
    ({"ball_friction": [1, 2]}, "expected 3 numbers"),
    ({"finger_noise": -0.1}, "must be >= 0"),
    ({"reward_weights": {"pos_dist": 1}}, "unknown reward term"),
    ({"ball_mass": float("nan")}, "finite"),
    ({"episode_steps": 0}, "expected a whole number >= 1"),
    ({"episode_steps": 1.5}, "expected a whole number >= 1"),
    ({"episode_steps": True}, "expected a whole number >= 1"),
])
def test_bad_knobs_name_the_problem(knobs, message):
    with pytest.raises(ValueError) as error:
        BaodingEnv(**knobs)
    assert message in str(error.value)
    assert list(knobs)[0] in str(error.value) or "did you mean" in str(error.value)


def test_unknown_preset_lists_allowed():
    with pytest.raises(ValueError, match="p3.*not one of p1, p1_2022, p2"):
        BaodingEnv("p3")


def test_numeric_strings_from_yaml_are_accepted():
    knobs = BaodingKnobs.parse("p1", solved_radius="1.5e-2", period=["4e0", "6"])
    assert knobs.solved_radius == 0.015 and knobs.period.high == 6.0


def test_nan_action_raises_and_leaves_simulation_untouched():
    env = BaodingEnv()
    env.reset(seed=0)
    env.step(np.zeros(39, np.float32))
    qpos, time = env.data.qpos.copy(), env.data.time
    bad = np.zeros(39, np.float32)
    bad[5] = np.nan
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(bad)
    bad[5] = np.inf
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(bad)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(38, np.float32))
    np.testing.assert_array_equal(env.data.qpos, qpos)
    assert env.data.time == time
    env.step(np.zeros(39, np.float32))  # still usable


def test_unstable_step_ends_episode_with_flag():
    env = BaodingEnv()
    obs, _ = env.reset(seed=0)
    qvel = np.zeros(35)
    qvel[:23] = 1e12  # far beyond what the integrator accepts
    env.reset(seed=0, options={"state": {"qvel": qvel}})
    obs, reward, terminated, truncated, info = env.step(np.zeros(39, np.float32))
    assert info["unstable"] and terminated
    assert np.isfinite(obs).all() and math.isfinite(reward)


def test_reset_options_are_checked():
    env = BaodingEnv()
    with pytest.raises(ValueError, match="unknown reset option 'tsk'"):
        env.reset(options={"tsk": {}})
    with pytest.raises(ValueError, match="missing field"):
        env.reset(options={"task": {"direction": "cw"}})
    with pytest.raises(ValueError, match="state.qpos: expected shape"):
        env.reset(options={"state": {"qpos": np.zeros(3)}})


def test_task_round_trips_through_dict():
    env = BaodingEnv("p2", period="static")
    env.reset(seed=4)
    values = env.task.to_dict()
    assert values["period"] == "static"
    assert BaodingTask.from_mapping(values) == env.task


def test_ball_physics_edits_match_a_recompiled_model():
    """Edited ball radius and mass give the inertia and bounds MuJoCo's compiler would."""
    import mujoco

    from myo_sds.envs.assets import load_hand_model

    env = BaodingEnv()
    task = BaodingTask("ccw", 5.0, 0.025, 0.028, 0.7, (0.019, 0.024), (0.25, 0.035),
                       ((1.1, 0.005, 0.0001), (0.9, 0.004, 0.0001)))
    env.reset(seed=0, options={"task": task})
    _, spec = load_hand_model("myohand_baoding.xml")
    spec = spec.copy()
    for name, radius, mass in (("ball1", 0.019, 0.25), ("ball2", 0.024, 0.035)):
        spec.geom(name).size = [radius, 0, 0]
        spec.geom(name).mass = mass
    compiled = spec.compile()
    for field in ("body_mass", "body_inertia", "geom_rbound", "geom_aabb", "bvh_aabb",
                  "dof_invweight0", "body_invweight0"):
        np.testing.assert_allclose(getattr(env.model, field), getattr(compiled, field),
                                   rtol=1e-9, atol=1e-12, err_msg=field)
    # mj_setConst keeps stat.meaninertia, as in the official env (checked by the parity tests).
    del mujoco


def test_an_env_takes_knobs_already_read_and_nothing_else_with_them():
    from myo_sds.envs.die_task import DieKnobs

    hold = BaodingKnobs.parse("p1", direction="hold", period="static")
    env = BaodingEnv(distribution=hold)
    assert env.knobs is hold
    env.configure(distribution=BaodingKnobs.parse("p2"))
    assert env.knobs.direction == "random"
    with pytest.raises(ValueError, match="expected BaodingKnobs and no other knobs, got DieKnobs"):
        BaodingEnv(distribution=DieKnobs.parse())
    with pytest.raises(ValueError, match="got BaodingKnobs and direction"):
        env.configure(distribution=hold, direction="cw")


def test_episode_counts_its_steps_and_solved_steps_by_where_the_targets_are():
    from collections import Counter

    from myo_sds.envs.metrics import phase_sector

    for direction, sign in (("ccw", 1), ("cw", -1)):
        env = BaodingEnv(direction=direction, period=5.0, start_angle=0.3, rsi_probability=1.0, drop_height=-10.0)
        env.reset(seed=0)
        while True:
            _, _, terminated, truncated, info = env.step(np.zeros(39, np.float32))
            if terminated or truncated:
                break
        result = info["episode_result"]
        # Step k is solved against the targets at 0.3 + sign * 2 pi * k * dt / 5: one revolution in 200 steps.
        expected = Counter(phase_sector(0.3 + sign * 2 * math.pi * k * env.dt / 5.0) for k in range(result.length))
        assert result.steps_by_target_phase == tuple(expected[s] for s in range(8))
        assert min(result.steps_by_target_phase) >= 24 and sum(result.steps_by_target_phase) == result.length == 200
        assert sum(result.solved_by_target_phase) == result.solved_steps > 0
        assert all(s <= n for s, n in zip(result.solved_by_target_phase, result.steps_by_target_phase))


@pytest.mark.slow  # offscreen rendering
def test_render_draws_each_target_as_a_sphere_of_the_solved_radius_coloured_by_its_ball():
    import mujoco

    env = BaodingEnv("p1_2022", render_mode="rgb_array")
    env.reset(seed=0)
    scene_geoms = []

    def added(scene):  # the geoms the env adds after MuJoCo's own scene
        scene_geoms[:] = [scene.geoms[i] for i in range(scene.ngeom)]

    frame = env.render()
    added(env._renderer.scene)
    spheres = [g for g in scene_geoms[-2:] if g.type == int(mujoco.mjtGeom.mjGEOM_SPHERE) and g.objid == -1]  # no model object
    assert len(spheres) == 2 and frame.shape == (480, 640, 3)
    obs = env._obs
    for sphere, (target, offset) in zip(spheres, ((35, 41), (38, 44))):
        assert sphere.size[0] == pytest.approx(0.015)
        assert np.allclose(sphere.pos, obs[target:target + 3])
        inside = np.linalg.norm(obs[offset:offset + 3]) < 0.015  # target - ball, from the observation
        assert (sphere.rgba[1] > sphere.rgba[0]) == inside  # green inside, red outside
    # The 2022 start: both targets on their balls (green); MyoSuite 3.0.0's: both off (red).
    assert all(s.rgba[1] > s.rgba[0] for s in spheres)
    env = BaodingEnv("p1", render_mode="rgb_array")
    env.reset(seed=0)
    env.render()
    scene = env._renderer.scene
    assert all(scene.geoms[i].rgba[0] > scene.geoms[i].rgba[1] for i in (scene.ngeom - 2, scene.ngeom - 1))
    # The balls are drawn translucent, so a sphere inside one shows.
    balls = [scene.geoms[i] for i in range(scene.ngeom) if scene.geoms[i].objid in env._ball_geoms
             and scene.geoms[i].objtype == int(mujoco.mjtObj.mjOBJ_GEOM)]
    assert len(balls) == 2 and all(b.rgba[3] < 0.5 for b in balls)


def test_balls_phase_is_the_angle_of_balls_placed_on_their_targets():
    for angle in (0.3, 2.356, 4.0, 5.9):
        env = BaodingEnv(start_angle=angle, rsi_probability=1.0, direction="hold", period="static")
        env.reset(seed=0)
        assert env.balls_phase() == pytest.approx(angle, abs=1e-9)


def run_episodes(env: BaodingEnv, episodes: int, seed: int) -> list[tuple[bool, float, int]]:
    """Zero-action episodes; each one's (recorded start, start angle, length) and, stepwise, the
    states the env may have banked (every step after which the episode went on and was solved)."""
    env.reset(seed=seed)
    starts, seen = [], []
    for _ in range(episodes):
        _, info = env.reset()
        start = (env.recorded_start, info["task"].start_angle, env.data.qpos.copy(), env.data.qvel.copy(),
                 env.data.act.copy())
        while True:
            _, _, terminated, truncated, info = env.step(np.zeros(39, dtype=np.float32))
            if info["solved"] and not terminated:
                seen.append((env.data.qpos.copy(), env.data.qvel.copy(), env.data.act.copy()))
            if terminated or truncated:
                break
        starts.append(start)
    return starts, seen


def test_recorded_starts_restore_a_state_of_earlier_episodes_with_the_targets_on_its_balls():
    knobs = dict(direction="ccw", period=20.0, start_angle="uniform", rsi_probability=1.0,
                 start_offset=[-0.3, 0.3], recorded_start={"probability": 0.5, "capacity": 30, "every": 1})
    env = BaodingEnv(**knobs)
    starts, seen = run_episodes(env, 30, seed=4)
    bank = env.state_bank
    # Bounded: 30 states kept of every solved step offered (zero actions solve the first steps).
    assert bank.size == 30 and bank.offered == len(seen) > 30
    recorded = [s for s in starts if s[0]]
    assert 8 <= len(recorded) <= 22  # about half of the 29 resets after the first episode
    assert not starts[0][0]  # nothing banked before the first episode
    for _, angle, qpos, qvel, act in recorded:
        # The whole state is one the env saw at a solved step of an earlier episode ...
        assert any(np.array_equal(qpos, q) and np.array_equal(qvel, v) and np.array_equal(act, a)
                   for q, v, a in seen)
    # ... and the targets start on its balls' orbit angle plus an offset within start_offset.
    probe = BaodingEnv(**knobs)
    for _, angle, qpos, _, _ in recorded:
        probe.reset(seed=0)
        probe.data.qpos[:] = qpos
        offset = (angle - probe.balls_phase() + np.pi) % (2 * np.pi) - np.pi
        assert -0.3 <= offset <= 0.3
    # Same seed, same starts.
    again, _ = run_episodes(BaodingEnv(**knobs), 30, seed=4)
    assert [(s[0], s[1]) for s in again] == [(s[0], s[1]) for s in starts]


def test_recorded_starts_place_the_targets_on_the_restored_balls():
    env = BaodingEnv(direction="hold", period="static", start_angle=1.0, rsi_probability=1.0, rsi_height="target",
                     recorded_start={"probability": 1.0, "every": 1})
    env.reset(seed=0)
    env.step(np.zeros(39, dtype=np.float32))  # solved: the balls start on their targets
    assert env.state_bank.size == 1
    kept = env.state_bank.qpos[0].copy()
    env.configure(direction="hold", period="static", start_angle=4.0, rsi_probability=1.0,
                  recorded_start={"probability": 1.0, "every": 1})
    env.reset(seed=1)
    assert env.recorded_start and np.array_equal(env.data.qpos, kept)
    # The balls moved a few degrees in one step: the targets are back near angle 1.0, not at 4.0.
    assert env.task.start_angle == pytest.approx(1.0, abs=0.15)
    for ball, target in zip(env._ball_sites, env._target_sites):
        assert np.linalg.norm(env.data.site_xpos[ball] - env.data.site_xpos[target]) < 0.005


@pytest.mark.parametrize("value, message", [
    ({"capacity": 10}, "recorded_start.probability: missing: the share of resets"),
    ({"probability": 1.5}, "a probability must be in"),
    ({"probability": 0}, "must be > 0"),
    ({"probability": 0.5, "capacity": 0}, "recorded_start.capacity: expected a whole number"),
    ({"probability": 0.5, "evry": 2}, "did you mean 'every'"),
    ({"probability": 0.5, "solved_only": "yes"}, "expected true or false"),
    (0.5, "expected a mapping"),
])
def test_recorded_start_knob_names_the_problem(value, message):
    with pytest.raises(ValueError, match=message):
        BaodingKnobs.parse("p1", recorded_start=value)


def test_episode_result_says_how_the_episode_began_and_sums_its_reward():
    """``start``: on_targets where RSI placed the balls, rest where it did not; ``reward``: the sum
    of the step rewards under the env's weights (here alive 1 + solved 5: hand-countable)."""
    env = BaodingEnv(start_angle="uniform", rsi_probability=0.5, horizon=3,
                     reward_weights={"alive": 1.0, "solved": 5.0})
    kinds = set()
    for seed in range(12):
        obs, _ = env.reset(seed=seed)
        placed = np.linalg.norm(obs[41:44]) < 1e-3
        total = 0.0
        for _ in range(3):
            *_, reward, terminated, truncated, info = env.step(np.zeros(39, np.float32))
            total += reward
        result = info["episode_result"]
        assert result.start == ("on_targets" if placed else "rest")
        assert result.reward == pytest.approx(total)
        assert result.reward == pytest.approx(result.length - int(result.dropped) + 5 * result.solved_steps)
        kinds.add(result.start)
    assert kinds == {"on_targets", "rest"}


@pytest.mark.parametrize("direction, sign", [("ccw", 1.0), ("cw", -1.0)])
def test_chained_goals_move_the_targets_along_their_orbit(direction, sign):
    """After 3 solved steps the targets jump by U(offset) ahead along the orbit (clockwise:
    the angle falls), direction and period kept, seeded; the official presets chain nothing."""
    def play(seed):
        env = BaodingEnv(direction=direction, period=20.0, start_angle="uniform", rsi_probability=1.0,
                         solved_radius=0.05, goal_chain={"after_solved": 3, "offset": [0.2, 0.4]}, horizon=10)
        env.reset(seed=seed)
        starts = [env.task.start_angle]
        for _ in range(10):
            obs, *_, info = env.step(np.zeros(39, np.float32))
            starts.append(env.task.start_angle)
        return env, np.array(starts), obs, info

    env, starts, obs, info = play(0)
    jumps = np.diff(np.unwrap(starts))
    moved = np.flatnonzero(jumps)
    assert list(moved[:1]) == [2] and all(0.2 <= sign * j <= 0.4 for j in jumps[moved])  # the third solved step
    assert (env.task.direction, env.task.period) == (direction, 20.0)
    # The observation shows the targets where the moved task puts them.
    angle = env._target_angle
    target = env.data.site_xpos[env.model.site("target1_site").id]
    np.testing.assert_allclose(obs[35:38], target, atol=1e-6)
    assert angle == pytest.approx(starts[-1] + sign * 2 * math.pi * 9 * env.dt / 20.0)  # placed before the 10th step
    assert info["episode_result"].goals_reached == len(moved)
    _, again, _, _ = play(0)
    np.testing.assert_array_equal(starts, again)
    for preset in ("p1", "p1_2022", "p2"):
        assert BaodingEnv(preset).knobs.goal_chain is None


def test_the_winner_chain_rotates_clockwise_or_counter_clockwise_never_holds():
    """curricula/baoding_sds.yaml's stages 02-12 (the winner's `task: random`, which drew from
    MyoSuite's cw/ccw enum before v1.2.3 added hold) never draw a hold episode."""
    from pathlib import Path

    from myo_sds.curricula.schema import load_curriculum

    curriculum = load_curriculum(Path(__file__).resolve().parents[1] / "curricula" / "baoding_sds.yaml")
    rotating = [s for s in curriculum.stages if s.name.startswith(("rotate-", "fixed-"))]
    assert len(rotating) == 10  # their 02-05 and 06-12, their two 7 s runs as one stage
    env = BaodingEnv(distribution=rotating[0].distribution, horizon=2)
    for stage in rotating:
        env.configure(distribution=stage.distribution)
        drawn = [env.reset(seed=seed) and env.task.direction for seed in range(24)]
        assert set(drawn) == {"cw", "ccw"}, stage.name
