"""Ctrl-C held back over the env's bookkeeping (stori_jax/backends/interrupts.py): a SIGINT
inside the block is handled once, as the handler in place would have, when the block ends."""

from __future__ import annotations

import signal
import threading

import pytest

from stori_jax.backends.interrupts import interrupts_deferred


@pytest.fixture
def sigint_handler():
    """Set a SIGINT handler for the test; the runner's own is put back after it."""
    previous = signal.getsignal(signal.SIGINT)
    yield lambda handler: signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGINT, previous)


def test_a_ctrl_c_inside_the_block_is_raised_when_it_ends(sigint_handler):
    sigint_handler(signal.default_int_handler)
    done = []
    with pytest.raises(KeyboardInterrupt):
        with interrupts_deferred():
            signal.raise_signal(signal.SIGINT)
            done.append("after the signal")  # the block runs to its end
            signal.raise_signal(signal.SIGINT)  # several presses: one interrupt
    assert done == ["after the signal"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_nested_blocks_raise_once_at_the_outer_end(sigint_handler):
    sigint_handler(signal.default_int_handler)
    reached = []
    with pytest.raises(KeyboardInterrupt):
        with interrupts_deferred():
            with interrupts_deferred():
                signal.raise_signal(signal.SIGINT)
            reached.append("between the two ends")
    assert reached == ["between the two ends"]


def test_a_users_handler_is_called_once_and_put_back(sigint_handler):
    calls = []

    def handler(signum, frame):
        calls.append(signum)

    sigint_handler(handler)
    with interrupts_deferred():
        signal.raise_signal(signal.SIGINT)
        signal.raise_signal(signal.SIGINT)  # pressed twice: still one call
        assert calls == []
    assert calls == [signal.SIGINT]
    assert signal.getsignal(signal.SIGINT) is handler


def test_an_ignored_sigint_stays_ignored(sigint_handler):
    sigint_handler(signal.SIG_IGN)
    with interrupts_deferred():
        signal.raise_signal(signal.SIGINT)
    assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN


def test_an_error_inside_the_block_is_kept_under_the_interrupt(sigint_handler):
    sigint_handler(signal.default_int_handler)
    with pytest.raises(KeyboardInterrupt) as caught:
        with interrupts_deferred():
            signal.raise_signal(signal.SIGINT)
            raise RuntimeError("a worker died")
    assert isinstance(caught.value.__context__, RuntimeError)


def test_outside_the_main_thread_the_block_changes_no_handler(sigint_handler):
    sigint_handler(signal.default_int_handler)
    seen = []

    def in_a_thread():
        with interrupts_deferred():
            seen.append(signal.getsignal(signal.SIGINT))

    thread = threading.Thread(target=in_a_thread)
    thread.start()
    thread.join()
    assert seen == [signal.default_int_handler]


def test_under_the_default_action_a_ctrl_c_still_stops_the_process_when_the_block_ends():
    """SIG_DFL (a process that reset Ctrl-C to its default, killing, action): the interrupt is
    held until the block ends, then delivered, not dropped."""
    import subprocess
    import sys

    code = ("import signal\n"
            "from stori_jax.backends.interrupts import interrupts_deferred\n"
            "signal.signal(signal.SIGINT, signal.SIG_DFL)\n"
            "with interrupts_deferred():\n"
            "    signal.raise_signal(signal.SIGINT)\n"
            "    print('block ran to its end', flush=True)\n"
            "print('the interrupt was lost', flush=True)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60)
    assert out.stdout == "block ran to its end\n", out.stdout + out.stderr
    assert out.returncode == -signal.SIGINT


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_a_ctrl_c_python_dropped_in_a_gc_callback_stops_the_next_env_call():
    """A Ctrl-C whose handler ran inside a garbage-collection callback (JAX has one) cannot
    propagate there: Python prints "Exception ignored" and goes on.  The env raises it at its
    next call, before starting anything, and goes on after it as an uninterrupted twin."""
    import gc

    import numpy as np

    import stori_jax

    env, twin = (stori_jax.make("Breakout", num_envs=2, seed=0, obs="ram", num_workers=1)
                 for _ in range(2))
    fired = []

    def ctrl_c_in_a_gc_callback(phase, info):
        if not fired:
            fired.append(phase)
            raise KeyboardInterrupt

    try:
        env.reset()
        twin.reset()
        gc.callbacks.append(ctrl_c_in_a_gc_callback)
        try:
            gc.collect()  # Python drops the interrupt, as it drops one landing there
        finally:
            gc.callbacks.remove(ctrl_c_in_a_gc_callback)
        assert fired == ["start"]
        with pytest.raises(KeyboardInterrupt, match="garbage-collection callback"):
            env.step(np.ones(2, np.int32))
        actions = np.array([1, 3], np.int32)
        for _ in range(3):
            for got, expected in zip(env.step(actions)[:4], twin.step(actions)[:4]):
                np.testing.assert_array_equal(np.asarray(got), np.asarray(expected))
    finally:
        env.close()
        twin.close()


@pytest.fixture
def unraisable_seen(monkeypatch):
    """A sys.unraisablehook in place before an env installs its own on top, which records the
    (type, message) of each exception handed to it: not the exception, whose traceback would
    keep the test's envs alive.  The module's hook record and its dropped Ctrl-Cs are the
    test's own (a Ctrl-C left noted by a failed test would stop the whole session)."""
    import sys

    from stori_jax.backends import interrupts

    seen = []
    monkeypatch.setattr(interrupts, "_forward_to", list(interrupts._forward_to))
    monkeypatch.setattr(interrupts, "_lost", [])
    monkeypatch.setattr(sys, "unraisablehook",
                        lambda u: seen.append((type(u.exc_value), str(u.exc_value))))
    return seen


def _the_tests_own(seen):
    """The exceptions this file's tests dropped (another, from an earlier test's garbage, may
    be handed to the hook too)."""
    return [kind for kind, message in seen if message.startswith(DROPPED)]


DROPPED = "dropped by the test"


class _RaisesWhenDropped:
    """Raises ``error`` in its ``__del__``, where Python cannot propagate it: an "Exception
    ignored" handed to sys.unraisablehook (as a Ctrl-C landing there is)."""

    def __init__(self, error):
        self.error = error

    def __del__(self):
        raise self.error


def test_the_hook_in_place_before_the_env_still_sees_every_unraisable_exception(
        unraisable_seen):
    """The env notes a Ctrl-C Python dropped, and still hands every "Exception ignored" (the
    Ctrl-C too) to the hook that was in place before it: a user's, or pytest's."""
    import numpy as np

    import stori_jax

    with stori_jax.make("Breakout", num_envs=1, seed=0, obs="ram", num_workers=0) as env:
        env.reset()
        _RaisesWhenDropped(KeyboardInterrupt(DROPPED))
        _RaisesWhenDropped(ValueError(f"{DROPPED}: a __del__ that fails"))
        with pytest.raises(KeyboardInterrupt, match="garbage-collection callback or a __del__"):
            env.step(np.zeros(1, np.int32))
        assert env.step(np.zeros(1, np.int32))[0].shape == (1, 128)  # raised once
        assert _the_tests_own(unraisable_seen) == [KeyboardInterrupt, ValueError]


def test_an_ordinary_error_python_dropped_is_no_ctrl_c(unraisable_seen):
    """A __del__ or a garbage-collection callback that fails with any other exception during a
    step is only printed: the env's next step runs, as an undisturbed twin's."""
    import gc

    import numpy as np

    import stori_jax

    env, twin = (stori_jax.make("Breakout", num_envs=2, seed=0, obs="ram", num_workers=0)
                 for _ in range(2))

    def failing_gc_callback(phase, info):
        raise ValueError(f"{DROPPED}: a garbage-collection callback that fails")

    try:
        env.reset()
        twin.reset()
        actions = np.array([1, 3], np.int32)
        emulator, real_step = env.backend._inline[0], env.backend._inline[0].step

        def step_with_a_failing_cleanup():  # inside the step, where a collection may run
            _RaisesWhenDropped(ValueError(f"{DROPPED}: a __del__ that fails"))
            gc.callbacks.append(failing_gc_callback)
            try:
                gc.collect()
            finally:
                gc.callbacks.remove(failing_gc_callback)
            real_step()

        emulator.step = step_with_a_failing_cleanup
        first = env.step(actions)
        emulator.step = real_step
        assert _the_tests_own(unraisable_seen) == [ValueError] * 3
        try:
            expected = twin.step(actions)
            for got, want in zip(first[:4], expected[:4]):
                np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
            for _ in range(2):
                for got, want in zip(env.step(actions)[:4], twin.step(actions)[:4]):
                    np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
        except KeyboardInterrupt:  # a test failure, not the whole session stopped
            pytest.fail("an ordinary error Python dropped was raised as a Ctrl-C")
    finally:
        env.close()
        twin.close()
