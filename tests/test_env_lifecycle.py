"""Lifecycle and input validation of ``stori_jax.make`` / ``Env``: dead workers, close, garbage
collection, Ctrl-C, and the error messages of bad arguments and actions."""

from __future__ import annotations

import contextlib
import gc
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest

import stori_jax
from stori_jax import Config, ConceptDrift, ObservationMask

from _env_support import emulator_states, make, process_gone, run_env, wait_gone


def test_close_stops_every_worker_and_later_calls_raise():
    env = make("Breakout", num_envs=3, num_workers=3)
    pids = list(env.backend.pids)
    assert len(pids) == 3 and len(set(pids)) == 3
    env.reset()
    env.step(np.zeros(3, np.int32))
    assert not any(process_gone(pid) for pid in pids)
    env.close()
    assert env.closed
    assert all(process_gone(pid) for pid in pids)  # close() waits for them
    for pid in pids:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)  # reaped: no zombie left behind
    with pytest.raises(stori_jax.EnvClosedError):
        env.step(np.zeros(3, np.int32))
    with pytest.raises(stori_jax.EnvClosedError):
        env.reset()
    env.close()  # idempotent


def test_context_manager_closes():
    with make("Boxing", num_workers=1) as env:
        pids = list(env.backend.pids)
        env.reset()
    assert env.closed and wait_gone(pids, 1.0)


def test_deleting_the_env_stops_its_workers():
    env = make("Gopher", num_envs=2, num_workers=2)
    env.reset()
    env.step(np.zeros(2, np.int32))
    pids = list(env.backend.pids)
    del env
    gc.collect()
    assert wait_gone(pids, 3.0)


def test_deleting_an_env_stepped_through_xla_stops_its_workers():
    """JAX's caches keep every traced host callback: the env's must not keep the env (and its
    workers) alive. A step function kept past its env says the env is gone."""
    import jax
    import jax.numpy as jnp

    env = make("Breakout", num_envs=2, num_workers=1)
    env.reset()
    handle, step = env.xla()
    handle, out = step(handle, jnp.zeros(2, jnp.int32))
    jax.block_until_ready(out)
    pids = list(env.backend.pids)
    del env, out
    gc.collect()
    assert wait_gone(pids, 3.0)
    with pytest.raises(Exception, match="garbage collected"):
        jax.block_until_ready(step(handle, jnp.zeros(2, jnp.int32)))


@pytest.mark.timeout(30)
def test_a_killed_worker_raises_worker_error_quickly():
    env = make("Breakout", num_envs=4, num_workers=2)
    pids = list(env.backend.pids)
    env.reset()
    env.step(np.zeros(4, np.int32))
    os.kill(pids[0], signal.SIGKILL)
    start = time.monotonic()
    with pytest.raises(stori_jax.WorkerError, match="died"):
        for _ in range(3):  # the first call may already have been sent to a live pipe
            env.step(np.zeros(4, np.int32))
    assert time.monotonic() - start < 10.0  # promptly (no hang), with room for a busy machine
    assert env.closed
    assert wait_gone(pids, 3.0)  # the surviving worker is stopped too
    with pytest.raises(stori_jax.EnvClosedError):
        env.step(np.zeros(4, np.int32))


@pytest.mark.timeout(60)
def test_an_interrupted_step_stays_in_flight_and_can_be_finished():
    """Ctrl-C while waiting for the emulators (a notebook interrupt): the step stays in flight;
    recv() finishes it with the right result, and later steps match an uninterrupted twin.
    (Before the fix the next step() took the interrupted step's replies as its own.)"""
    ev, twin = make("Breakout", num_workers=1), make("Breakout")
    armed = threading.Event()

    def on_sigint(*_):
        if armed.is_set():  # a late signal is ignored instead of stopping the test session
            raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        ev.reset()
        twin.reset()
        actions = np.array([1, 2], np.int32)
        with stopped(ev.backend.pids[0]):  # so that the interrupt surely lands in the wait
            ev.send(actions)
            armed.set()
            threading.Timer(0.02, os.kill, (os.getpid(), signal.SIGINT)).start()
            with pytest.raises(KeyboardInterrupt):
                ev.recv()
            armed.clear()
        with pytest.raises(RuntimeError, match="in flight"):
            ev.step(actions)
        expected = twin.step(actions)
        got = ev.recv()
        for name, a, b in zip(("obs", "reward", "terminated", "truncated"), got, expected):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b), err_msg=name)
        for actions in ([3, 0], [2, 1]):
            got, expected = ev.step(actions), twin.step(actions)
            np.testing.assert_array_equal(np.asarray(got[4]["ram"]),
                                          np.asarray(expected[4]["ram"]))
        # a reset whose replies were never collected is finished by the next reset()
        ev.backend.send_reset()
        assert ev.backend.pending
        obs, info = ev.reset()
        np.testing.assert_array_equal(np.asarray(obs), np.asarray(twin.reset()[0]))
        assert not ev.backend.pending
    finally:
        armed.clear()
        signal.signal(signal.SIGINT, previous)
        ev.close()
        twin.close()


@contextlib.contextmanager
def stopped(pid):
    """The process stopped (SIGSTOP) inside the block, continued after it."""
    os.kill(pid, signal.SIGSTOP)
    try:
        yield
    finally:
        os.kill(pid, signal.SIGCONT)


