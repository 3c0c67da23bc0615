"""Episode boundaries through ``stori_jax.make``: autoreset, episode statistics, truncation and
``autoreset=False``."""

from __future__ import annotations

import numpy as np
import pytest

from _env_support import NOOP, make, random_actions, run_env


@pytest.mark.slow
def test_episode_statistics_and_autoreset_on_termination():
    """Breakout under random play loses its five lives: at the step an episode ends,
    episode_return is the sum of that episode's rewards and episode_length its number of steps
    (both 0 elsewhere); the observation returned is the next episode's first one (its 84x84
    frame stack holds one frame four times)."""
    steps = 450
    env = make("Breakout", obs="atari84")
    try:
        run = run_env(env, random_actions(4, steps, 2, seed=41))
    finally:
        env.close()
    reward, done = run.stacked("reward"), run.done
    terminated = run.stacked("terminated")
    assert terminated.sum() >= 2, "random play should end a few episodes"
    returns, lengths = run.stacked("episode_return"), run.stacked("episode_length")
    obs = run.stacked("obs")
    assert obs.shape == (steps, 2, 84, 84, 4)
    for b in range(2):
        start = 0
        for k in range(steps):
            if done[k, b]:
                assert returns[k, b] == reward[start:k + 1, b].sum(), (b, k)
                assert lengths[k, b] == k + 1 - start, (b, k)
                assert run.info[k]["lives"][b] == 5  # the new episode's lives
                frames = obs[k, b]
                assert all((frames[..., i] == frames[..., 0]).all() for i in range(4))
                start = k + 1
            else:
                assert returns[k, b] == 0 and lengths[k, b] == 0
        assert start > 0
    # mid-episode the stack holds four different frames
    moving = ~done
    assert any(not (obs[k, b][..., 0] == obs[k, b][..., 3]).all()
               for k, b in zip(*np.nonzero(moving)))
    # lives count down within an episode
    lives = run.stacked("lives")
    assert lives.min() < 5 and lives.max() == 5


def test_truncation_autoresets_to_a_first_observation():
    """max_episode_frames 40 at frame_skip 4: every 10th step is truncated (not terminated), and
    its observation is a fresh episode's first: the RAM equals the first reset's."""
    env = make("Breakout", max_episode_frames=40)
    try:
        run = run_env(env, np.full((25, 2), NOOP, np.int32))
    finally:
        env.close()
    truncated, terminated = run.stacked("truncated"), run.stacked("terminated")
    expected = (np.arange(25) % 10 == 9)[:, None].repeat(2, 1)
    np.testing.assert_array_equal(truncated, expected)
    assert not terminated.any()
    np.testing.assert_array_equal(run.stacked("episode_length"), np.where(expected, 10, 0))
    ram = run.stacked("ram")
    for k in (9, 19):
        np.testing.assert_array_equal(ram[k], run.reset_info["ram"])
        # the next step continues exactly as the first episode did
        np.testing.assert_array_equal(ram[k + 1], ram[0])
    assert not run.stacked("reset_step").any()


def test_without_autoreset_the_step_after_the_end_resets():
    """autoreset=False: the step that ends an episode returns its final observation; the next
    step resets instead of stepping (reset_step True, reward 0, the first observation)."""
    env = make("Breakout", max_episode_frames=40, autoreset=False)
    try:
        run = run_env(env, np.full((12, 2), NOOP, np.int32))
    finally:
        env.close()
    truncated = run.stacked("truncated")
    assert truncated[9].all() and truncated.sum() == 2
    ram, reset_step = run.stacked("ram"), run.stacked("reset_step")
    assert not (ram[9] == run.reset_info["ram"]).all()  # the final observation, not a new one
    np.testing.assert_array_equal(reset_step, (np.arange(12) == 10)[:, None].repeat(2, 1))
    np.testing.assert_array_equal(ram[10], run.reset_info["ram"])
    assert not run.stacked("reward")[10].any()
    np.testing.assert_array_equal(ram[11], ram[0])
