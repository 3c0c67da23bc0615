"""Stargunner: the ship, its missile, the bomb thrower at the top, its bomb and the three flying
enemies; ship, thrower and enemies only while RAM[12] == 2 (in play)."""

import jax.numpy as jnp

from stori_jax.objects.table import at, obj, table, where


def _playing(r):
    return r[:, 12] == 2


@obj("Player")
def player(r):
    return r[:, 21] - 10, r[:, 14] + 33, 8, 4, _playing(r)


@obj("PlayerMissile")
def player_missile(r):
    return r[:, 40] - 11, r[:, 41] + 32, 8, 1, r[:, 40] != 0


@obj("BombThrower")
def bomb_thrower(r):
    return r[:, 31] - 9, 37, 7, 10, _playing(r) & (r[:, 31] != 0)


@obj("Bomb")
def bomb(r):
    return r[:, 33] - 11, r[:, 34] + 32, 4, 1, r[:, 108] != 0


@obj("FlyingEnemy", 3)
def flying_enemy(r):  # every fourth frame (RAM[113] + 1 divisible by 4) they are drawn smaller
    x = at(r, range(74, 77))
    small = ((r[:, 113:114] + 1) % 4) == 0
    alive = (r[:, 15:16] >= jnp.arange(3)) & (x != 0)
    return (where(small, x - 9, x - 10), at(r, range(71, 74)) + 33, where(small, 7, 8),
            where(small, 8, 10), _playing(r)[:, None] & alive)


GAME = table("star_gunner", player, player_missile, bomb_thrower, bomb, flying_enemy)