@contextlib.contextmanager
def ctrl_c_armed():
    """SIGINT raises KeyboardInterrupt inside the block (whatever handler the runner left)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def signal_after(owner, method: str):
    """``owner.method`` does its work, then a real SIGINT arrives (once): Python runs the
    handler right there, as a Ctrl-C landing at that point would."""
    real = getattr(owner, method)

    def and_then_ctrl_c(*args):
        result = real(*args)
        delattr(owner, method)  # the class's method again
        signal.raise_signal(signal.SIGINT)
        return result

    setattr(owner, method, and_then_ctrl_c)


def assert_same_steps(env, twin, first_got, first_actions):
    expected = twin.step(first_actions)
    for name, a, b in zip(("obs", "reward", "terminated", "truncated"), first_got, expected):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b), err_msg=name)
    for t in range(6):
        actions = np.array([t % 4, (t + 1) % 4], np.int32)
        got, expected = env.step(actions), twin.step(actions)
        np.testing.assert_array_equal(np.asarray(got[4]["ram"]), np.asarray(expected[4]["ram"]),
                                      err_msg=f"step {t} after the interrupted one")


@pytest.mark.parametrize("where", ["after the first worker got the step",
                                   "after a worker's reply was read"])
def test_ctrl_c_between_two_workers_leaves_the_step_in_flight(where):
    """A Ctrl-C landing between sending the step to one worker and the next, or between reading
    a worker's reply and recording it: the step stays in flight, recv() finishes it, and the
    env goes on as an uninterrupted twin.  (Before, the env forgot the sent step and later
    steps read the workers' buffers while they were being written; or recv() waited forever
    for a reply it had already read.)"""
    env, twin = make("Breakout", num_workers=2, inline_envs=0), make("Breakout")
    try:
        env.reset()
        twin.reset()
        actions = np.array([1, 3], np.int32)
        conn = env.backend.conns[0]
        signal_after(conn, "send_bytes" if where.startswith("after the first") else "recv_bytes")
        with ctrl_c_armed(), pytest.raises(KeyboardInterrupt):
            env.step(actions)
        assert env.backend.pending  # the step is in flight, its records intact
        assert_same_steps(env, twin, env.recv(timeout=30), actions)
    finally:
        env.close()
        twin.close()


def test_an_interrupted_snapshot_points_every_call_to_reset():
    """Ctrl-C while the workers copy their state: step, recv, snapshot and xla all say reset(),
    which waits for the workers and gives the twin's first observation."""
    env, twin = make("Breakout", num_workers=1), make("Breakout")
    try:
        env.reset()
        twin.reset()
        with stopped(env.backend.pids[0]), ctrl_c_armed():
            threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGINT)).start()
            with pytest.raises(KeyboardInterrupt):
                env.snapshot()
        for call in (lambda: env.step([0, 1]), env.recv, env.snapshot, env.xla):
            with pytest.raises(RuntimeError, match=r"reset\(\)"):
                call()
        np.testing.assert_array_equal(np.asarray(env.reset()[0]), np.asarray(twin.reset()[0]))
        assert_same_steps(env, twin, env.step([1, 1]), np.array([1, 1], np.int32))
    finally:
        env.close()
        twin.close()


@pytest.mark.timeout(60)
def test_ctrl_c_stops_a_restore_waiting_on_a_stuck_worker():
    """The states go to the workers through files: every command is a few bytes, so nothing
    blocks while Ctrl-C is held back.  (A pickle of 16 emulators filled the pipe, and Ctrl-C
    waited for the stopped worker to read it.)"""
    env = make("Breakout", num_envs=16, num_workers=1)
    try:
        env.reset()
        snapshot = env.snapshot()
        with stopped(env.backend.pids[0]), ctrl_c_armed():
            threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT)).start()
            started = time.monotonic()
            with pytest.raises(KeyboardInterrupt):
                env.restore(snapshot)
            assert time.monotonic() - started < 10
        with pytest.raises(RuntimeError, match=r"reset\(\)"):
            env.step(np.zeros(16, np.int32))
        env.reset()
        env.restore(snapshot)  # and the next restore goes through
        assert env.step(np.zeros(16, np.int32))[0].shape == (16, 128)
    finally:
        env.close()


@pytest.mark.timeout(60)
@pytest.mark.parametrize("call", ["recv", "step"])
def test_a_timed_out_recv_names_the_late_worker_and_can_be_finished(call):
    """recv(timeout), or step(timeout), while a worker is stopped (SIGSTOP): a TimeoutError that
    names it, the step stays in flight, and once the worker runs again recv() finishes it as an
    uninterrupted twin does."""
    ev, twin = make("Breakout", num_workers=2, inline_envs=0), make("Breakout")
    try:
        ev.reset()
        twin.reset()
        actions = np.array([1, 3], np.int32)
        late = ev.backend.pids[1]
        with stopped(late):
            with pytest.raises(TimeoutError, match=rf"emulator worker\(s\) \[1\] \(pids "
                                                   rf"\[{late}\]\) did not finish a step within "
                                                   rf"0\.2 s; it is still in flight"):
                if call == "recv":
                    ev.send(actions)
                    ev.recv(timeout=0.2)
                else:
                    ev.step(actions, timeout=0.2)
            with pytest.raises(RuntimeError, match="in flight"):
                ev.step(actions)
        got, expected = ev.recv(timeout=30), twin.step(actions)
        for name, a, b in zip(("obs", "reward", "terminated", "truncated"), got, expected):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b), err_msg=name)
        got, expected = ev.step([2, 0]), twin.step([2, 0])
        np.testing.assert_array_equal(np.asarray(got[4]["ram"]), np.asarray(expected[4]["ram"]))
    finally:
        ev.close()
        twin.close()


@pytest.mark.timeout(60)
@pytest.mark.parametrize("in_flight", [False, True], ids=["settled", "step-in-flight"])
def test_a_timed_out_reset_needs_a_reset_that_waits_for_it(in_flight):
    """reset(timeout) while a worker is stopped: a TimeoutError that names it (the timeout bounds
    the wait for a step still in flight too); the env refuses steps until reset() again, which
    waits for the late one and gives the same episode as an uninterrupted twin."""
    ev, twin = make("Breakout", num_workers=2, inline_envs=0), make("Breakout")
    try:
        for env in (ev, twin):
            env.reset()
            env.step([1, 2])
        late = ev.backend.pids[0]
        with stopped(late):
            if in_flight:
                ev.send([3, 3])
            started = time.monotonic()
            with pytest.raises(TimeoutError, match=rf"emulator worker\(s\) \[0\] \(pids "
                                                   rf"\[{late}\]\) did not finish a "
                                                   rf"{'step' if in_flight else 'reset'} within "
                                                   rf"0\.3 s; the env needs reset\(\)"):
                ev.reset(timeout=0.3)
            assert time.monotonic() - started < 5
            with pytest.raises(RuntimeError, match=r"call reset\(\) first"):
                ev.send([0, 0])
        got, expected = ev.reset(timeout=30), twin.reset()
        np.testing.assert_array_equal(np.asarray(got[0]), np.asarray(expected[0]))
        got, expected = ev.step([1, 3], timeout=30), twin.step([1, 3])
        np.testing.assert_array_equal(np.asarray(got[4]["ram"]), np.asarray(expected[4]["ram"]))
    finally:
        ev.close()
        twin.close()


@pytest.mark.timeout(60)
@pytest.mark.parametrize("in_flight", [False, True], ids=["settled", "step-in-flight"])
def test_a_timed_out_reset_with_a_seed_is_finished_from_that_seed(in_flight):
    """reset(seed=7, timeout) while a worker is stopped (late with the reset, or with a step
    still in flight, before the reset was sent): the plain reset() that finishes it restarts
    from seed 7, the inline env too, as a new env of seed 7."""
    ev = make("Breakout", preset="1", seed=3, num_envs=3, num_workers=1, inline_envs=1)
    fresh = make("Breakout", preset="1", seed=7, num_envs=3)
    try:
        ev.reset()
        ev.step([1, 2, 3])
        with stopped(ev.backend.pids[0]):
            if in_flight:
                ev.send([3, 3, 3])
            with pytest.raises(TimeoutError, match="the env needs reset"):
                ev.reset(seed=7, timeout=0.3)
        assert ev.seed == 7
        got, expected = ev.reset(timeout=30), fresh.reset()
        np.testing.assert_array_equal(np.asarray(got[1]["ram"]), np.asarray(expected[1]["ram"]))
        assert emulator_states(ev) == emulator_states(fresh)  # ALE's random generator too
        for actions in ([1, 3, 0], [2, 0, 1], [3, 3, 3]):
            got, expected = ev.step(actions), fresh.step(actions)
            for name in ("ram", "executed_action"):
                np.testing.assert_array_equal(np.asarray(got[4][name]),
                                              np.asarray(expected[4][name]), err_msg=name)
    finally:
        ev.close()
        fresh.close()


