"""Pac-Man (the Atari 2600 one): Pac-Man, the four ghosts and the four power pills."""

import jax.numpy as jnp

from stori_jax.objects.table import at, obj, table

POWER_PILLS = ((6, 39), (6, 171), (150, 39), (150, 171))


@obj("Player")
def player(r):
    blink = r[:, 59]
    hidden = (blink == 96) | (blink == 97) | (blink == 160) | (blink == 161)
    return r[:, 49], 2 * r[:, 89] + 1, 8, 16, ~hidden


@obj("Ghost", 4)
def ghost(r):
    return at(r, range(50, 54)), 2 * at(r, range(55, 59)) + 25, 8, 16, True


@obj("PowerPill", 4)
def power_pill(r):  # pill i is bit 5 - i of RAM[26]
    eaten = (r[:, 26:27] >> (5 - jnp.arange(4))) & 1 == 0
    return (jnp.array([x for x, _ in POWER_PILLS]), jnp.array([y for _, y in POWER_PILLS]),
            4, 10, ~eaten)


GAME = table("pacman", player, ghost, power_pill)
