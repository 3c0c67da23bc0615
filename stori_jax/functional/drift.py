"""Type 2.2: the concept-drift schedule (which concept is active at an episode's agent step)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from stori_jax.checks import MAX_INT32, check_dtype, check_int, unless_traced
from stori_jax.config import DRIFT_SCHEDULES


def concept2_probability(episode_step: jax.Array, schedule: str, period: int) -> jax.Array:
    """P(concept 2) at 0-indexed agent step k of the episode (exact 0/1 except for gradual)."""
    period = unless_traced(check_int, "period", period, 1, MAX_INT32)
    check_dtype("episode_step", episode_step, "iu", "agent steps (an integer dtype)")
    k = jnp.asarray(episode_step, jnp.int32)
    if schedule == "sudden":
        return (k >= period).astype(jnp.float32)
    if schedule == "cyclic":
        return ((k // period) % 2).astype(jnp.float32)
    if schedule == "gradual":
        return jnp.clip((k - period).astype(jnp.float32) / period, 0.0, 1.0)
    raise ValueError(f"schedule must be one of {list(DRIFT_SCHEDULES)}, got {schedule!r}")


def concept_of(keys: jax.Array, episode_step: jax.Array, schedule: str, period: int) -> jax.Array:
    """(B,) int32 concept index (0 = concept 1 default, 1 = concept 2) for this step, from
    ``keys`` (B,) and ``episode_step``, each env's (B,) or one for all (a scalar)."""
    if np.ndim(keys) < 1 or np.ndim(episode_step) not in (0, 1) or (
            np.ndim(episode_step) == 1 and np.shape(episode_step)[0] != np.shape(keys)[0]):
        raise ValueError(f"episode_step must have shape () or (B,) for keys of shape (B, ...), "
                         f"got {tuple(np.shape(episode_step))} and keys "
                         f"{tuple(np.shape(keys))}")
    p2 = jnp.broadcast_to(concept2_probability(episode_step, schedule, period),
                          np.shape(keys)[:1])
    if schedule == "gradual":
        u = jax.vmap(lambda k: jax.random.uniform(k, (), jnp.float32))(keys)
        return (u < p2).astype(jnp.int32)
    return p2.astype(jnp.int32)