CHILD = textwrap.dedent("""
    import faulthandler
    import signal
    import sys
    import numpy as np

    faulthandler.register(signal.SIGUSR1, all_threads=True)  # the test asks for stacks on a hang
    # a terminal's Ctrl-C reaches a Python started with default signal handling; a child of the
    # test runner may inherit SIGINT ignored or blocked instead: record that, then start clean
    print(f"inherited: SIGINT handler {signal.getsignal(signal.SIGINT)!r}, blocked "
          f"{sorted(signal.pthread_sigmask(signal.SIG_BLOCK, []))}", file=sys.stderr, flush=True)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    import stori_jax

    env = stori_jax.make("Breakout", num_envs=2, seed=0, num_workers=2, obs="ram")
    env.reset()
    print(" ".join(str(p) for p in env.backend.pids), flush=True)
    actions = np.zeros(2, np.int32)
    while True:
        env.step(actions)
""")


@pytest.mark.slow
@pytest.mark.timeout(60)
def test_ctrl_c_exits_and_leaves_no_worker(tmp_path):
    """A script stepping forever gets Ctrl-C (SIGINT to its whole process group, as a terminal
    sends it): it exits, and none of its workers survives."""
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    child = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        line = child.stdout.readline()
        pids = [int(p) for p in line.split()]
        assert len(pids) == 2, (line, child.stderr.read() if child.poll() is not None else "")
        time.sleep(0.3)  # let it step a while
        assert child.poll() is None
        os.killpg(child.pid, signal.SIGINT)
        try:
            _, stderr = child.communicate(timeout=30)  # reading stderr: a full pipe cannot block it
        except subprocess.TimeoutExpired:
            child.send_signal(signal.SIGUSR1)
            time.sleep(1.0)
            child.kill()
            _, stderr = child.communicate()
            pytest.fail(f"the child did not exit on SIGINT; its stderr and stacks:\n"
                        f"{stderr[:3000]}\n...\n{stderr[-4000:]}")
        assert child.returncode != 0 and "KeyboardInterrupt" in stderr, stderr[-2000:]
        assert wait_gone(pids, 5.0), [p for p in pids if not process_gone(p)]
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()


# ---------------------------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def breakout():
    env = make("Breakout", num_envs=3)
    env.reset()
    yield env
    env.close()


@pytest.mark.parametrize("actions", [
    np.zeros(2, np.int32), np.zeros(4, np.int32), np.zeros((3, 1), np.int32), 0, [[0, 1, 2]],
])
def test_wrong_action_shape(breakout, actions):
    with pytest.raises(ValueError, match=r"\(3,\).*\[0, 3\]"):
        breakout.step(actions)


@pytest.mark.parametrize("actions", [np.zeros(3, np.float32), [0.0, 1.0, 2.0],
                                     np.array([True, False, True]), [True, 0, 1],
                                     np.zeros(3, "timedelta64[s]")])
def test_non_integer_actions(breakout, actions):
    with pytest.raises(ValueError, match=r"integer.*\(3,\).*\[0, 3\]"):
        breakout.step(actions)


@pytest.mark.parametrize("actions,shown", [(None, "NoneType None"), ("abc", "str 'abc'"),
                                           ([1, None, 2], r"list \[1, None, 2\]")])
def test_actions_that_are_no_numbers_are_named(breakout, actions, shown):
    with pytest.raises(ValueError, match=r"array of shape \(3,\) of ints in \[0, 3\], got " + shown):
        breakout.step(actions)


def test_masked_actions_are_refused(breakout):
    """np.asarray drops a mask: the hidden values were stepped as if they were actions."""
    actions = np.ma.masked_array([0, 1, 2], mask=[False, True, False])
    with pytest.raises(ValueError, match=r"actions must be a plain array of shape \(3,\) of ints "
                                         r"in \[0, 3\], not a masked array"):
        breakout.step(actions)


@pytest.mark.parametrize("actions", [[0, 1, 4], [-1, 0, 0], np.array([0, 0, 255], np.uint8)])
def test_out_of_range_actions(breakout, actions):
    with pytest.raises(ValueError, match=r"range.*\(3,\).*\[0, 3\]"):
        breakout.step(actions)


def test_valid_actions_of_any_integer_kind_are_accepted(breakout):
    import jax.numpy as jnp

    for actions in ([0, 1, 3], np.array([3, 2, 1], np.uint8), jnp.array([1, 1, 1], jnp.int32)):
        obs, reward, terminated, truncated, info = breakout.step(actions)
        assert obs.shape == (3, 128) and reward.shape == (3,)
        np.testing.assert_array_equal(np.asarray(info["executed_action"])[:, 0],
                                      np.asarray(actions))


def test_stepping_inside_jit_points_to_xla(breakout):
    """A traced batch of actions (env.step inside jax.jit) is named as such, not as a batch of
    the wrong shape; the env goes on."""
    import jax
    import jax.numpy as jnp

    actions = jnp.zeros(breakout.num_envs, jnp.int32)
    for call in (breakout.step, breakout.send):
        with pytest.raises(ValueError, match=r"actions are traced: env\.step / env\.send cannot "
                                             r"run inside jax\.jit.*env\.xla\(\)"):
            jax.jit(lambda a: call(a)[1])(actions)
    assert breakout.step(np.asarray(actions))[1].shape == (breakout.num_envs,)


def test_a_rejected_action_leaves_the_env_usable(breakout):
    with pytest.raises(ValueError):
        breakout.step([0, 9, 0])
    obs, *_ = breakout.step([0, 0, 0])
    assert obs.shape == (3, 128)


@pytest.mark.parametrize("timeout, message", [
    (-1, r"timeout must be in \[0, 1000000\], got -1.0"),
    ("5", r"timeout must be a number in \[0, 1000000\], got '5'"),
    (float("inf"), r"timeout must be in \[0, 1000000\], got inf"),
    # the pipes are waited on in int32 milliseconds: a longer finite wait failed, sent, with
    # Python's own OverflowError
    (2.148e6, r"timeout must be in \[0, 1000000\], got 2148000.0"),
])
def test_a_bad_timeout_is_refused_before_waiting_or_sending(breakout, timeout, message):
    with pytest.raises(ValueError, match=message):
        breakout.reset(timeout=timeout)
    breakout.reset()
    with pytest.raises(ValueError, match=message):
        breakout.step(np.zeros(3, np.int32), timeout=timeout)
    breakout.send(np.zeros(3, np.int32))  # step() sent nothing
    with pytest.raises(ValueError, match=message):
        breakout.recv(timeout=timeout)
    breakout.recv(timeout=30)  # the step was left in flight, untouched


