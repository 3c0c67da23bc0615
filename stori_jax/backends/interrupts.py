"""Ctrl-C held back over a few lines of bookkeeping.

Python runs a SIGINT handler between any two bytecodes, so a ``KeyboardInterrupt`` can land
between sending a command to one worker and the next, or between reading a worker's reply and
recording it.  The env then no longer knows which workers owe a reply, and its next step reads
buffers that are still being written.  Inside :func:`interrupts_deferred` a Ctrl-C is noted and
raised when the block ends, where the records agree with the workers again.  Only short blocks
use it: a wait for the workers' replies stays interruptible, and leaves the command in flight
for the next ``recv()``.  The exceptions are bounded: envpool's calls (its waits are C++, which a
Ctrl-C does not interrupt anyway) and ``close()``'s shutdown of the workers (a few seconds at
most), which runs once and must not stop half way.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading


_deferring: list = []  # non-empty while the main thread is inside a block
_lost: list = []  # Ctrl-Cs Python had to drop, not yet raised
_forward_to = [sys.__unraisablehook__]  # the hook in place before note_lost_interrupts'


def _note_lost_interrupt(unraisable) -> None:
    if isinstance(unraisable.exc_value, KeyboardInterrupt):
        _lost.append(True)
    _forward_to[0](unraisable)


def note_lost_interrupts() -> None:
    """Keep the Ctrl-Cs Python drops.  A SIGINT handler runs between any two bytecodes, also
    inside a garbage-collection callback (JAX registers one) or a ``__del__``, where an exception
    cannot propagate: Python prints "Exception ignored" and the program goes on as if Ctrl-C had
    never been pressed.  From this call on such a KeyboardInterrupt is noted (and still
    printed), and :func:`raise_lost_interrupt` raises it.  Idempotent; a hook installed later
    replaces this one."""
    if sys.unraisablehook is not _note_lost_interrupt:
        _forward_to[0] = sys.unraisablehook
        sys.unraisablehook = _note_lost_interrupt


def raise_lost_interrupt() -> None:
    """Raise the KeyboardInterrupt that Python dropped since the last call, if any."""
    if _lost:
        _lost.clear()
        raise KeyboardInterrupt("Ctrl-C (Python could not raise it where it landed: in a "
                                "garbage-collection callback or a __del__)")


@contextlib.contextmanager
def interrupts_deferred():
    """Run the block with SIGINT noted instead of handled; handle it (as the handler in place
    before would have) when the block ends.  Outside the main thread, where Python never
    delivers a signal, the block runs as it is."""
    if _deferring or threading.current_thread() is not threading.main_thread():
        yield  # inside an outer block, which handles it; or no signal can arrive here
        return
    previous = signal.getsignal(signal.SIGINT)
    if previous is None:  # a handler installed outside Python: it cannot be put back
        yield
        return
    noted = []
    signal.signal(signal.SIGINT, lambda signum, frame: noted.append(frame))
    _deferring.append(True)
    try:
        yield
    finally:
        _deferring.pop()
        signal.signal(signal.SIGINT, previous)
        if noted:
            if callable(previous):  # default_int_handler raises KeyboardInterrupt here
                previous(signal.SIGINT, noted[0])
            elif previous == signal.SIG_DFL:
                signal.raise_signal(signal.SIGINT)
