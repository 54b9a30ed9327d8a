"""uav_tilt/ContactInspection-v0: a valid Gymnasium environment, reproducible from its
seeds across processes, whose return with the mission's own controller as the policy is
the one the mission's metrics of that touch imply."""
import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from uav_tilt_common.modes import NOT_FLYING
from uav_tilt_control.controller_core import ControllerConfig
from uav_tilt_tools.gym import env as gym_env
from uav_tilt_tools.runner.inprocess import mission_result

MODULE_ID = f'uav_tilt_tools.gym.env:{gym_env.ENV_ID}'


def test_check_env_passes_with_the_camera():
    # the whole mission as the episode: check_env resets a dozen times
    env = gym_env.ContactInspectionEnv(render_mode='rgb_array', camera=True, start='takeoff',
                                       episode_s=1.0)
    try:
        check_env(env, skip_render_check=False)
        obs, _ = env.reset(seed=1)
        assert obs['image'].shape == env.observation_space['image'].shape
        assert obs['image'].std() > 0            # a rendered view, not a blank
        # an episode from the ground flies: the takeoff is no crash
        for _ in range(30):
            _, reward, terminated, truncated, info = env.step(env.action_space.sample())
            assert not terminated and reward == 0.0, info
        assert info['mode'] not in NOT_FLYING
    finally:
        env.close()


def test_vision_in_the_loop_runs_the_deployed_detector_from_any_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)         # the package's model, not one beside the user
    env = gym.make(gym_env.ENV_ID, start='takeoff', target_source='vision',
                   disable_env_checker=True)
    try:
        env.reset(seed=int(np.random.default_rng().integers(0, 2**31 - 1)))
        for _ in range(10):
            env.step(np.zeros(3, dtype=np.float32))
        vision = env.unwrapped.flight.vision
        # 10 steps of 10 ticks at 300 Hz: the 30 Hz camera's frames of a third of a second
        assert vision.frames >= 10 and vision.pipeline.detector.model_path.endswith(
            'detector_int8.onnx')
    finally:
        env.close()


def test_bad_options_stop_with_one_clear_error():
    with pytest.raises(Exception, match='start'):
        gym_env.ContactInspectionEnv(start='orbit')
    # 300 Hz over 7 Hz is no whole number of control ticks
    with pytest.raises(ValueError, match='action_rate_hz'):
        gym_env.ContactInspectionEnv(action_rate_hz=7.0)
    with pytest.raises(gym.error.ResetNeeded):
        gym_env.ContactInspectionEnv().step(np.zeros(3, dtype=np.float32))
    # the controller's parameters as a config, as well as a dict, and checked alike
    force_n = float(np.random.default_rng().uniform(2.0, 8.0))
    env = gym_env.ContactInspectionEnv(controller=ControllerConfig(contact_force=force_n))
    assert env.cfg.controller.contact_force == force_n
    with pytest.raises(ValueError, match='contact_force'):
        gym_env.ContactInspectionEnv(controller=ControllerConfig(contact_force=-force_n))
    # the target source is the environment's option: given to the controller it would be
    # overwritten without a word
    for options in ({'controller': {'target_source': 'vision'}},
                    {'controller.target_source': 'vision'}):
        with pytest.raises(ValueError, match="'controller.target_source'.*'target_source'"):
            gym_env.ContactInspectionEnv(**options)
    # a detector that is not there is found at make, not deep in the first reset
    with pytest.raises(ValueError, match="'model_path'.*no such file"):
        gym_env.ContactInspectionEnv(target_source='vision', model_path='no/such/model.onnx')


def test_a_takeoff_episode_counts_its_time_from_the_wall_and_refuses_bad_input():
    # gymnasium's checker wrapper takes a raising reset or step for a broken environment
    env = gym.make(gym_env.ENV_ID, start='takeoff', episode_s=1.0, disable_env_checker=True)
    try:
        with pytest.raises(ValueError, match='options'):
            env.reset(seed=5, options={'start': 'wall'})
        env.reset(seed=int(np.random.default_rng().integers(0, 2**31 - 1)))
        for bad in (np.float32([np.nan, 0.0, 0.0]), np.float32([0.0, np.inf, 0.0]),
                    np.float32([0.0, 0.0]), np.zeros((1, 3)), ['1', '0', '0'],
                    [True, False, True], None):
            with pytest.raises(ValueError, match='action'):
                env.step(bad)
        arrived = None
        for _ in range(5000):       # the flight in takes tens of seconds: 30 steps each
            _, _, terminated, truncated, info = env.step(np.zeros(3, dtype=np.float32))
            if arrived is None and info['mode'] == 'CONTACT':
                arrived = info['t_s']
            if terminated or truncated:
                break
        # a second at the wall, however long the flight in took
        assert truncated and not terminated and arrived is not None, info
        assert info['outcome'] == 'time_limit'
        assert info['t_s'] - arrived == pytest.approx(1.0, abs=0.1), (arrived, info)
        with pytest.raises(gym.error.ResetNeeded, match='ended'):
            env.step(np.zeros(3, dtype=np.float32))
    finally:
        env.close()