def test_step_before_reset_and_send_recv_misuse():
    env = make("Breakout")
    try:
        with pytest.raises(RuntimeError, match="reset"):
            env.step([0, 0])
        env.reset()
        with pytest.raises(RuntimeError, match="nothing in flight"):
            env.recv()
        env.send([0, 1])
        with pytest.raises(RuntimeError, match="already in flight"):
            env.send([0, 1])
        obs, *_ = env.recv()
        assert obs.shape == (2, 128)
    finally:
        env.close()


@pytest.mark.parametrize("kwargs,pattern", [
    (dict(game="NoSuchGame"), r"unknown game 'NoSuchGame'.*Breakout"),
    (dict(game="Breakout", preset="9.9"), r"unknown preset '9.9' for Breakout.*3\.2A"),
    (dict(game="Breakout", obs="rgb"), r"obs must be one of \['raw', 'atari84', 'dreamer64', "
                                       r"'ram', 'objects'\], got 'rgb'"),
    (dict(game="Breakout", num_envs=2, num_workers=3), r"num_workers must be <= num_envs \(2\)"),
    (dict(game="Breakout", num_workers=-1), r"num_workers must be >= 0, got -1"),
    (dict(game="Breakout", num_envs=3, num_workers=0, inline_envs=1),
     r"num_workers=0 emulates all num_envs \(3\) envs in this process: leave inline_envs None "
     r"or set it to 3, got 1"),
    (dict(game="Breakout", num_envs=2, num_workers=2, inline_envs=1),
     r"num_workers \(2\) \+ inline_envs \(1\) must be <= num_envs \(2\)"),
    (dict(game="Breakout", num_envs=2, inline_envs=-1),
     r"inline_envs must be in \[0, num_envs - 1 = 1\] with worker processes \(each needs an env; "
     r"num_workers=0 emulates all 2 here\), got -1"),
    (dict(game="Breakout", num_envs=2, inline_envs=2), r"inline_envs must be in \[0, num_envs - 1 = "
                                                       r"1\] .*, got 2"),
    (dict(game="Breakout", num_envs=2, inline_envs=1.0), r"inline_envs must be an int, got 1\.0"),
    (dict(game="Breakout", num_envs=1, num_workers=0, inline_envs=True),
     r"inline_envs must be an int, got True"),
    (dict(game=["Breakout"]), r"game must be a non-empty string, got \['Breakout'\]"),
    (dict(game="Breakout", num_envs=0), r"num_envs must be >= 1"),
    (dict(game="Breakout", granularity="episode"),
     r"granularity must be one of \['frame', 'step'\]"),
    (dict(game="Breakout", backend="threads"), r"backend must be one of \['subproc', 'envpool'\]"),
    (dict(game="Breakout", frame_skip=0), r"frame_skip must be >= 1"),
    (dict(game="Breakout", seed=-1), r"seed must be in \[0, 2147483647\], got -1"),
    (dict(game="Breakout", seed=1.5), r"seed must be an int"),
    (dict(game="Breakout", preset="1", config=Config()), r"either preset or config"),
    (dict(game="Breakout", config=Config(ram_observation=True), obs="raw"),
     r"type 0.*obs must be one of \['ram', 'objects'\], got 'raw'"),
    (dict(game="Breakout", config=Config(observation=ObservationMask("blackout", 1)), obs="ram"),
     r"obs='ram' cannot show an observation mask \(type 3\.2, Config\.observation\)"),
    (dict(game="Gopher", obs="ram", config=Config(drift=ConceptDrift(
        "sudden", 1, Config(observation=ObservationMask("blackout", 6))))),
     r"obs='ram' cannot show an observation mask \(type 3\.2, "
     r"Config\.drift\.secondary\.observation\)"),
    (dict(game="Breakout", config=Config(observation=ObservationMask("blackout", 12))),
     r"blackout modes: allowed \[1, 2, .*11\]"),
    (dict(game="Boxing", config=Config(game="Breakout")), r"bound to game 'Breakout'"),
    (dict(game="Gopher", config=Config(drift=ConceptDrift(
        "sudden", 5, Config(action_noise=stori_jax.ActionNoise(0.3), game="Boxing")))),
     r"secondary.*Boxing"),
    (dict(game="Breakout", seed=2**31), r"seed must be in \[0, 2147483647\], got 2147483648"),
    (dict(game="Breakout", autoreset="False"), r"autoreset must be True or False, got 'False'"),
    (dict(game="Breakout", backend="envpool", num_workers=2),
     r"num_workers applies to backend='subproc' only"),
    (dict(game="Breakout", backend="envpool", inline_envs=0),
     r"inline_envs applies to backend='subproc' only"),
    (dict(game="Breakout", frame_work="gpu"),
     r"frame_work must be one of \['workers', 'caller'\] or None .*, got 'gpu'"),
    (dict(game="Breakout", backend="envpool", frame_work="workers"),
     r"frame_work applies to backend='subproc' only"),
])
def test_bad_make_arguments(kwargs, pattern):
    kwargs = dict(kwargs)
    game = kwargs.pop("game")
    kwargs.setdefault("num_envs", 2)
    kwargs.setdefault("seed", 0)
    with pytest.raises(ValueError, match=pattern):
        stori_jax.make(game, **kwargs)


def test_an_interrupt_inside_inline_emulation_requires_a_reset():
    """Envs emulated in this process cannot resume half a frame loop: after a Ctrl-C there,
    the very next call already says reset() (it said "a step is in flight: call recv()"
    first), and reset() makes the env usable again."""
    import stori_jax

    env = stori_jax.make("Breakout", num_envs=3, seed=0, obs="ram", num_workers=1,
                         inline_envs=2)
    try:
        env.reset()
        emulator = env.backend._inline[1]
        real_step = emulator.step

        def interrupted():
            raise KeyboardInterrupt

        emulator.step = interrupted
        with pytest.raises(KeyboardInterrupt):
            env.step(np.zeros(3, np.int32))
        emulator.step = real_step
        with pytest.raises(RuntimeError, match=r"call reset\(\) first"):
            env.step(np.zeros(3, np.int32))
        with pytest.raises(RuntimeError, match=r"needs reset\(\)"):
            env.recv()
        env.reset()
        obs, *_ = env.step(np.zeros(3, np.int32))
        assert obs.shape == (3, 128)
    finally:
        env.close()


