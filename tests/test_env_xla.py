"""Stepping inside ``jax.jit`` (``handle, step = env.xla()``): a ``jax.lax.scan`` over the step
gives exactly what ``Env.step`` gives, handles step once, and every misuse is a clear error."""

from __future__ import annotations

import os
import signal

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import stori_jax
from stori_jax import Config

from _env_support import make, random_actions, to_numpy

STALE = "stale xla handle"


def scan(step, handle, actions):
    """Every step of ``actions`` (T, B) inside one compiled call."""
    return jax.jit(lambda h, a: jax.lax.scan(step, h, a))(handle, jnp.asarray(actions))


def python_steps(env, actions):
    return to_numpy(jax.tree.map(lambda *x: jnp.stack(x), *[env.step(a) for a in actions]))


def assert_same(a, b):
    names = ("obs", "reward", "terminated", "truncated")
    for name, x, y in zip(names, a[:4], b[:4]):
        np.testing.assert_array_equal(x, y, err_msg=name)
    assert a[4].keys() == b[4].keys()
    for name in a[4]:
        jax.tree.map(lambda x, y: np.testing.assert_array_equal(x, y, err_msg=name),
                     a[4][name], b[4][name])


DRIFT_T = 3
# episodes of 20 agent steps (max_episode_frames 80): autoresets inside the scan
CASES = {
    # (2.2's T = 300 is never reached in episodes of 20 steps: a cyclic T = 3 switches in each)
    "Breakout cyclic drift to a blackout, atari84": dict(game="Breakout", config=Config(
        drift=stori_jax.ConceptDrift("cyclic", DRIFT_T, Config(
            observation=stori_jax.ObservationMask("blackout", 1, 1.0)))), obs="atari84"),
    "Breakout 2.1 (events), autoreset=False": dict(game="Breakout", preset="2.1", obs="raw",
                                                   autoreset=False),
    "Boxing 3.2C (RAM-obs render), raw": dict(game="Boxing", preset="3.2C", obs="raw"),
    "Gopher 3.2 (per-frame blackout: both screens), raw": dict(game="Gopher", preset="3.2",
                                                              obs="raw"),
    "BankHeist 1 (action noise), type 0": dict(game="BankHeist", config=Config(
        action_noise=stori_jax.ActionNoise(0.3), ram_observation=True), obs="ram"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_scan_over_the_xla_step_is_env_step_bit_for_bit(case):
    kw = dict(CASES[case])
    game = kw.pop("game")
    steps = 45
    actions = random_actions(stori_jax.get_game(game).num_actions, steps, 2, seed=4)
    with make(game, max_episode_frames=80, **kw) as env:
        env.reset()
        expected = python_steps(env, actions)
    with make(game, max_episode_frames=80, **kw) as env:
        env.reset()
        handle, step = env.xla()
        handle, got = scan(step, handle, actions)
        assert int(handle.steps) == steps
    assert (expected[2] | expected[3]).sum() >= 4, "the run should cross episode ends"
    if "config" in kw and kw["config"].drift is not None:
        # the schedule at each env's own episode step: the counter restarts at every autoreset
        # (episodes of 20 steps are not a multiple of 2 T = 6, so a counter that ran on would
        # show)
        done = expected[2] | expected[3]
        episode_step = np.zeros(done.shape, int)
        for t in range(1, steps):
            episode_step[t] = np.where(done[t - 1], 0, episode_step[t - 1] + 1)
        np.testing.assert_array_equal(expected[4]["concept"], (episode_step // DRIFT_T) % 2)
    assert_same(to_numpy(got), expected)


def test_envpool_backend_steps_inside_jit_too():
    pytest.importorskip("envpool")
    actions = random_actions(4, 30, 2, seed=5)
    kw = dict(backend="envpool", autoreset=False, granularity="step", num_workers=None,
              max_episode_frames=80)
    with make("Breakout", preset="1", **kw) as env:
        env.reset()
        expected = python_steps(env, actions)
    with make("Breakout", preset="1", **kw) as env:
        env.reset()
        handle, step = env.xla()
        _, got = scan(step, handle, actions)
    assert_same(to_numpy(got), expected)


def test_reset_after_xla_steps_goes_on_as_after_python_steps():
    """The key stream continues from the last xla step: xla steps, reset, Python steps equal
    Python steps, reset, Python steps."""
    actions = random_actions(4, 12, 2, seed=6)
    with make("Breakout", preset="1") as env:
        env.reset()
        python_steps(env, actions[:8])
        expected = env.reset(), python_steps(env, actions[8:])
    with make("Breakout", preset="1") as env:
        env.reset()
        handle, step = env.xla()
        scan(step, handle, actions[:8])
        got = env.reset(), python_steps(env, actions[8:])
    jax.tree.map(np.testing.assert_array_equal, to_numpy(got[0]), to_numpy(expected[0]))
    assert_same(got[1], expected[1])


def test_a_handle_steps_once(caplog):
    with make("Breakout") as env:
        env.reset()
        first, step = env.xla()
        second, _ = step(first, jnp.zeros(2, jnp.int32))
        with pytest.raises(jax.errors.JaxRuntimeError, match=f"{STALE}: it follows 0 steps, "
                                                             "the env has taken 1"):
            step(first, jnp.zeros(2, jnp.int32))
        # the error is reported once, by the exception: JAX's log of it is dropped
        assert not [r for r in caplog.records if "io_callback failed" in r.getMessage()]
        third, _ = step(second, jnp.zeros(2, jnp.int32))  # the latest handle still steps
        assert int(third.steps) == 2
        env.reset()  # every handle is stale
        earlier = f"{STALE}: it comes from an earlier xla"
        with pytest.raises(jax.errors.JaxRuntimeError, match=earlier):
            step(third, jnp.zeros(2, jnp.int32))
        handle, same_step = env.xla()
        assert same_step is step  # one compiled step per env: a reset recompiles nothing
        with pytest.raises(jax.errors.JaxRuntimeError, match=earlier):
            step(first, jnp.zeros(2, jnp.int32))  # at 0 steps, as the new chain is
        handle, _ = step(handle, jnp.zeros(2, jnp.int32))
        assert int(handle.steps) == 1
        with make("Breakout") as other:  # a handle of another env, however alike
            other.reset()
            other_handle, other_step = other.xla()
            with pytest.raises(jax.errors.JaxRuntimeError, match="or from another env"):
                step(other_handle, jnp.zeros(2, jnp.int32))
            with pytest.raises(jax.errors.JaxRuntimeError, match="or from another env"):
                other_step(handle, jnp.zeros(2, jnp.int32))
            other_step(other_handle, jnp.zeros(2, jnp.int32))  # both still step their own
        step(handle, jnp.zeros(2, jnp.int32))


def test_a_handle_of_an_env_of_another_size_or_observation_is_refused_while_tracing():
    with make("Breakout") as env, make("Breakout", num_envs=3) as wider, \
            make("Breakout", obs="atari84") as stacked:
        handles = {}
        for name, e in (("env", env), ("wider", wider), ("stacked", stacked)):
            e.reset()
            handles[name] = e.xla()
        handle, step = handles["env"]
        for other in ("wider", "stacked"):
            other_handle, other_step = handles[other]
            with pytest.raises(ValueError, match=r"handle.state has .* comes from another env"):
                step(other_handle, jnp.zeros(2, jnp.int32))
            with pytest.raises(ValueError, match=r"handle.state has .* comes from another env"):
                other_step(handle, jnp.zeros(other_handle.reset_pending.shape, jnp.int32))
        step(handle, jnp.zeros(2, jnp.int32))  # refused before anything ran: each still steps
        handles["wider"][1](handles["wider"][0], jnp.zeros(3, jnp.int32))


@pytest.mark.parametrize("obs", ["atari84", "raw"])
def test_donating_a_handle_or_an_observation_leaves_the_env_intact(obs):
    """A caller's jit may donate its inputs (``donate_argnums``): the env hands out copies, so
    its own state survives, and it goes on exactly as an env whose arrays were not donated."""
    actions = random_actions(4, 6, 2, seed=9)
    donate = jax.jit(lambda x: jax.tree.map(lambda a: a // 2, x), donate_argnums=0)

    def play(env, donating):
        first, _ = env.reset()
        handle, step = env.xla()
        later, _ = step(handle, jnp.asarray(actions[0]))
        if donating:  # the first observation, the handle xla() gave and the one it stepped to
            donate((first, handle, later))
            assert first.is_deleted() and handle.state.stack.is_deleted()
        start = env.reset()
        last_obs = env.step(actions[1])[0]
        if donating:
            donate(last_obs)
            assert last_obs.is_deleted()
        return start, python_steps(env, actions[2:])

    with make("Breakout", preset="1", obs=obs) as env:
        expected = play(env, donating=False)
    with make("Breakout", preset="1", obs=obs) as env:
        got = play(env, donating=True)
    jax.tree.map(np.testing.assert_array_equal, to_numpy(got[0]), to_numpy(expected[0]))
    assert_same(got[1], expected[1])


def test_xla_misuse_is_a_clear_error():
    with make("Breakout") as env:
        with pytest.raises(RuntimeError, match="settled env: reset"):
            env.xla()
        env.reset()
        handle, step = env.xla()
        with pytest.raises(RuntimeError, match="already called"):
            env.xla()
        with pytest.raises(RuntimeError, match="stepped by the step function of env.xla"):
            env.step(np.zeros(2, np.int32))
        with pytest.raises(RuntimeError, match="stepped by the step function of env.xla"):
            env.recv()  # not "call send() first": send is refused too
        with pytest.raises(RuntimeError, match="needs a settled env"):
            env.snapshot()
        with pytest.raises(ValueError, match=r"shape \(2,\) of ints in \[0, 3\], got shape \(3,\)"):
            step(handle, jnp.zeros(3, jnp.int32))
        with pytest.raises(ValueError, match="integer dtype .* got float32"):
            step(handle, jnp.zeros(2, jnp.float32))
        with pytest.raises(ValueError, match="handle must be the XlaHandle"):
            step((handle.state,), jnp.zeros(2, jnp.int32))
        # a value out of range is seen on the host, before anything is sent
        with pytest.raises(jax.errors.JaxRuntimeError, match=r"actions out of range: .* 0\.\.7"):
            step(handle, jnp.array([0, 7], jnp.int32))
        handle, _ = step(handle, jnp.array([0, 3], jnp.int32))
        env.reset()
        env.step(np.zeros(2, np.int32))  # stepped from Python again
    with pytest.raises(jax.errors.JaxRuntimeError, match="environment is closed"):
        step(handle, jnp.zeros(2, jnp.int32))


def test_numpy_int64_actions_out_of_range_are_refused_with_x64_off():
    """JAX's default (x64 off) casts a numpy int64 argument to int32 before tracing: the step
    checks host values first, as env.step does (2**32 + 1 executed action 1)."""
    with make("Breakout") as env:
        env.reset()
        handle, step = env.xla()
        with pytest.raises(ValueError, match=r"actions out of range: .* got values "
                                             r"0\.\.4294967297"):
            step(handle, np.array([2 ** 32 + 1, 0]))
        with pytest.raises(ValueError, match="actions must have shape"):
            step(handle, [1, 2, 3])
        handle, (*_, info) = step(handle, np.array([3, 1]))
        np.testing.assert_array_equal(np.asarray(info["executed_action"])[:, -1], [3, 1])
        for actions in ([2, 0], (np.int64(1), np.int64(2))):  # as env.step takes them
            handle, (*_, info) = step(handle, actions)
            np.testing.assert_array_equal(np.asarray(info["executed_action"])[:, -1], actions)


def test_64_bit_actions_out_of_range_are_refused_not_wrapped():
    """With jax_enable_x64, int64 2**32 + 1 cast to int32 is 1: the xla step refuses it as
    env.step does (it executed action 1)."""
    with jax.enable_x64(True), make("Breakout") as env:
        env.reset()
        handle, step = env.xla()
        for actions in (jnp.array([2 ** 32 + 1, 0], jnp.int64),
                        jnp.array([-2 ** 32 + 2, 0], jnp.int64),
                        jnp.array([2 ** 63, 1], jnp.uint64)):
            with pytest.raises(jax.errors.JaxRuntimeError, match=r"actions out of range: .* got "
                               r"values (0\.\.2147483647|-2147483648\.\.0|1\.\.2147483647)\n"):
                step(handle, actions)
        handle, (obs, *_, info) = step(handle, jnp.array([3, 1], jnp.int64))
        np.testing.assert_array_equal(np.asarray(info["executed_action"])[:, -1], [3, 1])


def test_a_worker_dying_under_an_xla_step_is_reported():
    with make("Breakout", num_envs=2, num_workers=1, inline_envs=0) as env:
        env.reset()
        handle, step = env.xla()
        handle, _ = step(handle, jnp.zeros(2, jnp.int32))
        os.kill(env.backend.pids[0], signal.SIGKILL)
        with pytest.raises(jax.errors.JaxRuntimeError, match="worker 0 .*died"):
            step(handle, jnp.zeros(2, jnp.int32))


def test_a_failed_restore_of_an_xla_driven_env_needs_a_reset():
    with make("Breakout", num_envs=2, num_workers=1, inline_envs=0) as env:
        env.reset()
        snap = env.snapshot()
        handle, step = env.xla()
        step(handle, jnp.zeros(2, jnp.int32))
        broken = dict(snap, emulators=snap["emulators"][:1])  # one emulator missing
        with pytest.raises(Exception):
            env.restore(broken)
        with pytest.raises(RuntimeError, match="reset"):
            env.step(np.zeros(2, np.int32))
        env.restore(snap)  # a good restore (or a reset) continues
        env.step(np.zeros(2, np.int32))


def test_a_handle_taken_after_an_episode_end_starts_with_the_reset_step():
    """autoreset=False: an episode that ended in a Python step is reset by the next step, also
    when that step is the first through env.xla() (the handle carries the pending reset)."""
    kw = dict(autoreset=False, max_episode_frames=8)
    actions = np.array([[1, 3], [2, 0], [3, 1]], np.int32)
    with make("Breakout", **kw) as env:
        env.reset()
        expected = python_steps(env, actions)
    with make("Breakout", **kw) as env:
        env.reset()
        first = python_steps(env, actions[:2])
        assert first[3][-1].all()  # truncated: the cap of 8 frames
        handle, step = env.xla()
        handle, got = step(handle, jnp.asarray(actions[2]))
    assert np.asarray(got[4]["reset_step"]).all()
    assert_same(to_numpy(jax.tree.map(lambda x: x[None], got)),
                jax.tree.map(lambda x: x[2:], expected))


def test_after_an_error_in_an_xla_step_no_handle_is_current_until_reset():
    """An emulator failing under an xla step (here the env emulated in this process): the
    latest handle is stale too, and Python steps point to reset(), after which the env goes on
    as a fresh twin."""
    kw = dict(num_envs=2, num_workers=1, inline_envs=1)
    with make("Breakout", **kw) as env, make("Breakout", **kw) as twin:
        env.reset()
        handle, step = env.xla()
        handle, _ = step(handle, jnp.zeros(2, jnp.int32))

        def broken():
            raise RuntimeError("emulator failed")

        env.backend._inline[0].step = broken
        with pytest.raises(jax.errors.JaxRuntimeError, match="emulator failed"):
            step(handle, jnp.ones(2, jnp.int32))
        del env.backend._inline[0].step
        with pytest.raises(jax.errors.JaxRuntimeError, match=STALE):
            step(handle, jnp.ones(2, jnp.int32))
        with pytest.raises(RuntimeError, match=r"call reset\(\) first"):
            env.step(np.zeros(2, np.int32))
        np.testing.assert_array_equal(np.asarray(env.reset()[0]), np.asarray(twin.reset()[0]))
        actions = random_actions(4, 3, 2, seed=9)
        assert_same(python_steps(env, actions), python_steps(twin, actions))


def test_close_right_after_dispatching_a_scan_lets_its_queued_steps_finish():
    """A jitted scan returns before its emulator callbacks have run wherever JAX dispatches
    asynchronously (an accelerator; XLA's CPU client too, for long enough programs): close()
    waits for the steps still queued, so every one of them completes, as the same steps from
    Python do, instead of meeting closed workers."""
    actions = random_actions(4, 60, 2, seed=8)
    with make("Breakout", preset="1") as env:
        env.reset()
        expected = python_steps(env, actions)
    env = make("Breakout", preset="1")
    env.reset()
    handle, step = env.xla()
    handle, got = scan(step, handle, actions)  # dispatched, not waited for
    env.close()
    assert env.closed
    assert int(handle.steps) == len(actions)
    assert_same(to_numpy(got), expected)
