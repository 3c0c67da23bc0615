"""Type 2.2 concept drift through ``stori_jax.make``: the concept switches at the exact agent
step (0-indexed step k is concept 2 iff k >= T for sudden, (k // T) % 2 for cyclic), returning
to concept 1 removes the secondary's effect, and the counter restarts with every episode."""

from __future__ import annotations

import numpy as np

from stori_jax import ActionNoise, Config, ConceptDrift, ObservationMask, RandomEvent, get_game

from _env_support import (NOOP, breakout_tracker, last_ram, lockstep_with_twin, make,
                          random_actions, run_env, run_lockstep)

BREAKOUT_ALL = [(8, 151, 57, 92), (7, 152, 189, 195), (2, 158, 3, 16), (8, 151, 105, 130),
                (8, 151, 131, 156), (8, 151, 157, 182)]  # Breakout blackout mode 1, black


def breakout_blackout_hidden():
    hidden = np.zeros((210, 160), bool)
    for x0, x1, y0, y1 in BREAKOUT_ALL:
        hidden[y0:y1 + 1, x0:x1 + 1] = True
    return hidden


def drift(schedule, period, secondary, **kw):
    return Config(drift=ConceptDrift(schedule, period, secondary), **kw)


def sudden_drift_in_episodes_of_10(game, secondary, *, steps, T, seed):
    """2 envs under sudden drift at ``T`` to ``secondary``, in episodes of 10 steps
    (max_episode_frames 40, frame_skip 4), beside a 3.1 twin on the same random actions: the
    game is the twin's, concept 2 holds on episode steps T..9, each episode is truncated at
    step 9, and concept 2 masks the observation, except the one returned with a truncation
    (the next episode's first).  (run, twin run, masked, truncated)."""
    config = drift("sudden", T, secondary)
    actions = random_actions(get_game(game).num_actions, steps, 2, seed=seed)
    ev, twin = lockstep_with_twin(game, config, steps, lambda k, runs: actions[k], obs="raw",
                                  max_episode_frames=40)
    np.testing.assert_array_equal(ev.ram, twin.ram)
    episode_step = np.arange(steps) % 10
    concept = ev.stacked("concept")
    np.testing.assert_array_equal(concept, np.repeat((episode_step >= T)[:, None], 2, 1))
    truncated = ev.stacked("truncated")
    np.testing.assert_array_equal(truncated, np.repeat((episode_step == 9)[:, None], 2, 1))
    masked = ev.stacked("obs_masked")
    np.testing.assert_array_equal(masked, (concept == 1) & ~truncated)
    assert not ev.reset_info["obs_masked"].any()
    return ev, twin, masked, truncated


def test_sudden_drift_to_blackout_switches_at_step_T_and_restarts_each_episode():
    """T = 5, episodes of 10 steps (max_episode_frames 40, frame_skip 4): steps 0..4 of each
    episode show the twin's screen, steps 5..9 the blackout; the observation returned at the
    episode end is the next episode's first (unmasked) one."""
    ev, twin, masked, truncated = sudden_drift_in_episodes_of_10(
        "Breakout", Config(observation=ObservationMask("blackout", 1, 1.0)), steps=25, T=5,
        seed=21)
    obs, twin_obs = ev.stacked("obs"), twin.stacked("obs")
    hidden = breakout_blackout_hidden()
    np.testing.assert_array_equal(obs[~masked], twin_obs[~masked])
    np.testing.assert_array_equal(obs[masked][:, ~hidden], twin_obs[masked][:, ~hidden])
    assert not obs[masked][:, hidden].any()
    np.testing.assert_array_equal(ev.reset_obs, twin.reset_obs)
    # no no-ops: the next episode's first screen is the first episode's (the twin would show
    # the old episode's last screen too, were both wrong alike)
    for k in np.nonzero(truncated[:, 0])[0]:
        np.testing.assert_array_equal(obs[k], ev.reset_obs, err_msg=f"step {k}")


