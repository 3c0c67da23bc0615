"""Galaxian: the player's ship, its missile and the convoy of enemy ships (six rows of seven,
RAM[38 + row] bits 6..0, shifted by RAM[36])."""

import jax.numpy as jnp

from stori_jax.objects.table import obj, table

ROW_Y = (19, 32, 43, 56, 67, 79)


@obj("Player")
def player(r):
    return r[:, 100] + 8, 170, 8, 13, r[:, 11] != 255


@obj("PlayerMissile")
def player_missile(r):
    y = r[:, 11]
    return r[:, 60] + 2, y + 16, 1, 3, (y != 255) & (y != 151)


@obj("EnemyShip", 42)
def enemy_ship(r):  # slot 7 row + column
    column = jnp.tile(jnp.arange(7), 6)
    row = jnp.repeat(jnp.arange(6), 7)
    here = (r[:, 38 + row] >> (6 - column)) & 1 == 1
    return (72 + 2 * r[:, 36:37] + 17 * column, jnp.array(ROW_Y)[row], 6,
            jnp.where((row == 1) | (row == 3), 8, 9), here)


GAME = table("galaxian", player, player_missile, enemy_ship,
             notes="EnemyMissile: OCAtari 2.2.1 lists it but never reports one (it has no "
                   "formula for it); left out.")
