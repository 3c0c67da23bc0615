"""Type 1 (action corruption) through ``stori_jax.make``: the executed actions reported in
``info['executed_action']`` are the ones the emulators execute, corrupted at rate p, with the
replacement drawn uniformly from the game's set (BankHeist: actions 0..9)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

import stori_jax
from stori_jax import ActionNoise, Config
from stori_jax.builder import emulator_seeds

from _env_support import binomial_ok, make, new_ale, random_actions, run_env, to_numpy


def noise(prob, granularity="frame", **kw):
    return Config(action_noise=ActionNoise(prob, **kw), granularity=granularity)


def test_frame_granularity_corrupts_each_frame_at_rate_p():
    steps, p = 100, 0.3
    env = make("Breakout", noise(p))
    try:
        run = run_env(env, random_actions(4, steps, 2, seed=31))
    finally:
        env.close()
    executed, corrupted = run.stacked("executed_action"), run.stacked("action_corrupted")
    assert executed.shape == corrupted.shape == (steps, 2, 4)
    assert executed.dtype.kind == "i" and corrupted.dtype == bool
    intended = np.broadcast_to(run.stacked("actions")[:, :, None], executed.shape)
    np.testing.assert_array_equal(executed[~corrupted], intended[~corrupted])
    assert binomial_ok(int(corrupted.sum()), corrupted.size, p)
    # the replacement is uniform over the whole minimal set (it may equal the intended action)
    counts = np.bincount(executed[corrupted], minlength=4)
    assert len(counts) == 4 and binomial_ok(int(counts[0]), int(corrupted.sum()), 0.25)
    assert (counts > 0).all()
    changed = (executed != intended).sum()
    assert binomial_ok(int(changed), executed.size, p * 3 / 4)


@pytest.mark.parametrize("game,replacements", [
    ("Breakout", range(4)), ("Boxing", range(18)), ("Gopher", range(8)), ("BankHeist", range(10))])
def test_the_env_s_own_draws_corrupt_at_rate_p_uniformly_over_its_whole_set(game, replacements):
    """The env's draw (its compiled plan through core.before_step, with no emulator: 8192 envs,
    two steps, 65536 frame draws) corrupts at p within 4% and draws each replacement as often
    as any other. (A plan at 1.2 p, or a table that named one action twice, passed the rate
    tests on a few hundred emulated draws, which checked one action's share.)"""
    from stori_jax.core import before_step, initial_state
    from stori_jax.env import jit_key
    from stori_jax.plan import compile_plan

    p, b = 0.3, 8192
    plan = compile_plan(stori_jax.preset(game, "1"), stori_jax.get_game(game), num_envs=b,
                        frame_skip=4, obs="ram", noop_max=0)
    assert plan.noise.prob == p and plan.noise.replacement == tuple(replacements)
    state, executed, corrupted = initial_state(plan, 0), [], []
    intended = jnp.asarray(random_actions(plan.num_actions, 1, b, seed=5)[0])
    for _ in range(2):
        state, draws = before_step(jit_key(plan), state, intended)
        executed.append(np.asarray(draws.executed))
        corrupted.append(np.asarray(draws.corrupted))
    executed, corrupted = np.stack(executed), np.stack(corrupted)
    assert binomial_ok(int(corrupted.sum()), corrupted.size, p)
    counts = np.bincount(executed[corrupted], minlength=plan.num_actions)
    share = 1 / len(replacements)
    for action in range(plan.num_actions):
        if action in replacements:
            assert binomial_ok(int(counts[action]), int(corrupted.sum()), share), counts
        else:  # BankHeist: the eight moves that also fire are never a replacement
            assert counts[action] == 0, counts
    kept = np.broadcast_to(np.asarray(intended)[None, :, None], executed.shape)
    np.testing.assert_array_equal(executed[~corrupted], kept[~corrupted])


def test_step_granularity_draws_once_per_step():
    steps, p = 120, 0.4
    env = make("Gopher", noise(p, "step"))
    try:
        run = run_env(env, random_actions(8, steps, 2, seed=32))
    finally:
        env.close()
    executed, corrupted = run.stacked("executed_action"), run.stacked("action_corrupted")
    assert executed.shape == corrupted.shape == (steps, 2)
    intended = run.stacked("actions")
    np.testing.assert_array_equal(executed[~corrupted], intended[~corrupted])
    assert binomial_ok(int(corrupted.sum()), corrupted.size, p)
    assert ((0 <= executed) & (executed < 8)).all()


def test_reported_executed_actions_are_the_executed_ones():
    """Feeding a 3.1 twin (frame_skip 1) the reported executed actions reproduces the noisy
    run's RAM and rewards frame for frame."""
    steps = 60
    ev = make("Boxing", noise(0.5), frame_skip=1)
    twin = make("Boxing", frame_skip=1)
    intended = random_actions(18, steps, 2, seed=33)
    try:
        ev_ram = [to_numpy(ev.reset()[1]["ram"])]
        twin_ram = [to_numpy(twin.reset()[1]["ram"])]
        ev_reward, twin_reward, n_changed = [], [], 0
        for k in range(steps):
            _, r, _, _, info = to_numpy(ev.step(intended[k]))
            executed = info["executed_action"]
            assert executed.shape == (2, 1)
            n_changed += int((executed[:, 0] != intended[k]).sum())
            _, tr, _, _, tinfo = to_numpy(twin.step(executed[:, 0]))
            ev_ram.append(info["ram"])
            twin_ram.append(tinfo["ram"])
            ev_reward.append(r)
            twin_reward.append(tr)
    finally:
        ev.close()
        twin.close()
    assert n_changed > 10
    np.testing.assert_array_equal(np.stack(ev_ram), np.stack(twin_ram))
    np.testing.assert_array_equal(np.stack(ev_reward), np.stack(twin_reward))


def test_bankheist_replacements_come_from_actions_0_to_9():
    """BankHeist draws the replacement from actions 0..9 (NOOP, FIRE, the eight directions)."""
    steps = 60
    env = make("BankHeist", noise(1.0))
    intended = np.random.default_rng(34).integers(10, 18, (steps, 2)).astype(np.int32)
    try:
        run = run_env(env, intended)
    finally:
        env.close()
    executed, corrupted = run.stacked("executed_action"), run.stacked("action_corrupted")
    assert corrupted.all()
    assert ((0 <= executed) & (executed < 10)).all()
    assert set(np.unique(executed)) == set(range(10))


def test_sticky_actions_repeat_the_previous_executed_action():
    steps = 80
    env = make("Boxing", noise(0.5, sticky=True))
    try:
        run = run_env(env, random_actions(18, steps, 2, seed=35))
    finally:
        env.close()
    executed, corrupted = run.stacked("executed_action"), run.stacked("action_corrupted")
    intended = run.stacked("actions")
    flat = executed.transpose(1, 0, 2).reshape(2, -1)  # (B, T * frame_skip) frame by frame
    previous = np.concatenate([np.zeros((2, 1), flat.dtype), flat[:, :-1]], 1)
    fired = corrupted.transpose(1, 0, 2).reshape(2, -1)
    wanted = np.repeat(intended.T, 4, axis=1)
    np.testing.assert_array_equal(flat[fired], previous[fired])
    np.testing.assert_array_equal(flat[~fired], wanted[~fired])
    assert binomial_ok(int(fired.sum()), fired.size, 0.5)


def test_sticky_actions_start_every_episode_from_noop():
    """After an autoreset, as after env.reset(), the previous executed action is NOOP: the first
    frame of an episode never repeats the last action of the one before (episodes truncated at
    40 frames = 10 steps; NOOP is action 0)."""
    steps, episode = 60, 10
    env = make("Boxing", noise(0.5, sticky=True), max_episode_frames=4 * episode)
    try:
        run = run_env(env, np.random.default_rng(36).integers(1, 18, (steps, 2), dtype=np.int32))
    finally:
        env.close()
    np.testing.assert_array_equal(run.stacked("truncated")[:, 0],
                                  np.arange(steps) % episode == episode - 1)
    executed, fired = run.stacked("executed_action"), run.stacked("action_corrupted")
    flat = executed.transpose(1, 0, 2).reshape(2, -1)  # (B, T * frame_skip) frame by frame
    sticky = fired.transpose(1, 0, 2).reshape(2, -1)
    starts = np.arange(0, steps, episode) * 4  # the first frame of every episode
    previous = np.concatenate([np.zeros((2, 1), flat.dtype), flat[:, :-1]], 1)
    last_of_episode_before = previous[:, starts[1:]].copy()
    previous[:, starts] = 0
    np.testing.assert_array_equal(flat[sticky], previous[sticky])
    # not vacuous: some episodes start sticky where the episode before ended on another action
    assert (sticky[:, starts[1:]] & (last_of_episode_before != 0)).sum() >= 2


def test_a_steps_per_frame_actions_reach_the_emulator_in_frame_order():
    """Frame granularity: ``info['executed_action'][b, f]`` is what frame f of the step ran. A
    bare emulator of the same seed fed those actions frame by frame has the env's RAM after
    every step (the rate tests above could not see the frames played in another order)."""
    env = make("Boxing", noise(0.5), num_envs=1, num_workers=0)
    ale = new_ale("boxing", emulator_seeds(0, 1)[0])
    minimal = ale.getMinimalActionSet()
    ale.reset_game()
    mixed = 0
    try:
        env.reset()
        for k, actions in enumerate(random_actions(18, 15, 1, seed=0)):
            obs, *_, info = to_numpy(env.step(actions))
            executed = info["executed_action"][0]
            mixed += len(set(executed.tolist())) > 1
            for action in executed:
                ale.act(minimal[int(action)])
            np.testing.assert_array_equal(obs[0], ale.getRAM(), err_msg=f"step {k}")
    finally:
        env.close()
    assert mixed >= 5  # steps whose frames ran different actions: the order matters there


@pytest.mark.parametrize("autoreset", [True, False])
def test_frames_after_an_episode_s_end_are_reported_as_not_played(autoreset):
    """Frame granularity, an episode cut at frame 6 of steps of 4 frames: its second step plays
    2 frames, so its last two slots report NOOP (0) and no corruption (ALE plays no frame past
    an episode's end; an env reset instead of stepped reports the same)."""
    env = make("Breakout", noise(1.0), num_envs=1, num_workers=0, obs="ram",
               max_episode_frames=6, autoreset=autoreset)
    ale = new_ale("breakout", emulator_seeds(0, 1)[0])
    minimal = ale.getMinimalActionSet()
    ale.reset_game()
    try:
        env.reset()
        for k in range(2):
            obs, _, _, truncated, info = to_numpy(env.step(np.array([k + 1], np.int32)))
            played = 4 if k == 0 else 2
            assert bool(truncated[0]) == (k == 1)
            assert info["frames_played"][0] == played
            corrupted, executed = info["action_corrupted"][0], info["executed_action"][0]
            np.testing.assert_array_equal(corrupted, np.arange(4) < played, err_msg=f"step {k}")
            assert (executed[played:] == 0).all()
            for action in executed[:played]:
                ale.act(minimal[int(action)])
        if not autoreset:  # the final observation: the RAM after exactly the played frames
            np.testing.assert_array_equal(obs[0], ale.getRAM())
    finally:
        env.close()
