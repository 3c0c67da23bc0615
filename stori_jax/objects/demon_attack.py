"""Demon Attack: the cannon and its missile, the demons (three rows, each one demon or, split,
two; the diving demon), the halves of a demon taking shape, and the demons' missiles (a bitmap:
ten rows of eight columns in RAM[37..46], under the diving demon's column RAM[20])."""

import jax.numpy as jnp

from stori_jax.objects.table import at, obj, table, where

ROWS = 3
MISSILE_ROWS = 10


def column_x(value):  # a horizontal position byte: coarse in the low nibble, fine in the high
    coarse, fine = value % 16, value >> 4
    return (coarse * 15 + where(fine > 7, 28 - fine, 12 - fine))


@obj("Player")
def player(r):
    return column_x(r[:, 16]), 174, 7, 12, True


@obj("PlayerMissile")
def player_missile(r):
    y = r[:, 21]
    return 2 + column_x(r[:, 22]), where(y >= 90, 176, 178) - y, 1, 8, True


def _rows(r):
    state = at(r, range(29, 29 + ROWS))  # > 24: split in two, > 3: whole, > 0: taking shape
    y = (175 - at(r, range(69, 69 + ROWS)))
    return (state, column_x(at(r, range(13, 13 + ROWS))), column_x(at(r, range(17, 17 + ROWS))),
            y)


@obj("Enemy", 8)
def enemy(r):  # per row its left and right demon, then the diving demon
    state, left_x, right_x, y = _rows(r)
    split, whole = state > 24, (state > 3) & (state <= 24)
    right_alive = at(r, range(33, 33 + ROWS)) > 3
    left_dead = (state == 0) & (at(r, range(47, 47 + ROWS)) >> 6 != 0)
    left = split | whole
    right = (split & right_alive) | left_dead
    diving = (r[:, 51] != 0) & (r[:, 50] >> 6 != 0)
    x = jnp.stack([left_x, right_x], axis=2).reshape(-1, 2 * ROWS)
    w = jnp.stack([where(whole, 16, 8), jnp.full_like(state, 8)], axis=2).reshape(-1, 2 * ROWS)
    ys = jnp.repeat(y, 2, axis=1)
    here = jnp.stack([left, right], axis=2).reshape(-1, 2 * ROWS)
    return (jnp.concatenate([x, column_x(r[:, 20:21])], 1),
            jnp.concatenate([ys, (177 - r[:, 72:73])], 1),
            jnp.concatenate([w, jnp.full_like(w[:, :1], 8)], 1), 7,
            jnp.concatenate([here, diving[:, None]], 1))


@obj("EnemyPart", 6)
def enemy_part(r):  # the two halves of each row's demon while it takes shape
    state, left_x, right_x, y = _rows(r)
    shaping = (state > 0) & (state <= 3)
    x = jnp.stack([left_x, right_x], axis=2).reshape(-1, 2 * ROWS)
    return x, jnp.repeat(y, 2, axis=1), 30, 7, jnp.repeat(shaping, 2, axis=1)


@obj("EnemyMissile", 14)
def enemy_missile(r):  # row i (from the bottom), column k (the byte's bits, high bit first)
    i = jnp.repeat(jnp.arange(MISSILE_ROWS), 8)
    k = jnp.tile(jnp.arange(8), MISSILE_ROWS)
    here = (r[:, 37 + i] >> (7 - k)) & 1 == 1
    return (column_x(r[:, 20:21]) + k), 179 - 8 * i, 1, 4, here


GAME = table("demon_attack", player, player_missile, enemy, enemy_part, enemy_missile,
             notes="EnemyMissile: OCAtari keeps only the last missile of the bitmap (each new "
                   "one overwrites its first slot); here every missile of the bitmap is an "
                   "object.")
