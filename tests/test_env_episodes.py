"""Episode boundaries through ``stori_jax.make``: autoreset, episode statistics, truncation and
``autoreset=False``."""

from __future__ import annotations

import numpy as np
import pytest

import stori_jax
from stori_jax import ActionNoise, ConceptDrift, Config, ObservationMask, RandomEvent

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


def test_without_autoreset_the_final_observation_ends_its_episode_stack_and_concept():
    """autoreset=False, atari84, Boxing cut at 200 frames (50 steps) under sudden drift (T = 3)
    to the clock's blackout at p = 1: the step that ends the episode returns its last four frames (the
    stack goes on, it does not restart there) and concept 2's mask; the reset step after it
    starts a new stack (one frame four times) under concept 1."""
    config = Config(drift=ConceptDrift("sudden", 3, Config(
        observation=ObservationMask("blackout", 8, 1.0))))
    env = make("Boxing", config, obs="atari84", max_episode_frames=200, autoreset=False)
    try:
        run = run_env(env, random_actions(env.num_actions, 52, 2, seed=0))
    finally:
        env.close()
    obs, done = run.stacked("obs"), run.done
    np.testing.assert_array_equal(done[:, 0], np.arange(52) == 49)
    final, before, first = obs[49], obs[48], obs[50]
    np.testing.assert_array_equal(final[..., :3], before[..., 1:])  # the stack went on
    for b in range(2):
        assert not (final[b][..., 0] == final[b][..., 3]).all(), b
        assert all((first[b][..., i] == first[b][..., 0]).all() for i in range(4)), b
    masked = run.stacked("obs_masked")
    assert masked[3:50].all() and not masked[:3].any() and not masked[50:].any()
    np.testing.assert_array_equal(run.stacked("concept")[:, 0], (np.arange(52) >= 3)
                                  & (np.arange(52) < 50))


@pytest.mark.parametrize("inline_envs", [0, 1])
def test_reset_reports_no_outcome_of_the_step_before(inline_envs):
    """``reset()`` after an episode end (and mid-episode) gives zero reward, events and
    episode totals: it carried the last step's event count and the ended episode's length and
    return, so a logger reading them counted the episode twice (worker and inline envs)."""
    env = make("BankHeist", Config(event=RandomEvent(3, 1.0)), max_episode_frames=40,
               num_workers=1, inline_envs=inline_envs)
    try:
        env.reset()
        for _ in range(10):
            *_, truncated, info = env.step(np.zeros(2, np.int32))
        assert truncated.all() and (info["event_fired"] > 0).all()
        assert (info["episode_length"] == 10).all()
        for _ in range(2):  # after the end, and mid-episode
            _, info = env.reset()
            for name in ("event_fired", "episode_length", "episode_return"):
                assert not np.asarray(info[name]).any(), name
            env.step(np.zeros(2, np.int32))
    finally:
        env.close()


def test_a_reset_step_reports_no_drawn_action_and_concept_1():
    """autoreset=False under sudden drift (T = 3) to type 1 at p = 1: the env reset instead of
    stepped reports executed NOOPs, no corruption and concept 1 (it reported the ended
    episode's concept 2 and corrupted actions that were never executed), as reset() does."""
    config = Config(drift=ConceptDrift("sudden", 3, Config(action_noise=ActionNoise(1.0))))
    env = make("Breakout", config, max_episode_frames=24, autoreset=False, num_envs=2)
    try:
        run = run_env(env, np.full((8, 2), 1, np.int32))
    finally:
        env.close()
    reset_step = run.stacked("reset_step")[:, 0]
    np.testing.assert_array_equal(reset_step, np.arange(8) == 6)  # ended at step 6 (24 frames)
    concept, corrupted = run.stacked("concept"), run.stacked("action_corrupted")
    np.testing.assert_array_equal(concept[:, 0], [0, 0, 0, 1, 1, 1, 0, 0])
    assert corrupted[3:6].all() and not corrupted[6].any() and not corrupted[:3].any()
    assert not run.stacked("executed_action")[6].any()
    np.testing.assert_array_equal(run.stacked("frames_played")[:, 0], np.where(reset_step, 0, 4))
    for info in (run.reset_info, run.info[6]):
        assert not info["concept"].any() and not info["action_corrupted"].any()


def test_episode_statistics_and_frame_stack_restart_at_each_autoreset():
    """Boxing, episodes cut at 200 frames (50 steps), three of them under random play with
    atari84 observations: at each end, episode_return is the sum of that episode's rewards
    alone and episode_length its 50 steps (the totals restart at an autoreset, not only at
    reset()); the observation returned is the next episode's first, its stack one frame four
    times (the frame stack restarts too, not only at reset())."""
    steps = 150
    env = make("Boxing", obs="atari84", max_episode_frames=200)
    try:
        run = run_env(env, random_actions(env.num_actions, steps, 2, seed=0))
    finally:
        env.close()
    reward, done, obs = run.stacked("reward"), run.done, run.stacked("obs")
    returns, lengths = run.stacked("episode_return"), run.stacked("episode_length")
    ends = np.arange(steps) % 50 == 49
    np.testing.assert_array_equal(done, ends[:, None].repeat(2, 1))
    np.testing.assert_array_equal(lengths, np.where(done, 50, 0))
    for k in np.nonzero(ends)[0]:
        np.testing.assert_array_equal(returns[k], reward[k - 49:k + 1].sum(0), err_msg=f"step {k}")
        for b in range(2):
            frames = obs[k, b]
            assert all((frames[..., i] == frames[..., 0]).all() for i in range(4)), (k, b)
        # without no-ops every episode starts as the first did: the NEW episode's first screen
        # (one frame four times would hold for the old episode's last screen too)
        np.testing.assert_array_equal(obs[k], run.reset_obs, err_msg=f"step {k}")
    assert not returns[~done].any()
    # engaged: an episode before the last scored, so a return carried over would show; the
    # stack mid-episode holds different frames, so a stack carried over would show
    assert returns[ends][:-1].any()
    assert all(not (obs[k, b][..., 0] == obs[k, b][..., 3]).all() for b in range(2)
               for k in np.nonzero(ends)[0][:-1] - 1)


def test_reset_clears_the_reset_a_finished_episode_left_pending():
    """Without autoreset, an ended episode's next step would reset it; a reset() in between
    does that, so the step after it is a real step that plays the agent's action (it was
    taken for the pending reset step and the action dropped)."""
    env = make("Breakout", num_envs=1, num_workers=0, autoreset=False, max_episode_frames=8,
               granularity="step")
    try:
        env.reset()
        env.step(np.zeros(1, np.int32))
        assert env.step(np.zeros(1, np.int32))[3][0]  # truncated: a reset is pending
        env.reset()
        *_, info = env.step(np.ones(1, np.int32))
        assert not info["reset_step"][0] and int(info["executed_action"][0]) == 1
    finally:
        env.close()


def test_no_step_after_the_first_compiles_not_even_at_an_episode_end():
    """The step that ends an episode hands over the ended episodes' screens too: compiled at
    reset, not at the first episode end (a second's pause mid-run, where Ctrl-C would land)."""
    from stori_jax import core

    with stori_jax.make("Breakout", "3.1", num_envs=1, seed=0, max_episode_frames=40) as env:
        env.reset()
        env.step([0])
        sizes = lambda: [f._cache_size() for f in (core.after_step, core.push_frames,  # noqa: E731
                                                   core.step_objects)]
        compiled = sizes()
        ended = 0
        for _ in range(12):
            ended += int(np.asarray(env.step([1])[3]).sum())
        assert ended >= 1
        assert sizes() == compiled
