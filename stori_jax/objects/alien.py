"""Alien: the player, the three aliens, the pulsar, the rocket and the eggs (13 rows of six on
each side of the maze, a bit each in RAM[65 + row] and RAM[78 + row])."""

import jax.numpy as jnp

from stori_jax.objects.table import obj, table

# per egg of a row: its bit in the row's byte, its x on the left (the right: + 63, + 62), its dy
EGG_BITS = (2, 3, 4, 5, 6, 7)
EGG_X = (26, 56, 34, 64, 42, 72)
EGG_DY = (0, 0, 2, 2, 4, 4)
RIGHT_X = (89, 118, 97, 126, 105, 134)


def _maze(r):  # RAM[0] == 0: the maze; else the bonus stage, not covered
    return r[:, 0] == 0


@obj("Player")
def player(r):
    return r[:, 52] + 18, 197 - 2 * r[:, 45], 6, 13, True


@obj("Alien", 12)
def alien(r):
    y, x = r[:, 42:45], r[:, 49:52]
    return (x + 17), (196 - 2 * y), 8, 13, (y != 0) & (x != 0) & _maze(r)[:, None]


@obj("Pulsar")
def pulsar(r):
    where_ = r[:, 103]
    return (jnp.array([0, 123, 31, 77])[where_ % 4], jnp.array([0, 137, 137, 17])[where_ % 4],
            7, 5, (where_ != 0) & (where_ < 4) & _maze(r))


@obj("Rocket")
def rocket(r):
    y = r[:, 47]
    return 17 + 15 * (r[:, 60] & 7), 197 - 2 * y, 8, 5, (y != 0) & _maze(r)


@obj("Egg", 156)
def egg(r):
    row = jnp.repeat(jnp.arange(13), 6)
    k = jnp.tile(jnp.arange(6), 13)
    bits, dy = jnp.array(EGG_BITS)[k], jnp.array(EGG_DY)[k]
    left = (r[:, 65 + row] >> bits) & 1 == 1
    right = (r[:, 78 + row] >> bits) & 1 == 1
    x = jnp.concatenate([jnp.array(EGG_X)[k], jnp.array(RIGHT_X)[k]])
    y = jnp.tile(19 + 12 * row + dy, 2)
    return x, y, 1, 2, jnp.concatenate([left, right], axis=1) & _maze(r)[:, None]


GAME = table("alien", player, alien, pulsar, rocket, egg,
             notes="The bonus stage (RAM[0] != 0) is not covered: there the aliens and the "
                   "rocket are absent here.")
