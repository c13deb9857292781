"""Gymnasium's conventions for an environment, checked on any object (our own checker: Debian
does not package gymnasium, whose env_checker this follows): the spaces describe themselves
(shape, dtype, low, high, contains), reset returns a pair (observation, info dict), step a
5-tuple (observation, float reward, bool terminated, bool truncated, info dict), and every
observation is in the observation space."""

import numpy as np


def check_space(space):
    for field in ("shape", "dtype", "low", "high"):
        assert hasattr(space, field), field
    assert callable(space.contains)
    assert np.shape(space.low) == tuple(space.shape) == np.shape(space.high)
    assert np.all(np.asarray(space.low) <= np.asarray(space.high))


def check_reset(env, seed=None):
    out = env.reset(seed=seed)
    assert isinstance(out, tuple) and len(out) == 2, out
    obs, info = out
    assert env.observation_space.contains(obs), obs
    assert isinstance(info, dict)
    return obs, info


def check_step(env, action):
    assert env.action_space.contains(np.asarray([action], dtype=env.action_space.dtype)), action
    out = env.step(action)
    assert isinstance(out, tuple) and len(out) == 5, out
    obs, reward, terminated, truncated, info = out
    assert env.observation_space.contains(obs), obs
    assert isinstance(reward, float) and np.isfinite(reward), reward
    assert isinstance(terminated, bool) and isinstance(truncated, bool)
    assert not (terminated and truncated)
    assert isinstance(info, dict)
    return out


def check_env(env, actions, seed=None):
    """Checks the spaces, reset, and a step per action until the episode ends or the actions
    run out; returns (first observation, first info, the steps' 5-tuples)."""
    check_space(env.action_space)
    check_space(env.observation_space)
    obs, info = check_reset(env, seed)
    steps = []
    for action in actions:
        steps.append(check_step(env, action))
        if steps[-1][2] or steps[-1][3]:
            break
    return obs, info, steps
