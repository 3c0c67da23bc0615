"""A clear error, not a deadlock, for JAX in a process forked from one that had started JAX.

JAX runs its compiler and its computations on threads; ``os.fork()`` copies none of them, so
the child's first compilation waits forever (JAX itself only warns, in the parent).  Python's
default start method on Linux is fork: gymnasium's ``make_vec(..., vectorization_mode="async")``
and a ``multiprocessing.Pool`` fork a process that has already made an env, and an env made in
such a child hung at its first step.  This module notes such a fork, without importing JAX, and
:func:`refuse_if_forked_after_jax` turns it into an error that names what works.
"""

from __future__ import annotations

import os
import sys

_forked_after_jax = False


def _jax_started() -> bool:
    if "jax" not in sys.modules:
        return False
    try:
        from jax._src import xla_bridge
    except ImportError:  # another JAX layout: assume nothing (the old behaviour)
        return False
    started = getattr(xla_bridge, "backends_are_initialized", None)
    return bool(started()) if started is not None else False


def _after_fork_in_child() -> None:
    global _forked_after_jax
    _forked_after_jax = _forked_after_jax or _jax_started()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)


def forked_after_jax() -> bool:
    """This process was forked (at any depth) from one whose JAX had started."""
    return _forked_after_jax


def refuse_if_forked_after_jax(what: str) -> None:
    if _forked_after_jax:
        raise RuntimeError(
            f"{what} cannot run in a process forked from one that had started JAX: JAX's "
            "threads do not survive os.fork(), and its first compilation here would wait "
            "forever. Start the process with the 'spawn' method instead: "
            "multiprocessing.get_context('spawn'), or gymnasium.make_vec(..., "
            "vectorization_mode='async', vector_kwargs={'context': 'spawn'})")
