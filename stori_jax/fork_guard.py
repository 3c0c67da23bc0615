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
_jax_started_at_fork = False


def _jax_started() -> bool:
    """JAX has made its backends (its threads run).  Read without JAX's lock and without an
    import: this runs at a fork, where another thread may hold either."""
    bridge = sys.modules.get("jax._src.xla_bridge")
    return bool(getattr(bridge, "_backends", None))


def _before_fork() -> None:  # in the parent, before it forks
    global _jax_started_at_fork
    _jax_started_at_fork = _jax_started()


def _after_fork_in_child() -> None:  # in the child: takes no lock, imports nothing
    global _forked_after_jax
    _forked_after_jax = _forked_after_jax or _jax_started_at_fork


if hasattr(os, "register_at_fork"):
    os.register_at_fork(before=_before_fork, after_in_child=_after_fork_in_child)


def refuse_if_forked_after_jax(what: str) -> None:
    if _forked_after_jax:
        raise RuntimeError(
            f"{what} cannot run in a process forked from one that had started JAX: JAX's "
            "threads do not survive os.fork(), and its first compilation here would wait "
            "forever. Start the process with the 'spawn' method instead: "
            "multiprocessing.get_context('spawn'), or gymnasium.make_vec(..., "
            "vectorization_mode='async', vector_kwargs={'context': 'spawn'})")