def test_cyclic_drift_to_a_ram_obs_mode_alternates_every_T_steps():
    """Boxing, cyclic T = 3 to RAM mode 2 (hide enemy): the observation is rendered from the
    modified RAM exactly on steps 3..5, 9..11, ...; the game always equals the twin's."""
    steps, T = 14, 3
    config = drift("cyclic", T, Config(observation=ObservationMask("ram", 2, 1.0)))
    actions = random_actions(18, steps, 2, seed=22)
    ev, twin = lockstep_with_twin("Boxing", config, steps, lambda k, runs: actions[k], obs="raw")
    np.testing.assert_array_equal(ev.ram, twin.ram)
    np.testing.assert_array_equal(ev.stacked("reward"), twin.stacked("reward"))
    expected = (np.arange(steps) // T) % 2
    np.testing.assert_array_equal(ev.stacked("concept"), np.repeat(expected[:, None], 2, 1))
    masked = ev.stacked("obs_masked")
    np.testing.assert_array_equal(masked, ev.stacked("concept") == 1)
    obs, twin_obs = ev.stacked("obs"), twin.stacked("obs")
    np.testing.assert_array_equal(obs[~masked], twin_obs[~masked])
    assert (obs[masked] != twin_obs[masked]).any(axis=(1, 2, 3)).all()
    assert not ev.reset_info["obs_masked"].any()


def test_sudden_drift_to_a_ram_obs_mode_leaves_each_episodes_first_observation_true():
    """Boxing, sudden T = 3 to RAM mode 2 (hide enemy) at p = 1, episodes of 10 steps
    (max_episode_frames 40), autoreset: steps 3..9 of each episode are concept 2, and every
    one but the last is rendered; the observation returned with a truncation is the next
    episode's first, seen under concept 1: the true screen, the twin's and the first reset's,
    not rendered (obs_masked False) though the ending step was under concept 2."""
    ev, twin, masked, truncated = sudden_drift_in_episodes_of_10(
        "Boxing", Config(observation=ObservationMask("ram", 2, 1.0)), steps=22, T=3, seed=23)
    obs, twin_obs = ev.stacked("obs"), twin.stacked("obs")
    np.testing.assert_array_equal(obs[~masked], twin_obs[~masked])
    assert (obs[masked] != twin_obs[masked]).any(axis=(1, 2, 3)).all()
    np.testing.assert_array_equal(ev.reset_obs, twin.reset_obs)
    for k in np.nonzero(truncated[:, 0])[0]:
        np.testing.assert_array_equal(obs[k], ev.reset_obs, err_msg=f"step {k}")


def test_drift_to_action_noise_restarts_after_autoreset():
    """Sudden T = 3 to type 1 with p = 1 at step granularity, episodes of 8 steps: corruption
    happens exactly on episode steps 3..7 of every episode."""
    steps, T = 20, 3
    config = drift("sudden", T, Config(action_noise=ActionNoise(1.0)), granularity="step")
    env = make("Breakout", config, max_episode_frames=32)
    try:
        run = run_env(env, np.full((steps, 2), NOOP, np.int32))
    finally:
        env.close()
    episode_step = np.arange(steps) % 8
    np.testing.assert_array_equal(run.stacked("truncated")[:, 0], episode_step == 7)
    np.testing.assert_array_equal(run.stacked("episode_length")[:, 0],
                                  np.where(episode_step == 7, 8, 0))
    concept = run.stacked("concept")
    np.testing.assert_array_equal(concept, np.repeat((episode_step >= T)[:, None], 2, 1))
    corrupted = run.stacked("action_corrupted")
    assert corrupted.shape == (steps, 2)
    np.testing.assert_array_equal(corrupted, concept == 1)
    executed = run.stacked("executed_action")
    assert (executed[concept == 0] == NOOP).all()
    assert (executed[concept == 1] != NOOP).any()
    # what the emulators played, not only what info reports: the reported actions, replayed
    # without noise, give the same game frame for frame
    plain = make("Breakout", Config(granularity="step"), max_episode_frames=32)
    try:
        replay = run_env(plain, executed)
    finally:
        plain.close()
    np.testing.assert_array_equal(run.ram, replay.ram)


def test_drift_to_an_event_keeps_the_episode_start_ram():
    """docs/spec.md section 9b: the switch to concept 2 does not re-read the episode-start RAM.
    Breakout, sudden T = 200 to regenerate-a-hit-block (mode 3, p = 1, per frame), a
    ball-tracking policy: the blocks hit in concept 1 stay missing until step T, whose four
    frames write them back to their values at the reset, one per frame; from then on the blocks
    are the reset's (a block hit is regenerated in its own frame). Re-reading the RAM at the
    switch would take the missing blocks as the start and never bring them back."""
    T = 200
    config = drift("sudden", T, Config(event=RandomEvent(3, 1.0)))
    env = make("Breakout", config)
    try:
        run = run_lockstep([env], T + 10, lambda k, runs: breakout_tracker(last_ram(runs[0])))[0]
    finally:
        env.close()
    assert not run.done.any()
    np.testing.assert_array_equal(run.stacked("concept"),
                                  np.repeat((np.arange(T + 10) >= T)[:, None], 2, 1))
    start, blocks = run.reset_info["ram"][:, :36], run.ram[:, :, :36]  # ram[k + 1]: after step k
    missing = (blocks != start).sum(-1)
    assert (missing[T] >= 2).all(), "the tracker should have hit blocks before the switch"
    fired = run.stacked("event_fired")
    assert not fired[:T].any()
    np.testing.assert_array_equal(fired[T], missing[T])
    np.testing.assert_array_equal(blocks[T + 1:], np.broadcast_to(start, blocks[T + 1:].shape))


def test_previous_ram_is_tracked_while_a_drifted_event_is_off():
    """'Previous RAM' is the RAM before the current frame, also while concept 1 has the event
    switched off.  Breakout, sudden T = 150 to block-hit cancel (mode 1, p = 1, per frame), a
    ball-tracking policy: the blocks hit in concept 1 stay gone, and from step T on every further
    hit is undone, so the block RAM stays what it was at the switch.  (With the previous RAM
    frozen at the reset while the event was off, the first frame of step T saw every block hit
    in concept 1 as a change of that frame and wrote them all back.)"""
    T, steps = 150, 170
    config = drift("sudden", T, Config(event=RandomEvent(1, 1.0)))
    env = make("Breakout", config)
    try:
        run = run_lockstep([env], steps, lambda k, runs: breakout_tracker(last_ram(runs[0])))[0]
    finally:
        env.close()
    assert not run.done.any()
    np.testing.assert_array_equal(run.stacked("concept"),
                                  np.repeat((np.arange(steps) >= T)[:, None], 2, 1))
    start, blocks = run.reset_info["ram"][:, :36], run.ram[:, :, :36]  # ram[k + 1]: after step k
    assert ((blocks[T] != start).sum(-1) >= 2).all(), "the tracker should have hit blocks"
    fired = run.stacked("event_fired")
    assert not fired[:T].any()
    assert fired[T:].any(), "a hit after the switch should have been undone"
    np.testing.assert_array_equal(blocks[T:], np.broadcast_to(blocks[T], blocks[T:].shape))


def test_make_granularity_overrides_a_drift_secondary_s_too():
    """``make(granularity=...)`` overrides the config's: concept 2's own field included (it
    refused a secondary set to 'step', telling the user to set a field they had not passed)."""
    step = Config(granularity="step", drift=ConceptDrift("sudden", 5, Config(
        action_noise=ActionNoise(0.3), granularity="step")))
    env = make("Breakout", step, granularity="frame")
    try:
        assert env.config.granularity == "frame" and env.plan.per_frame
        assert env.config.drift.secondary.granularity == "frame"
    finally:
        env.close()