def test_workers_outlive_the_thread_that_made_the_env():
    """Workers watch their parent process, not the thread that started them: an env made in a
    short-lived thread (a thread pool, a data loader) keeps working after that thread ends."""
    made = {}
    thread = threading.Thread(target=lambda: made.update(env=make("Breakout", num_workers=1)))
    thread.start()
    thread.join()
    env = made["env"]
    try:
        time.sleep(0.5)
        assert not any(process_gone(pid) for pid in env.backend.pids)
        env.reset()
        obs, *_ = env.step([0, 1])
        assert obs.shape == (2, 128)
    finally:
        env.close()


def test_envs_started_in_two_threads_at_once_leave_main_as_it_was(monkeypatch):
    """Starting workers hides __main__'s __file__ and __spec__ and puts them back.  Two threads
    doing it at once: the second saved the first's hidden values and put those back last, so
    __spec__ stayed None for good (a user's own spawned processes then failed).  They take
    turns now: the second starts its workers once the first has put everything back."""
    from stori_jax.backends.subproc import _main_module_not_reimported

    main = sys.modules["__main__"]  # as a script run with python -m has them (xdist's lacks)
    monkeypatch.setattr(main, "__file__", "/somewhere/script.py", raising=False)
    monkeypatch.setattr(main, "__spec__", object(), raising=False)
    before = {k: getattr(main, k) for k in ("__file__", "__spec__")}
    first_inside, first_may_leave, first_left = (threading.Event() for _ in range(3))

    def first():
        with _main_module_not_reimported():
            first_inside.set()
            first_may_leave.wait(10)
        first_left.set()

    def second():
        with _main_module_not_reimported():
            first_left.wait(10)  # (without turns: inside both at once, and leaving last)

    threads = [threading.Thread(target=first), threading.Thread(target=second)]
    threads[0].start()
    first_inside.wait(10)
    threads[1].start()
    time.sleep(0.2)  # the second is in, or waiting for its turn
    first_may_leave.set()
    for thread in threads:
        thread.join(10)
    assert {k: getattr(main, k, "missing") for k in ("__file__", "__spec__")} == before


def test_a_ctrl_c_during_close_comes_once_every_worker_is_gone():
    """close() waits for a worker that does not answer (here: stopped), then terminates it.
    A Ctrl-C in that wait stopped the shutdown half way, for good (it runs once): the worker
    lived on.  Now the interrupt is raised once the workers are gone."""
    env = make("Breakout", num_workers=2)
    env.reset()
    pids = env.backend.pids
    os.kill(pids[1], signal.SIGSTOP)  # as a worker that is stuck
    timer = threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            env.close()
        assert env.closed
        assert all(process_gone(pid) for pid in pids)
    finally:
        timer.join()
        # where the test failed: a stopped worker hangs multiprocessing's exit (kill() signals
        # only a process not yet reaped, never a pid reused since)
        env.backend.processes[1].kill()


@contextlib.contextmanager
def interrupting(owner, method: str):
    """``owner.method`` raises KeyboardInterrupt (a Ctrl-C landing there) inside the block."""
    def interrupted(*args):
        raise KeyboardInterrupt

    real = getattr(owner, method)
    setattr(owner, method, interrupted)
    try:
        yield
    finally:
        setattr(owner, method, real)


def assert_points_to_reset(env):
    with pytest.raises(RuntimeError, match=r"call reset\(\) first"):
        env.step([0, 1])
    with pytest.raises(RuntimeError, match=r"needs reset\(\)"):
        env.recv()


def test_an_interrupt_after_the_emulators_finished_requires_a_reset():
    """Ctrl-C between the workers' reply and the env's own bookkeeping: the emulators are a step
    ahead of the env's state, so the env must refuse to step on (not silently diverge)."""
    env = make("Breakout")
    try:
        env.reset()
        with interrupting(env, "_finish"), pytest.raises(KeyboardInterrupt):
            env.step([0, 1])
        assert_points_to_reset(env)
        env.reset()
        obs, *_ = env.step([0, 1])
        assert obs.shape == (2, 128)
    finally:
        env.close()


@contextlib.contextmanager
def interrupted_at(function, statement: str):
    """A KeyboardInterrupt (a Ctrl-C landing there) just before ``function`` runs its line that
    reads ``statement``, once, inside the block."""
    import inspect

    lines, first = inspect.getsourcelines(function)
    at = [first + i for i, line in enumerate(lines) if line.split("#")[0].strip() == statement]
    assert len(at) == 1, f"{statement!r} is not one line of {function.__qualname__}"
    code, fired = function.__code__, []

    def in_function(frame, event, arg):
        if event == "line" and frame.f_lineno == at[0] and not fired:
            fired.append(True)
            raise KeyboardInterrupt
        return in_function

    sys.settrace(lambda frame, event, arg: in_function if frame.f_code is code else None)
    try:
        yield
    finally:
        sys.settrace(None)
    assert fired, "the line was never reached"


@pytest.mark.parametrize("call, statement", [
    ("step", "self._reset_pending = pending"),
    ("step", "self._in_flight = None"),
    ("reset", "self._restart_due = False"),
    ("reset", "self._phase = Phase.READY"),
])
@pytest.mark.parametrize("then", ["reset", "step", "restore"])
def test_an_interrupt_inside_the_envs_record_of_a_call_requires_a_reset(call, statement, then):
    """Ctrl-C between the statements that record a finished step or reset: a step whose
    record was half written stepped on with the previous step's resets due (an env whose
    episode had ended went on past its end); now the env needs reset() until its record is
    whole, and after it the run is a twin's reset at the same point."""
    function = stori_jax.Env.recv if call == "step" else stori_jax.Env.reset
    env, twin = (make("Breakout", autoreset=False, max_episode_frames=20) for _ in range(2))
    try:
        env.reset(), twin.reset()
        actions = np.random.default_rng(0).integers(0, 4, (12, 2))
        for a in actions[:4]:
            env.step(a), twin.step(a)
        with interrupted_at(function, statement), pytest.raises(KeyboardInterrupt):
            env.step(actions[4]) if call == "step" else env.reset()
        # reset() or restore() straight away recover too (they called the backend's recv for
        # a step it had handed over: refused, every time)
        if then == "restore":
            env.restore(twin.snapshot())
        else:
            if then == "step":
                assert_points_to_reset(env)
            env.reset(), twin.reset()
        for a in actions[5:]:  # episodes of 5 steps: ends and resets within these
            for x, y in zip(env.step(a)[:4], twin.step(a)[:4]):
                np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    finally:
        env.close()
        twin.close()


