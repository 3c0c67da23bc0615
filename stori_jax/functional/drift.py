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
    """int32 concept index (0 = concept 1 default, 1 = concept 2) for this step, one per key:
    (B,) for ``keys`` (B,) (a batch of typed keys, or (B, 2) raw uint32 ones), () for a single
    key (one env, e.g. under ``jax.vmap``); ``episode_step`` is each env's or one for all (a
    scalar)."""
    given = tuple(np.shape(keys))
    if not jax.dtypes.issubdtype(keys.dtype, jax.dtypes.prng_key):  # raw uint32 key data
        try:
            keys = jax.random.wrap_key_data(keys)  # checks its trailing axis: a key's words
        except (TypeError, ValueError) as e:
            raise ValueError(f"concept_of takes keys (B,) (raw: (B, 2)) or one key, got keys "
                             f"of shape {given} and dtype {keys.dtype} "
                             f"({e})") from None
    batch = tuple(np.shape(keys))
    if len(batch) > 1 or np.shape(episode_step) not in ((), batch):
        raise ValueError(f"concept_of takes keys (B,) (raw: (B, 2)) or one key, and an "
                         f"episode_step of shape () or the keys' (B,): got keys "
                         f"{given} and episode_step "
                         f"{tuple(np.shape(episode_step))}")
    p2 = jnp.broadcast_to(concept2_probability(episode_step, schedule, period), batch)
    if schedule == "gradual":
        draw = lambda k: jax.random.uniform(k, (), jnp.float32)  # noqa: E731
        u = jax.vmap(draw)(keys) if batch else draw(keys)
        return (u < p2).astype(jnp.int32)
    return p2.astype(jnp.int32)