def test_two_vector_envs_reproduce_from_their_seeds():
    rng = np.random.default_rng()
    seeds = [int(s) for s in rng.integers(0, 2**31 - 1, size=2)]
    actions = rng.uniform(-1.0, 1.0, size=(6, 2, 3)).astype(np.float32)
    envs = gym.make_vec(MODULE_ID, num_envs=2, vectorization_mode='async',
                        vector_kwargs={'context': 'spawn'})
    try:
        episodes = []
        for _ in range(2):
            obs, info = envs.reset(seed=seeds)
            trace = [obs]
            for action in actions:
                obs, reward, terminated, truncated, _ = envs.step(action)
                trace.append((obs, reward, terminated, truncated))
            episodes.append((list(info['world_seed']), trace))
    finally:
        envs.close()
    (worlds, first), (again, second) = episodes
    assert worlds == again and worlds[0] != worlds[1], seeds
    for a, b in zip(first, second):
        obs_a, obs_b = (a, b) if isinstance(a, dict) else (a[0], b[0])
        for key in obs_a:
            np.testing.assert_array_equal(obs_a[key], obs_b[key], err_msg=key)
        if not isinstance(a, dict):
            for x, y in zip(a[1:], b[1:]):
                np.testing.assert_array_equal(x, y)
    # two worlds: two different flights
    assert not np.array_equal(first[0]['tip_t'][0], first[0]['tip_t'][1])


def test_the_missions_controller_earns_the_reward_its_touch_metrics_imply():
    env = gym.make(gym_env.ENV_ID)
    try:
        _, info = env.reset(seed=int(np.random.default_rng().integers(0, 2**31 - 1)))
        world = info['world_seed']
        total, zero = 0.0, np.zeros(3, dtype=np.float32)
        while True:
            _, reward, terminated, truncated, info = env.step(zero)
            total += reward
            if terminated or truncated:
                break
        base = env.unwrapped
        assert info['outcome'] == 'success', (world, info)
        assert info['mode'] in ('HOLD', 'RETREAT'), info      # ended with the hold
        metrics = mission_result(base.flight)
        cfg = base.cfg
        dt_s = base.flight.plant.dt_tick
        hold_ticks = round(metrics['hold_time_s'] / dt_s) + 1
        assert hold_ticks * dt_s >= cfg.controller.mission.contact.hold_time_s
        # mean over HOLD of 1 - (force error / scale)^2 - POI error / scale, per step
        implied = hold_ticks / base.ticks_per_step * (
            1.0 - (metrics['force_rms_error_n'] / cfg.force_scale_n) ** 2
            - metrics['poi_error_m'] / cfg.poi_scale_m)
        assert total == pytest.approx(implied, rel=1e-6), world
        assert implied > 0.5 * hold_ticks / base.ticks_per_step, metrics
    finally:
        env.close()


def test_a_hold_completed_off_the_point_is_a_failure():
    """An agent that holds the tool a fresh 2-8 cm along the wall from the POI lets the
    controller complete its hold, but the truth puts the tip past the 1 cm bar: the episode
    ends 'off_target', with the failure penalty."""
    rng = np.random.default_rng()
    env = gym.make(gym_env.ENV_ID)
    try:
        _, info = env.reset(seed=int(rng.integers(0, 2**31 - 1)))
        cfg = env.unwrapped.cfg
        offset_m = rng.uniform(0.02, 0.08)
        action = np.array([offset_m / cfg.max_offset_m, 0.0, 0.0], dtype=np.float32)
        while True:
            _, reward, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
        # the controller completed its hold; the episode ends there, not after the landing
        assert [r.success for r in env.unwrapped.flight.core.mission.records] == [True], info
        assert info['mode'] in ('HOLD', 'RETREAT')
        assert info['outcome'] == 'off_target', (info, offset_m)
        assert reward < 1.0 - cfg.failure_penalty
    finally:
        env.close()