def test_an_interrupted_reset_says_reset_again():
    """Ctrl-C while the workers reset: step, recv and snapshot all point to reset(), and a
    second reset() gives the same first observation as an uninterrupted one."""
    env, twin = make("Breakout"), make("Breakout")
    try:
        with interrupting(env.backend, "recv"), pytest.raises(KeyboardInterrupt):
            env.reset()
        assert env.backend.pending
        assert_points_to_reset(env)
        with pytest.raises(RuntimeError, match=r"reset\(\) it"):
            env.snapshot()
        obs, _ = env.reset()
        twin_obs, _ = twin.reset()
        np.testing.assert_array_equal(np.asarray(obs), np.asarray(twin_obs))
    finally:
        env.close()
        twin.close()


def test_an_env_cannot_be_copied_or_pickled_and_says_what_can():
    """A copy shared the workers, and dropping it closed the original's."""
    import copy
    import pickle

    with make("Breakout") as env:
        for clone in (copy.copy, copy.deepcopy, pickle.dumps):
            with pytest.raises(TypeError, match=r"cannot be copied or pickled: env.snapshot\(\)"):
                clone(env)
        env.reset()
        assert env.step([0, 1])[0].shape == (2, 128)


def test_an_absurd_batch_is_refused_before_anything_is_allocated():
    """num_envs=10**9 sat in make() for minutes, then failed deep inside multiprocessing."""
    started = time.monotonic()
    with pytest.raises(ValueError, match=r"num_envs=1000000000 with frame_skip=4 needs .* GiB "
                                         r"of shared buffers .* choose a smaller num_envs"):
        make("Breakout", num_envs=10**9)
    assert time.monotonic() - started < 30
    with pytest.raises(ValueError, match=r"num_envs=1000000000 with frame_skip=4 needs .* GiB "
                                         r"of envpool's frame buffers .* choose a smaller"):
        make("Breakout", num_envs=10**9, backend="envpool", autoreset=False, granularity="step")


def test_a_ram_observation_shares_no_screen_buffers():
    """obs='ram' allocated two screens per env it never reads (200 KB an env: 0.8 GB of shared
    memory at B = 4096); now its frame buffer is empty, and the memory check counts so."""
    with make("Breakout", num_envs=3) as ram, make("Breakout", num_envs=3, obs="raw") as raw:
        assert len(ram.backend.buffers.raw["frames"][0]) == 0
        assert len(raw.backend.buffers.raw["frames"][0]) == 2 * 3 * 210 * 160 * 3
        for env in (ram, raw):
            env.reset()
        np.testing.assert_array_equal(np.asarray(ram.step([1, 2, 3])[4]["ram"]),
                                      np.asarray(raw.step([1, 2, 3])[4]["ram"]))
    from stori_jax.backends.layout import shared_bytes

    assert shared_bytes(1, 4, screens=False) < 1024 < 2 * 210 * 160 * 3 < shared_bytes(1, 4)


@pytest.mark.timeout(60)
def test_close_from_another_thread_is_reported_as_closed_not_as_a_dead_worker():
    env = make("Breakout", num_workers=1)
    try:
        env.reset()
        os.kill(env.backend.pids[0], signal.SIGSTOP)  # busy as long as it takes; close kills it
        env.send([0, 1])
        threading.Timer(0.3, env.close).start()
        with pytest.raises(stori_jax.EnvClosedError, match="closed during a step .*another "
                                                           "thread"):
            env.recv()
        assert env.closed
    finally:
        env.close()


FORKED_CHILD = """
import os, sys, warnings
import numpy as np, stori_jax
warnings.simplefilter("ignore")  # JAX's warning about the fork
env = stori_jax.make("Breakout", num_envs=2, seed=0, obs="ram", num_workers=1)
env.reset()
pid = os.fork()
if pid == 0:  # the child: the env is the parent's; using it is refused, dropping it is harmless
    import signal
    # a hang (the refusal regressed, or JAX's exit in a forked child, which may hang after
    # Python's exit handlers ran) ends in 5 s
    signal.alarm(5)
    try:
        env.step(np.zeros(2, np.int32))
        print("child stepped the parent's env", flush=True)
    except RuntimeError as error:
        print("child:", error, flush=True)
    env.close()
    del env
    os._exit(0) if sys.argv[1] == "os._exit" else sys.exit(0)
os.waitpid(pid, 0)
obs, reward, *_ = env.step(np.ones(2, np.int32))
print("parent stepped", obs.shape, flush=True)
env.close()
"""


