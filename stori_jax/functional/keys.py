"""Key discipline: one key per env per agent step, one sub-key per purpose."""

from __future__ import annotations

import enum
import numbers

import jax
import jax.numpy as jnp

from stori_jax.checks import check_int


class Purpose(enum.IntEnum):
    """Independent random streams of one env step (folded into the env's step key)."""

    ACTIONS = 1
    EVENTS = 2
    OBSERVATION = 3
    DRIFT = 4
    NOOPS = 5


def env_keys(step_key: jax.Array, num_envs: int) -> jax.Array:
    """(B,) keys: ``fold_in(step_key, i)`` for env i, independent of how the batch is split."""
    num_envs = check_int("num_envs", num_envs, 1)
    return jax.vmap(jax.random.fold_in, in_axes=(None, 0))(step_key, jnp.arange(num_envs))


def purpose_keys(keys: jax.Array, purpose: Purpose) -> jax.Array:
    """(B,) keys for one purpose."""
    if isinstance(purpose, bool) or not isinstance(purpose, numbers.Integral) \
            or purpose not in list(Purpose):  # 1.0 == Purpose.ACTIONS, but is none
        raise ValueError(f"purpose must be a stori_jax.functional.Purpose "
                         f"({', '.join(f'{p.name} = {p.value}' for p in Purpose)}), "
                         f"got {purpose!r}")
    return jax.vmap(jax.random.fold_in, in_axes=(0, None))(keys, int(purpose))
