"""Yars' Revenge: Yar, the Qotile (or the Swirl it turns into), the destroyer missile, Yar's
energy missile, the neutral zone and the shield (16 rows of eight cells, RAM[1..16])."""

import jax.numpy as jnp

from stori_jax.objects.table import obj, table


def _playing(r):  # RAM[53] > 159 while the field is shown
    return r[:, 53] > 159


@obj("Player")
def player(r):
    return r[:, 32], r[:, 31] + 3, 8, 16, _playing(r)


@obj("Enemy")
def enemy(r):  # the Qotile: RAM[43] >= 145
    return r[:, 43], r[:, 42] + 3, 8, 18, _playing(r) & (r[:, 43] >= 145)


@obj("Swirl")
def swirl(r):
    return r[:, 43] + 4, r[:, 42] + 3, 8, 18, _playing(r) & (r[:, 43] < 145)


@obj("Enemy_Missile")
def enemy_missile(r):
    return r[:, 47], r[:, 46] + 2, 4, 2, _playing(r)


@obj("Player_Bullet")
def player_bullet(r):  # shown while away from Yar (OCAtari takes the rows' difference as a byte)
    away = (jnp.abs(r[:, 38] - 3 - r[:, 32]) > 5) & ((r[:, 37] - r[:, 31]) % 256 > 5)
    return r[:, 38] - 1, r[:, 37] + 4, 1, 2, _playing(r) & away


@obj("Barrier")
def barrier(r):
    return 52, 4, 28, 190, _playing(r)


@obj("Shield_Block", 128)
def shield_block(r):  # row j (RAM[1 + j], from the bottom), cell i (bit i)
    j = jnp.repeat(jnp.arange(16), 8)
    i = jnp.tile(jnp.arange(8), 16)
    here = (r[:, 1 + j] >> i) & 1 == 1
    top = j == 15
    return (128 + 4 * i, r[:, 26:27] + jnp.where(top, 122, 121) - 8 * j, 4,
            jnp.where(top, 7, 8), here & _playing(r)[:, None])


GAME = table("yars_revenge", player, enemy, swirl, enemy_missile, player_bullet, barrier,
             shield_block)
