"""flatland.Env, the closed loop a tick at a time in Gymnasium's convention: the plan's
accelerations as actions give the open-loop experiment's world bit for bit, a seed gives the
same episode twice, bad actions are one-line ValueErrors, and Gymnasium's conventions hold
(env_checker.py) with gymnasium (a stand-in module) and without it."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import flatland
from env_checker import check_env, check_reset, check_step

TESTS = Path(__file__).resolve().parent


@pytest.fixture(scope="module")
def open_loop():
    return flatland.experiment(controller="open-loop")


def plan_actions(run, env):
    """The open-loop experiment's commands over [0, T): the plan's accelerations, mid-tick."""
    t = run.log["t"]
    return run.log["command"][(t >= 0) & (t < env.plan.duration)]


def test_the_plans_accelerations_as_actions_give_the_open_loop_experiment(open_loop):
    env = flatland.Env(observation="state")
    obs, info = env.reset()
    assert info["t"] == 0.0 and info["outcome"] is None
    actions = plan_actions(open_loop, env)
    log = open_loop.log
    row = {t: i for i, t in enumerate(log["t"])}
    steps = 0
    for action in actions:
        # Each observation is the world's truth at its tick, as the experiment logged it.
        i = row[info["t"]]
        assert (obs[0], obs[2], obs[3]) == (log["theta_true"][i], log["s_true"][i],
                                            log["sdot_true"][i])
        obs, reward, terminated, truncated, info = env.step(action)
        steps += 1
        if terminated:
            break
    # The motion ends at the plan's end, after the last of the plan's ticks.
    assert terminated and not truncated and steps == len(actions)
    assert info["ended_by"] == "motion-end"
    # Bit for bit: the same commands on the same world give the same truth, measurements,
    # estimates and ending (the hold after the motion is the paper controller's, the verdict
    # run_synthetic's). Only the controller's own columns differ: its mode and reference.
    own = env.log()
    assert list(own) == list(log)
    for name, column in log.items():
        if name in ("stage", "theta_plan"):
            continue
        np.testing.assert_array_equal(own[name], column, err_msg=name)
    acting = own["stage"] == "action"
    assert acting.sum() == len(actions)
    assert list(own["stage"][~acting]) == list(log["stage"][~acting])
    np.testing.assert_array_equal(own["theta_plan"][~acting], log["theta_plan"][~acting])
    for key in ("success", "outcome", "s_end", "duration_s", "fn_min_ratio", "mu_max"):
        assert info[key] == open_loop[key], key
    assert reward == (1.0 if open_loop["success"] else 0.0)


def rollout(env, seed, actions):
    obs, info = env.reset(seed=seed)
    observations, infos = [obs], [info]
    for action in actions:
        obs, _, terminated, _, info = env.step(action)
        observations.append(obs)
        infos.append(info)
        if terminated:
            break
    return np.array(observations), infos


def test_reset_with_a_seed_twice_gives_the_same_episode_and_the_noise_follows_it(open_loop):
    env = flatland.Env(observation="measurement", ticks_per_step=5)
    actions = plan_actions(open_loop, env)[::5][:200]  # the first second
    a, info_a = rollout(env, 7, actions)
    b, info_b = rollout(env, 7, actions)
    np.testing.assert_array_equal(a, b)
    assert info_a == info_b
    c, info_c = rollout(env, 8, actions)
    # Another seed, other camera noise: other measurements of the same world.
    s_meas = env.observation_names.index("s_meas")
    assert not np.array_equal(a[:, s_meas], c[:, s_meas])
    assert [i["s_h"] for i in info_a] == [i["s_h"] for i in info_c]
    # Observations arrive with the camera: at most 30 a second, each after its capture.
    t, t_capture = a[:, 0], a[:, env.observation_names.index("t_capture")]
    seen = np.isfinite(t_capture)
    assert np.all(t_capture[seen] < t[seen])
    assert 20 <= len(np.unique(t_capture[seen])) <= 31


@pytest.mark.parametrize("action, message", [
    (float("nan"), r"^action: must be finite \(rad/s\^2\), got nan$"),
    (np.array([np.inf]), r"^action: must be finite \(rad/s\^2\), got inf$"),
    (np.zeros(2), r"^action: shape \(1,\) \(rad/s\^2\), got shape \(2,\)$"),
    ([[1.0]], r"^action: shape \(1,\) \(rad/s\^2\), got shape \(1, 1\)$"),
    ("fast", r"^action: a number or an array of shape \(1,\) \(rad/s\^2\), got a str$"),
    (True, r"^action: a number or an array of shape \(1,\) \(rad/s\^2\), got a bool$"),
    (None, r"^action: a number or an array of shape \(1,\) \(rad/s\^2\), got a NoneType of "
           r"object$"),
    (1e6, r"^action: must be within \+-200 rad/s\^2 \(joint\.torque_limit / joint\.inertia\), "
          r"got 1e\+06$"),
])
def test_bad_actions_are_value_errors_naming_them(action, message):
    env = flatland.Env(observation="state")
    env.reset()
    with pytest.raises(ValueError, match=message):
        env.step(action)
    # Nothing was done: the episode goes on from where it was.
    _, _, terminated, _, info = env.step(0.0)
    assert info["t"] == pytest.approx(env.dt) and not terminated


def test_bad_arguments_are_value_errors_and_misuse_runtime_errors():
    with pytest.raises(ValueError, match=r"^observation: must be image, measurement or state, "
                                         r"got 'pixels'$"):
        flatland.Env(observation="pixels")
    with pytest.raises(ValueError, match=r"^ticks_per_step: must be in \[1, 1000000\], got 0$"):
        flatland.Env(ticks_per_step=0)
    with pytest.raises(ValueError, match=r"^reward: a callable\(info\) -> float, got a int$"):
        flatland.Env(reward=5)
    with pytest.raises(ValueError, match=r"^duration: must be positive and finite"):
        flatland.Env(duration=-1.0)
    env = flatland.Env(observation="state")
    with pytest.raises(RuntimeError, match=r"^Env\.step: call reset\(\) first$"):
        env.step(0.0)
    with pytest.raises(ValueError, match=r"^options: none are known, got \['x'\]$"):
        env.reset(options={"x": 1})
    with pytest.raises(ValueError, match=r"^seed: must be in \[0, "):
        env.reset(seed=-1)
    env = flatland.Env(observation="state", reward=lambda info: "much")
    env.reset()
    with pytest.raises(ValueError, match=r"^reward: the callable returned 'much' at t = 0\.001 s"):
        env.step(0.0)


def test_gymnasiums_conventions_and_the_end_of_the_motion(open_loop):
    env = flatland.Env(observation="measurement", ticks_per_step=10)
    actions = plan_actions(open_loop, env)[::10]
    obs, info, steps = check_env(env, actions, seed=1)
    assert len(obs) == len(env.observation_names) == 10
    # It ends when the motion's time is up: terminated, judged, rewarded once.
    _, reward, terminated, truncated, info = steps[-1]
    assert terminated and info["ended_by"] == "motion-end" and info["outcome"] is not None
    assert sum(s[1] for s in steps) == reward == (1.0 if info["success"] else 0.0)
    assert info["t"] >= env.plan.duration
    # The last observation is of that tick, although the loop ran on after it (the hold, the
    # settling): what had arrived by then, captured before it.
    last = dict(zip(env.observation_names, steps[-1][0]))
    assert last["t"] == info["t"] and last["t_capture"] < info["t"]
    with pytest.raises(RuntimeError, match=r"^Env\.step: the episode has ended \(motion-end\): "
                                           r"call reset\(\)$"):
        env.step(0.0)
    check_reset(env)  # and a new episode starts


@pytest.mark.parametrize("actions, ended_by, stop", [
    # A 50 ms push: the disk slides off the hand, out of its reach (the world's failure).
    ([15.0] * 5 + [0.0] * 300, "disk", "disk: the disk slid off the hand and was not caught"),
    # A steady 30 rad/s^2: the disk slides away, and the estimator's innovations say so first.
    ([30.0] * 300, "safe-stop", "estimator: 3 implausible innovations in a row"),
])
def test_the_episode_ends_when_the_disk_leaves_the_hand(actions, ended_by, stop):
    env = flatland.Env(observation="state", ticks_per_step=10)
    _, _, steps = check_env(env, actions)
    _, reward, terminated, truncated, info = steps[-1]
    assert terminated and not truncated and info["ended_by"] == ended_by
    assert info["stop_reason"].startswith(stop)
    # Where the disk went: off the hand, whoever noticed first.
    assert info["outcome"] == "slid_off" and not info["success"] and reward == 0.0
    assert len(steps) < len(actions)


def test_truncation_at_the_time_limit():
    env = flatland.Env(observation="state", time_limit=0.05, ticks_per_step=10)
    _, _, steps = check_env(env, [0.0] * 10)
    _, reward, terminated, truncated, info = steps[-1]
    assert truncated and not terminated and info["ended_by"] == "time-limit"
    assert info["outcome"] is None and reward == 0.0
    # At the first tick at or after the limit (ticks are t_start + i dt: 0.3 - 0.25 is a hair
    # below 0.05, so that is the 301st tick, one into the sixth step).
    assert info["t"] >= 0.05 and steps[-2][4]["t"] < 0.05
    assert info["t"] - steps[-2][4]["t"] <= env.dt + 1e-12


def test_image_observations_and_render():
    env = flatland.Env(observation="image")
    obs, info = check_reset(env, seed=2)
    assert obs.shape == (480, 640, 3) and obs.dtype == np.uint8 and not obs.flags.writeable
    assert obs.any()  # a frame has arrived during the waiting phase
    np.testing.assert_array_equal(env.render(), obs[..., ::-1])  # RGB of the BGR observation
    for _ in range(40):  # a frame every 33 ms at 30 Hz: at least one new one
        new, *_ = check_step(env, 0.0)
    assert not np.array_equal(new, obs)
    np.testing.assert_array_equal(env.render(), new[..., ::-1])


def test_a_replaced_reward_sees_the_truth():
    seen = []
    env = flatland.Env(observation="state",
                       reward=lambda info: seen.append(info) or -abs(info["s_h"] + 1.0))
    obs, _ = env.reset()
    _, reward, *_ = env.step(0.0)
    assert reward == -abs(seen[-1]["s_h"] + 1.0)
    assert set(seen[-1]) >= {"t", "s_h", "sdot_h", "theta", "fn_ratio", "mode", "estimating",
                             "measured", "stopping", "stop_reason", "ended_by", "success"}


class LastMeasurement:
    """An estimator that believes the latest measurement, at rest."""

    def reset(self, t, s_h, sdot_h):
        self.s = s_h

    def propagate(self, t_next, hand):
        pass

    def update(self, z):
        self.s = z.s_h

    def estimate(self):
        return flatland.Estimate(0.0, self.s, 0.0, ((1e-6, 0.0), (0.0, 1.0)))


def test_env_runs_your_own_estimator():
    env = flatland.Env(observation="measurement", estimator=LastMeasurement())
    obs, _ = env.reset()
    seen = dict(zip(env.observation_names, obs))
    assert seen["s_est"] == seen["s_meas"] and seen["sigma_s_est"] == 1e-3
    for _ in range(100):
        obs, *_ = env.step(0.0)
        seen = dict(zip(env.observation_names, obs))
        assert seen["s_est"] == seen["s_meas"] and seen["sdot_est"] == 0.0


def run_python(code, tmp_path, block_gymnasium=False):
    fake = tmp_path / "fake"
    (fake / "gymnasium").mkdir(parents=True)
    (fake / "gymnasium" / "__init__.py").write_text(FAKE_GYMNASIUM)
    (fake / "gymnasium" / "spaces.py").write_text(FAKE_SPACES)
    prelude = f"import sys\nsys.path[:0] = [{str(TESTS)!r}]\n"
    if block_gymnasium:
        prelude += "sys.modules['gymnasium'] = None  # import gymnasium raises ImportError\n"
    else:
        prelude += f"sys.path.insert(0, {str(fake)!r})\n"
    p = subprocess.run([sys.executable, "-c", prelude + textwrap.dedent(code)],
                       capture_output=True, text=True, timeout=600, env=dict(os.environ))
    assert p.returncode == 0, p.stderr
    return p.stdout


# Debian does not package gymnasium: this stand-in has the real API's signatures for what Env
# uses (gymnasium 1.0: Env.reset(*, seed=None, options=None) seeding np_random, metadata,
# render_mode, spec; spaces.Box(low, high, shape=None, dtype=np.float32, seed=None) and its
# contains), so that the subclassing path runs here.
FAKE_GYMNASIUM = '''
import numpy as np
from . import spaces


class Env:
    metadata = {"render_modes": []}
    render_mode = None
    spec = None
    action_space = None
    observation_space = None
    _np_random = None

    @property
    def np_random(self):
        if self._np_random is None:
            self._np_random = np.random.default_rng()
        return self._np_random

    def reset(self, *, seed=None, options=None):
        if seed is not None:
            self._np_random = np.random.default_rng(seed)

    def step(self, action):
        raise NotImplementedError

    def render(self):
        raise NotImplementedError

    def close(self):
        pass

    @property
    def unwrapped(self):
        return self
'''

FAKE_SPACES = '''
import numpy as np


class Box:
    def __init__(self, low, high, shape=None, dtype=np.float32, seed=None):
        self.dtype = np.dtype(dtype)
        self.shape = tuple(shape) if shape is not None else np.shape(low)
        self.low = np.broadcast_to(np.asarray(low, dtype=self.dtype), self.shape).copy()
        self.high = np.broadcast_to(np.asarray(high, dtype=self.dtype), self.shape).copy()

    def contains(self, x):
        if not isinstance(x, np.ndarray):
            try:
                x = np.asarray(x, dtype=self.dtype)
            except (ValueError, TypeError):
                return False
        return bool(np.can_cast(x.dtype, self.dtype) and x.shape == self.shape
                    and np.all(x >= self.low) and np.all(x <= self.high))
'''


def test_with_gymnasium_env_subclasses_it_and_uses_its_spaces(tmp_path):
    out = run_python('''
        import gymnasium
        import flatland
        from env_checker import check_env
        assert issubclass(flatland.Env, gymnasium.Env)
        env = flatland.Env(observation="measurement")
        assert isinstance(env.action_space, gymnasium.spaces.Box)
        assert isinstance(env.observation_space, gymnasium.spaces.Box)
        assert not isinstance(env.action_space, flatland.Box)
        _, _, steps = check_env(env, [0.0] * 20, seed=3)
        assert len(steps) == 20 and env._np_random is not None  # gymnasium's reset seeded it
        print("with gymnasium")
    ''', tmp_path)
    assert out.strip() == "with gymnasium"


def test_without_gymnasium_env_is_a_plain_class_with_plain_spaces(tmp_path):
    out = run_python('''
        import flatland
        from env_checker import check_env
        assert flatland.Env.__mro__[1:] == (object,)
        env = flatland.Env(observation="state")
        assert isinstance(env.action_space, flatland.Box)
        assert env.action_space.shape == (1,) and env.action_space.dtype == "float64"
        assert env.action_space.high[0] == -env.action_space.low[0] == env.max_acceleration
        _, _, steps = check_env(env, [0.0] * 20, seed=3)
        assert len(steps) == 20
        print("without gymnasium")
    ''', tmp_path, block_gymnasium=True)
    assert out.strip() == "without gymnasium"
