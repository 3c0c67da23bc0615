"""Freeway: the two chickens and the ten cars (one per lane, top lane first)."""

import jax.numpy as jnp

from stori_jax.objects.table import at, obj, table


@obj("Chicken", 2)
def chicken(r):  # left (player 1) then right
    return jnp.array([44, 108]), 193 - at(r, (14, 15)), 6, 8, True


@obj("Car", 10)
def car(r):
    return at(r, range(117, 107, -1)) - 3, 27 + 16 * jnp.arange(10), 8, 10, True


GAME = table("freeway", chicken, car)
