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
