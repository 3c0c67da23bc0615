"""Type 2.2: the concept-drift schedule (which concept is active at an episode's agent step)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from stori_jax.checks import MAX_INT32, check_int, unless_traced
from stori_jax.config import DRIFT_SCHEDULES


def concept2_probability(episode_step: jax.Array, schedule: str, period: int) -> jax.Array:
    """P(concept 2) at 0-indexed agent step k of the episode (exact 0/1 except for gradual)."""
    period = unless_traced(check_int, "period", period, 1, MAX_INT32)
    k = jnp.asarray(episode_step, jnp.int32)
    if schedule == "sudden":
        return (k >= period).astype(jnp.float32)
    if schedule == "cyclic":
        return ((k // period) % 2).astype(jnp.float32)
    if schedule == "gradual":
        return jnp.clip((k - period).astype(jnp.float32) / period, 0.0, 1.0)
    raise ValueError(f"schedule must be one of {list(DRIFT_SCHEDULES)}, got {schedule!r}")


def concept_of(keys: jax.Array, episode_step: jax.Array, schedule: str, period: int) -> jax.Array:
    """(B,) int32 concept index (0 = concept 1 default, 1 = concept 2) for this step."""
    p2 = concept2_probability(episode_step, schedule, period)
    if schedule == "gradual":
        u = jax.vmap(lambda k: jax.random.uniform(k, (), jnp.float32))(keys)
        return (u < p2).astype(jnp.int32)
    return p2.astype(jnp.int32)