@pytest.mark.parametrize("ending", ["sys.exit", "os._exit"])
def test_a_forked_child_leaves_the_parents_workers_alone(tmp_path, ending):
    """A child forked after make(): its copy of the env refuses to step (the workers answer
    the parent), and closing or dropping it, or exiting, does not stop the parent's workers.
    (Before, the child's close or exit handlers sent them 'close' and terminated them: the
    parent's next step read a stale buffer, then found its worker dead.)"""
    script = tmp_path / "forked.py"
    script.write_text(FORKED_CHILD)
    out = subprocess.run([sys.executable, str(script), ending], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert "child: this env was made in process" in out.stdout, out.stdout + out.stderr
    assert "parent stepped (2, 128)" in out.stdout, out.stdout + out.stderr
    assert "can only join a child process" not in out.stderr, out.stderr


def test_no_workers_emulates_every_env_in_this_process():
    """num_workers=0 starts no process; the batch still steps, resets and snapshots."""
    with make("Breakout", num_envs=3, num_workers=0) as env:
        assert env.backend.pids == []
        env.reset()
        state = env.snapshot()
        first = env.step(np.ones(3, np.int32))[0]
        env.restore(state)
        np.testing.assert_array_equal(np.asarray(env.step(np.ones(3, np.int32))[0]),
                                      np.asarray(first))


def test_inline_envs_alone_leaves_the_workers_the_rest(monkeypatch):
    """Only inline_envs given, on a machine with many cores: the default worker count shrinks to
    the envs left to the workers, instead of an error about a num_workers nobody passed."""
    monkeypatch.setattr("stori_jax.builder.available_cores", lambda: 16)
    with make("Breakout", num_envs=4, num_workers=None, inline_envs=2) as env:
        assert len(env.backend.pids) == 2
        env.reset()
        obs, *_ = env.step(np.zeros(4, np.int32))
        assert obs.shape == (4, 128)


def test_a_config_bound_to_another_spelling_of_the_game_fits():
    with make("Pong", Config(game="pong", action_noise=stori_jax.ActionNoise(0.25))) as env:
        assert env.plan.game == "Pong"
        env.reset()
        assert env.step(np.zeros(2, np.int32))[0].shape == (2, 128)


@pytest.mark.timeout(30)
def test_a_dead_workers_error_names_its_index_envs_pid_and_exit_code():
    """3 envs on 2 workers: worker 1 holds env 2 alone.  Killed, it is named with its envs,
    its pid and how it ended, so that a user can tell an OOM kill (-9) from a crash."""
    env = make("Breakout", num_envs=3, num_workers=2, inline_envs=0)
    env.reset()
    pid = env.backend.pids[1]
    os.kill(pid, signal.SIGKILL)
    env.backend.processes[1].join(5)
    with pytest.raises(stori_jax.WorkerError, match=rf"emulator worker 1 \(envs 2\.\.2, pid "
                                                    rf"{pid}\) died .*with exit code -9; the "
                                                    r"environment is closed"):
        env.step(np.zeros(3, np.int32))
    assert env.closed


def test_a_batch_split_unevenly_between_workers_plays_the_one_worker_run():
    """3 envs on 2 workers (2 + 1): every env is emulated, with its own seed, as without
    workers."""
    actions = np.random.default_rng(1).integers(0, 4, (6, 3), dtype=np.int32)
    with make("Breakout", preset="1", num_envs=3, num_workers=2, inline_envs=0) as split, \
            make("Breakout", preset="1", num_envs=3) as whole:
        got, expected = run_env(split, actions), run_env(whole, actions)
        # the seeds themselves (ALE's random state, which play alone need not show)
        assert emulator_states(split) == emulator_states(whole)
    np.testing.assert_array_equal(got.ram, expected.ram)
    np.testing.assert_array_equal(got.stacked("reward"), expected.stacked("reward"))
    assert len({bytes(r) for r in got.ram[-1]}) == 3  # three emulators of their own


def test_a_second_send_is_refused_and_leaves_the_step_in_flight_untouched():
    """send() while a step is in flight is refused before it writes anything: the step in
    flight (its inline env emulated only in recv(), its worker stopped meanwhile) finishes with
    its own actions, as an uninterrupted twin's; the backend refuses a second command too."""
    env, twin = make("Breakout", num_envs=2, num_workers=1, inline_envs=1), make("Breakout")
    try:
        env.reset()
        twin.reset()
        actions = np.array([1, 3], np.int32)
        with stopped(env.backend.pids[0]):
            env.send(actions)
            with pytest.raises(RuntimeError, match="already in flight"):
                env.send(np.array([2, 2], np.int32))
            with pytest.raises(RuntimeError, match=r"already in flight \(send\(\) started it\): "
                               r"call recv\(\) to finish it before step\(\)"):
                env.step(np.array([2, 2], np.int32))
            with pytest.raises(RuntimeError, match="already in flight"):
                env.backend.send_step()
        assert_same_steps(env, twin, env.recv(timeout=30), actions)
    finally:
        env.close()
        twin.close()


def test_workers_ignore_a_ctrl_c_sent_to_the_whole_process_group():
    """A terminal's Ctrl-C reaches every process of its foreground group: the workers leave it
    to the parent (which decides whether the step stays in flight) and keep emulating."""
    with ctrl_c_armed():  # workers that would inherit SIGINT ignored from the runner do not
        env = make("Breakout", num_workers=2, inline_envs=0)
    twin = make("Breakout")
    try:
        env.reset()
        twin.reset()
        for pid in env.backend.pids:
            os.kill(pid, signal.SIGINT)
        time.sleep(0.3)  # delivered before the next command
        assert not any(process_gone(pid) for pid in env.backend.pids)
        assert_same_steps(env, twin, env.step([1, 2]), np.array([1, 2], np.int32))
    finally:
        env.close()
        twin.close()


def test_close_asks_the_workers_to_stop_before_terminating_them():
    """close() sends every worker its stop command and they exit by themselves (exit code 0),
    instead of being terminated (SIGTERM) after a second's grace each."""
    env = make("Breakout", num_envs=3, num_workers=3)
    env.reset()
    env.step(np.zeros(3, np.int32))
    processes = list(env.backend.processes)
    env.close()
    assert [p.exitcode for p in processes] == [0, 0, 0]


UNGUARDED = """
import numpy as np, stori_jax
print("script ran", flush=True)
env = stori_jax.make("Breakout", num_envs=2, seed=0, obs="ram", num_workers=1)
env.reset()
print("stepped", env.step(np.zeros(2, np.int32))[0].shape, flush=True)
env.close()
"""


def test_a_script_without_a_main_guard_is_not_run_again_in_the_workers(tmp_path):
    """The workers are spawned: they would import the user's script as their __main__ and run
    it again (make() inside a starting worker then fails).  They import none of it."""
    script = tmp_path / "unguarded.py"
    script.write_text(UNGUARDED)
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.splitlines() == ["script ran", "stepped (2, 128)"], out.stdout


def test_a_restore_leaves_no_state_files_behind(tmp_path, monkeypatch):
    """The states reach the workers through files: they are removed once the workers read them."""
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    with make("Breakout", num_envs=3, num_workers=2, inline_envs=0) as env:
        env.reset()
        snapshot = env.snapshot()
        env.step(np.ones(3, np.int32))
        env.restore(snapshot)
        assert list(tmp_path.iterdir()) == []
        env.step(np.ones(3, np.int32))


def test_ctrl_c_after_the_first_worker_got_a_snapshot_command_points_to_reset():
    """Ctrl-C between sending the snapshot command to one worker and the next: the env knows
    the workers owe replies, so every call points to reset(), which collects them; the env then
    goes on as an uninterrupted twin.  (Otherwise the next step would take the snapshot's
    reply for its own, and read buffers the worker is still writing.)"""
    env, twin = make("Breakout", num_workers=2, inline_envs=0), make("Breakout")
    try:
        env.reset()
        twin.reset()
        signal_after(env.backend.conns[0], "send_bytes")
        with ctrl_c_armed(), pytest.raises(KeyboardInterrupt):
            env.snapshot()
        assert env.backend.pending
        with pytest.raises(RuntimeError, match=r"reset\(\)"):
            env.step([0, 1])
        np.testing.assert_array_equal(np.asarray(env.reset()[0]), np.asarray(twin.reset()[0]))
        assert_same_steps(env, twin, env.step([1, 1]), np.array([1, 1], np.int32))
    finally:
        env.close()
        twin.close()


KILLED_PARENT = """
import os, signal, time, warnings
import numpy as np, stori_jax
warnings.simplefilter("ignore")  # JAX's warning about the fork
env = stori_jax.make("Breakout", num_envs=2, seed=0, obs="ram", num_workers=2, inline_envs=0)
env.reset()
env.step(np.zeros(2, np.int32))
child = os.fork()
if child == 0:  # holds copies of the parent's pipe ends: the workers see no end of file
    devnull = os.open(os.devnull, os.O_RDWR)
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)
    time.sleep(60)
    os._exit(0)
print(child, *env.backend.pids, flush=True)
os.kill(os.getpid(), signal.SIGKILL)  # no close(), no exit handlers
"""


@pytest.mark.timeout(60)
def test_workers_stop_when_their_parent_is_killed(tmp_path):
    """Killed outright (SIGKILL, the OOM killer), the parent closes nothing; a process it forked
    still holds its pipe ends, so the workers see no end of file.  They exit anyway: they watch
    their parent."""
    script = tmp_path / "killed.py"
    script.write_text(KILLED_PARENT)
    with open(tmp_path / "stderr.txt", "w") as stderr:
        parent = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE,
                                  stderr=stderr, text=True)
    pids = [int(p) for p in parent.stdout.readline().split()]
    try:
        assert parent.wait(timeout=30) == -signal.SIGKILL and len(pids) == 3, \
            (tmp_path / "stderr.txt").read_text()[-2000:]
        workers = pids[1:]
        assert wait_gone(workers, 5.0), [p for p in workers if not process_gone(p)]
    finally:
        parent.stdout.close()
        for pid in pids:  # the forked child, and workers that outlived their parent
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


