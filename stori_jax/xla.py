"""Stepping inside ``jax.jit``: ``handle, step = env.xla()``, as envpool's xla handle.

``step(handle, actions) -> (handle, (obs, reward, terminated, truncated, info))`` is a pure JAX
function: the draws before the emulators and the masks and preprocessing after them are the
same compiled code as :meth:`Env.step`, and the emulators themselves run in one ordered host
callback (``jax.experimental.io_callback``).  So a whole rollout, policy included, can be one
``jax.lax.scan`` inside one ``jax.jit``, and it gives the trajectory ``Env.step`` gives, bit for
bit.

The emulators are not functional: a handle is a ticket for the next step of the env that made
it, valid once.  Stepping an old handle again (rewinding) is an error, never a silent fork.
"""

from __future__ import annotations

import functools
import itertools
import logging
import weakref
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental import io_callback

from stori_jax.backends.layout import FRAME_OUTPUTS, buffer_specs
from stori_jax.checks import check_actions
from stori_jax.core import (EnvState, WorkerOutputs, before_step, finish_step,
                            initial_state)


class XlaHandle(NamedTuple):
    """The JAX side of an env between two steps (a pytree: pass it through ``jit``/``scan``)."""

    state: EnvState
    reset_pending: jax.Array  # (B,) bool: reset these envs on the next step (autoreset=False)
    steps: jax.Array          # () int32: steps taken since env.xla(), checked by the env
    epoch: jax.Array          # () int32: which xla() call (of which env) began this chain


_EPOCHS = itertools.count(1)


def new_epoch() -> int:
    """A number no other xla() call of any env in this process has had."""
    return next(_EPOCHS)


def output_shapes(plan) -> WorkerOutputs:
    """What one step's callback returns; no screens where the observation is the RAM.  An
    autoresetting env's always holds the final_* outputs (a compiled step has one shape)."""
    shapes = buffer_specs(plan.num_envs, plan.frame_skip, final=plan.autoreset,
                          frames_layout=plan.frames_layout)
    if not plan.screens:
        shapes.update({name: ((0,), np.uint8) for name in FRAME_OUTPUTS if name in shapes})
    return WorkerOutputs(**{name: jax.ShapeDtypeStruct(*shapes[name])
                            for name in WorkerOutputs._fields if name in shapes})


def initial_handle(state: EnvState, reset_pending, epoch: int) -> XlaHandle:
    return XlaHandle(state=state, reset_pending=jnp.asarray(reset_pending, bool),
                     steps=jnp.zeros((), jnp.int32), epoch=jnp.asarray(epoch, jnp.int32))


def check_traced_actions(actions, num_envs: int, num_actions: int) -> jax.Array:
    """Shape and dtype are known while tracing: check them there (values on the host)."""
    shape, dtype = jnp.shape(actions), jnp.result_type(actions)
    expected = f"shape ({num_envs},) of ints in [0, {num_actions - 1}]"
    if shape != (num_envs,):
        raise ValueError(f"actions must have {expected}, got shape {shape}")
    if not jnp.issubdtype(dtype, jnp.integer):
        raise ValueError(f"actions must have an integer dtype ({expected}), got {dtype}")
    # wider values saturate (a plain cast would wrap a 64-bit 2**32 + 1 to 1): out of range
    # stays out of range, and the host refuses it as env.step does
    bounds, wide = jnp.iinfo(jnp.int32), jnp.iinfo(dtype)
    if wide.max > bounds.max:
        actions = jnp.clip(actions, max(bounds.min, wide.min), bounds.max)
    return jnp.asarray(actions, jnp.int32)


def check_handle_shapes(plan, handle: XlaHandle) -> None:
    """A handle of another env whose batch or observation differs fails here, while tracing,
    not deep inside the traced step (same-shaped ones are refused by the host callback)."""
    expected = jax.eval_shape(lambda: initial_handle(initial_state(plan, 0),
                                                     jnp.zeros((plan.num_envs,), bool), 0))
    for name, want, got in zip(XlaHandle._fields, expected, handle):
        want_leaves, got_leaves = jax.tree.leaves(want), jax.tree.leaves(got)
        same = len(want_leaves) == len(got_leaves) and all(
            jnp.shape(g) == w.shape and jnp.result_type(g) == w.dtype
            for w, g in zip(want_leaves, got_leaves))
        if not same:
            shapes = lambda leaves: [f"{jnp.result_type(x)}{list(jnp.shape(x))}" for x in leaves]
            raise ValueError(f"handle.{name} has {shapes(got_leaves)}, this env's has "
                             f"{shapes(want_leaves)}: the handle comes from another env (another "
                             "num_envs or obs); step the latest handle of this env's xla()")


def xla_step(plan, emulate, handle: XlaHandle, actions):
    """One agent step of every env, traceable: ``emulate`` is the env's host callback."""
    if not isinstance(handle, XlaHandle):
        raise ValueError(f"handle must be the XlaHandle from env.xla() or the last step, got "
                         f"{type(handle).__name__}")
    check_handle_shapes(plan, handle)
    actions = check_traced_actions(actions, plan.num_envs, plan.num_actions)
    state, draws = before_step(plan, handle.state, actions)
    out = io_callback(emulate, output_shapes(plan), handle.epoch, handle.steps, state.key,
                      actions, draws.executed, draws.event_u, draws.event_active,
                      draws.ram_render, draws.noops, handle.reset_pending, ordered=True)
    state, result, pending = finish_step(plan, state, draws, out, handle.reset_pending)
    return XlaHandle(state, pending, handle.steps + 1, handle.epoch), result


def make_step(plan, emulate):
    """``step(handle, actions)``, jitted (it may also be called inside a caller's jit; actions
    given as host values are checked before they enter it).
    ``emulate`` is a bound method of the env, held weakly: JAX's caches keep every traced
    callback alive, and a strong one would keep the env and its worker processes with it."""
    _quiet_callback_log()
    jitted = jax.jit(functools.partial(xla_step, plan, _weak_callback(emulate)))

    def step(handle, actions):
        if not isinstance(actions, jax.Array):
            # a host value (numpy, a list): with x64 off (JAX's default) jit casts a 64-bit one
            # to int32 before tracing, wrapping 2**32 + 1 to 1; check it as env.step does (and
            # pass one int32 array on: jit would take a list for a pytree of scalars)
            actions = check_actions(actions, plan.num_envs, plan.num_actions)
        return jitted(handle, actions)

    return step


def _weak_callback(method):
    """``method`` (bound) called through a weak reference to its object."""
    ref = weakref.WeakMethod(method)

    def callback(*args):
        bound = ref()
        if bound is None:
            from stori_jax.errors import EnvClosedError

            raise marked(EnvClosedError("the environment of this xla() step was garbage "
                                        "collected (its workers are closed); keep the env "
                                        "while you step it"))
        return bound(*args)

    return callback


# An error raised in the emulators' callback reaches the caller as a JaxRuntimeError whose
# message already holds the traceback; JAX also logs it.  Those log records are dropped for the
# errors our callback raises (and marks), so that a stale handle is one message, not three.
CALLBACK_LOGGER = "jax._src.callback"
MARK = "stori_jax_xla_step"


class _DropOurCallbackErrors(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        error = record.exc_info[1] if record.exc_info else None
        return not getattr(error, MARK, False)


@functools.cache
def _quiet_callback_log() -> None:
    logging.getLogger(CALLBACK_LOGGER).addFilter(_DropOurCallbackErrors())


def marked(error: BaseException) -> BaseException:
    """``error`` marked as raised by the emulators' callback (see above)."""
    setattr(error, MARK, True)
    return error
