"""``info["final_obs"]`` of an autoresetting env: where a step ends an episode, the observation
that episode ended on, exactly what the same env with ``autoreset=False`` returns on that step
(masks, RAM-obs renders, early ends inside a step and the frame stack included); elsewhere the
step's own observation."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import stori_jax
from stori_jax import Config

from _env_support import make, random_actions, to_numpy

# max_episode_frames 81: each episode ends on the first frame of its 21st step (an early end
# inside a step, whose observation is that one frame); 80: on the last frame of its 20th
CASES = {
    "Breakout 3.1, atari84 (the stack it ended with)": dict(game="Breakout", preset="3.1",
                                                           obs="atari84", cap=81),
    "Breakout 3.1, atari84, ended on a step's last frame": dict(game="Breakout", preset="3.1",
                                                                obs="atari84", cap=80),
    "Gopher 3.2 (per-frame blackout of both screens), raw": dict(game="Gopher", preset="3.2",
                                                                 obs="raw", cap=81),
    "Breakout 3.2C (torch), dreamer64": dict(game="Breakout", preset="3.2C", obs="dreamer64",
                                             cap=81),
    "Boxing 3.2C (RAM-obs render), raw": dict(game="Boxing", preset="3.2C", obs="raw", cap=81),
    "Breakout type 0 (the RAM)": dict(game="Breakout", config=Config(ram_observation=True),
                                      obs="ram", cap=81),
    "Breakout 2.1 (events), atari84": dict(game="Breakout", preset="2.1", obs="atari84",
                                           cap=81),
}


def twin_runs(game, cap, steps, **kw):
    """(autoreset run, autoreset=False run) of the same seed and actions, step by step."""
    actions = random_actions(stori_jax.get_game(game).num_actions, steps, 2, seed=4)
    runs = []
    for autoreset in (True, False):
        with make(game, max_episode_frames=cap, autoreset=autoreset, **kw) as env:
            env.reset()
            runs.append([to_numpy(env.step(a)) for a in actions])
    return runs


@pytest.mark.parametrize("case", list(CASES))
def test_final_obs_is_what_the_env_without_autoreset_ends_on(case):
    kw = dict(CASES[case])
    game, cap = kw.pop("game"), kw.pop("cap")
    steps = 21  # both envs end by step 21 (index 20)
    with_autoreset, without = twin_runs(game, cap, steps, **kw)
    ends = 0
    for t in range(steps):  # up to the end (without autoreset, the next step is a reset)
        obs, _, terminated, truncated, info = with_autoreset[t]
        twin_obs, _, twin_terminated, twin_truncated, _ = without[t]
        np.testing.assert_array_equal(terminated | truncated, twin_terminated | twin_truncated)
        np.testing.assert_array_equal(info["final_obs"], twin_obs, err_msg=f"step {t}")
        done = terminated | truncated
        ends += done.sum()
        # where no episode ended, the step's own observation; where one did, not the
        # autoreset's first observation of the next episode
        np.testing.assert_array_equal(info["final_obs"][~done], obs[~done])
        if done.any():
            if kw["obs"] != "ram":
                assert not np.array_equal(info["final_obs"][done], obs[done])
            break
    assert ends == 2 and t == cap // 4 - (cap % 4 == 0), "both envs end on the cap's step"


def test_final_obs_at_step_granularity_and_after_an_early_end():
    """A one-frame observation of an early end at step granularity (one mask decision a step)
    is the twin's too."""
    config = Config(observation=stori_jax.ObservationMask("blackout", 1, 0.5),
                    granularity="step")
    with_autoreset, without = twin_runs("Breakout", 81, 21, config=config, obs="raw")
    for t in range(21):
        np.testing.assert_array_equal(with_autoreset[t][4]["final_obs"], without[t][0])
    assert (with_autoreset[20][2] | with_autoreset[20][3]).all()


def test_final_obs_is_the_envs_own_array():
    """final_obs is a buffer of its own: a jit that donates the observation leaves it intact."""
    with make("Breakout", preset="3.1", obs="atari84") as env:
        env.reset()
        obs, *_, info = env.step(np.zeros(2, np.int32))
        expected = np.asarray(obs).copy()
        jax.jit(lambda o: o + 1, donate_argnums=0)(obs)
        np.testing.assert_array_equal(info["final_obs"], expected)


def test_no_final_obs_without_autoreset():
    """autoreset=False returns the ended episode's last observation itself: no final_obs."""
    with make("Breakout", autoreset=False) as env:
        _, info = env.reset()
        assert "final_obs" not in info
        assert "final_obs" not in env.step(np.zeros(2, np.int32))[4]


def test_only_an_autoresetting_env_keeps_final_buffers_and_the_memory_check_counts_them():
    from stori_jax.backends.layout import shared_bytes

    with make("Breakout", obs="raw") as autoresetting, \
            make("Breakout", obs="raw", autoreset=False) as not_autoresetting:
        assert len(autoresetting.backend.buffers.raw["final_frames"][0]) == 2 * 2 * 210 * 160 * 3
        assert "final_frames" not in not_autoresetting.backend.buffers.raw
    screens = 2 * 210 * 160 * 3
    assert shared_bytes(1, 4, final=True) - shared_bytes(1, 4, final=False) > screens
    assert shared_bytes(1, 4, screens=False, final=True) < 1024 < screens
