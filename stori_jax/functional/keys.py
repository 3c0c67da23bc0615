"""Key discipline: one key per env per agent step, one sub-key per purpose."""

from __future__ import annotations

import enum

import jax
import jax.numpy as jnp


class Purpose(enum.IntEnum):
    """Independent random streams of one env step (folded into the env's step key)."""

    ACTIONS = 1
    EVENTS = 2
    OBSERVATION = 3
    DRIFT = 4
    NOOPS = 5


def env_keys(step_key: jax.Array, num_envs: int) -> jax.Array:
    """(B,) keys: ``fold_in(step_key, i)`` for env i, independent of how the batch is split."""
    return jax.vmap(jax.random.fold_in, in_axes=(None, 0))(step_key, jnp.arange(num_envs))


def purpose_keys(keys: jax.Array, purpose: Purpose) -> jax.Array:
    """(B,) keys for one purpose."""
    return jax.vmap(jax.random.fold_in, in_axes=(0, None))(keys, int(purpose))