def test_close_removes_the_state_files_of_an_interrupted_restore(tmp_path, monkeypatch):
    """A restore stopped by Ctrl-C leaves its state files for the workers still to read them;
    close() removes them (nothing else will)."""
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    env = make("Breakout", num_workers=1)
    try:
        env.reset()
        snapshot = env.snapshot()
        signal_after(env.backend, "_send_each")  # the workers have the files' names
        with ctrl_c_armed(), pytest.raises(KeyboardInterrupt):
            env.restore(snapshot)
        assert list(tmp_path.glob("stori-jax-restore-*"))
    finally:
        env.close()
    assert list(tmp_path.glob("stori-jax-restore-*")) == []


@pytest.mark.timeout(30)
def test_a_worker_that_fails_a_restore_closes_the_env():
    """A damaged emulator state passes the env's own checks (it is bytes, as ALE's are) and
    fails in its worker: the restore raises WorkerError naming that worker, and the
    env is closed, every worker stopped, as after a worker's death."""
    env = make("Breakout", num_workers=2, inline_envs=0)
    pids = list(env.backend.pids)
    try:
        env.reset()
        snapshot = env.snapshot()
        snapshot["emulators"] = [dict(e) for e in snapshot["emulators"]]
        snapshot["emulators"][0]["ale"] = b"not an ALE state"
        with pytest.raises(stori_jax.WorkerError, match=r"emulator worker 0 \(envs 0\.\.0\) "
                                                        r"failed during a restore"):
            env.restore(snapshot)
        assert env.closed
        assert wait_gone(pids, 3.0)
        with pytest.raises(stori_jax.EnvClosedError):
            env.step(np.zeros(2, np.int32))
    finally:
        env.close()


def test_an_interrupted_start_leaves_no_worker(monkeypatch):
    """Ctrl-C while make() waits for its workers to start: the workers are stopped there, even
    while the interrupt (whose traceback holds the half-made backend) is kept."""
    from stori_jax.backends import subproc

    real_wait = subproc.wait

    def interrupted_wait(*args, **kwargs):  # the first wait: the one for the start
        monkeypatch.setattr(subproc, "wait", real_wait)
        raise KeyboardInterrupt

    monkeypatch.setattr(subproc, "wait", interrupted_wait)
    with pytest.raises(KeyboardInterrupt) as caught:
        make("Breakout", num_workers=2, inline_envs=0)
    tb, backend = caught.value.__traceback__, None
    while tb is not None:  # the backend being made, from the frames of its __init__
        if isinstance(tb.tb_frame.f_locals.get("self"), subproc.SubprocBackend):
            backend = tb.tb_frame.f_locals["self"]
        tb = tb.tb_next
    assert backend is not None and len(backend.pids) == 2
    try:
        assert backend.closed
        assert wait_gone(backend.pids, 3.0)
    finally:
        backend.close()


def test_a_reset_straight_after_an_interrupt_inside_inline_emulation():
    """The env of test_an_interrupt_inside_inline_emulation_requires_a_reset: reset() waits
    for the workers' half of the broken step itself, and a refused recv() before it changes
    nothing (both give the same reset and steps)."""
    import jax

    kw = dict(num_envs=3, num_workers=1, inline_envs=2)
    env, twin = make("Breakout", **kw), make("Breakout", **kw)
    try:
        for e in (env, twin):
            e.reset()
            with interrupting(e.backend._inline[1], "step"), pytest.raises(KeyboardInterrupt):
                e.step(np.zeros(3, np.int32))
        with pytest.raises(RuntimeError, match=r"needs reset\(\)"):
            twin.recv()
        got, expected = env.reset(), twin.reset()  # (obs, info): every array alike
        for x, y in zip(jax.tree.leaves(got), jax.tree.leaves(expected), strict=True):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
        for t in range(3):
            actions = np.array([t % 4, 1, 3], np.int32)
            np.testing.assert_array_equal(np.asarray(env.step(actions)[4]["ram"]),
                                          np.asarray(twin.step(actions)[4]["ram"]))
    finally:
        env.close()
        twin.close()


def test_the_context_manager_closes_on_an_error_and_lets_it_through():
    with pytest.raises(ValueError, match="inside the block"):
        with make("Breakout", num_workers=0) as env:
            env.reset()
            raise ValueError("inside the block")
    assert env.closed


@pytest.mark.parametrize("second", ["step", "reset", "snapshot", "xla"])
def test_a_call_from_a_second_thread_during_a_call_is_refused_and_changes_nothing(second):
    """Two threads stepping one env interleaved their steps: a trajectory silently differed
    from the single-threaded run's.  A call while another thread's call runs is refused with
    ConcurrentUseError, and the running call's results are the single-threaded run's."""
    env, twin = make("Breakout", num_workers=1, inline_envs=0), make("Breakout")
    try:
        env.reset(), twin.reset()
        waiting, release, outcome = threading.Event(), threading.Event(), {}
        real_recv = env.backend.recv

        def held_recv(*args, **kwargs):
            waiting.set()
            release.wait(10)
            return real_recv(*args, **kwargs)

        env.backend.recv = held_recv
        first = threading.Thread(target=lambda: outcome.update(step=env.step([1, 2])))
        first.start()
        assert waiting.wait(10)
        calls = {"step": lambda: env.step([0, 0]), "reset": env.reset,
                 "snapshot": env.snapshot, "xla": env.xla}
        with pytest.raises(stori_jax.ConcurrentUseError, match=rf"{second}\(\) was called "
                           r"while another thread's call of this env \(step\(\)\) runs"):
            calls[second]()
        release.set()
        first.join(10)
        env.backend.recv = real_recv
        for x, y in zip(outcome["step"][:4], twin.step([1, 2])[:4]):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
        for a in ([3, 1], [0, 2]):  # and the env goes on as the twin
            np.testing.assert_array_equal(np.asarray(env.step(a)[4]["ram"]),
                                          np.asarray(twin.step(a)[4]["ram"]))
    finally:
        env.close()
        twin.close()
