"""Asterix: the player (Asterix or Obelix) and, in each of the eight lanes, a reward, an enemy
or a consumable (the lane's kind from RAM[73 + i] and RAM[29 + i]; RAM[18 - i] == 11: an empty
lane)."""

import jax.numpy as jnp

from stori_jax.objects.table import at, obj, table, where

LANE_Y = 26 + 16 * jnp.arange(8)


@obj("Player")
def player(r):
    dying = r[:, 71] >= 82
    return (r[:, 41], 26 + 16 * r[:, 39], where(dying, 16, where(r[:, 54] < 5, 8, 6)), 11, True)


def _lanes(r):
    empty = at(r, range(18, 10, -1)) == 11
    reward = ~empty & (at(r, range(73, 81)) != 0)
    enemy = ~empty & ~reward & (at(r, range(29, 37)) % 2 == 1)
    return at(r, range(42, 50)), reward, enemy, ~empty & ~reward & ~enemy


@obj("Reward", 8)
def reward(r):
    x, here, _, _ = _lanes(r)
    return x, LANE_Y, 8, 11, here


@obj("Enemy", 8)
def enemy(r):
    x, _, here, _ = _lanes(r)
    return x, LANE_Y, 7, 11, here


@obj("Consumable", 8)
def consumable(r):
    x, _, _, here = _lanes(r)
    return x + 1, LANE_Y + 1, 7, 11, here


GAME = table("asterix", player, reward, enemy, consumable)
