"""Uniform draws that drive the emulator workers' event rules."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from stori_jax.checks import check_int


def event_uniforms(keys: jax.Array, num_slots: int) -> jax.Array:
    """(B, num_slots, 2) float32 in [0, 1): per slot, the firing draw u and the choice draw."""
    num_slots = check_int("num_slots", num_slots, 1)
    return jax.vmap(lambda k: jax.random.uniform(k, (num_slots, 2), jnp.float32))(keys)
