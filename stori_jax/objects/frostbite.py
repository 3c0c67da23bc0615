"""Frostbite: the player, the igloo (its stage RAM[77], 255 none), the birds (four rows, row i
at y 160 - 26 i: RAM[35 + i] the kind, RAM[84 + i] the column, RAM[88 + i] != 0 a second one
32 to the right) and the ice floes (four rows at y 174 - 26 i from column RAM[31 + i]: three
whole floes when RAM[30] == 8, else six halves drawn apart by |RAM[30] - 8|)."""

import jax.numpy as jnp

from stori_jax.objects.table import at, obj, table, where

IGLOO_Y = (51,) * 4 + (47,) * 4 + (42,) * 4 + (39, 39, 35, 35)
IGLOO_W = (8, 16, 24) + (32,) * 13
IGLOO_H = (4,) * 4 + (8,) * 4 + (13,) * 4 + (16, 16, 20, 20)


@obj("Player")
def player(r):
    sink = r[:, 107]
    sinking = (0 < sink) & (sink < 18)
    y = r[:, 100] + 29
    return (r[:, 102], where(sinking, y + sink, y), 8, where(sinking, 18 - sink, 18),
            (r[:, 106] != 26) & (sink < 18))


@obj("House")
def house(r):
    stage = jnp.clip(r[:, 77], 0, 15)
    return (112, jnp.asarray(IGLOO_Y)[stage], jnp.asarray(IGLOO_W)[stage],
            jnp.asarray(IGLOO_H)[stage], r[:, 77] != 255)


@obj("Bird", 8)
def bird(r):  # the first of each row (rows 0..3), then the second ones
    x, second = at(r, range(84, 88)), at(r, range(88, 92)) != 0
    kind = at(r, range(35, 39))
    here = ((0 < x) & (x < 160) | second) & ((kind == 18) | (kind == 26))
    y = 160 - 26 * jnp.arange(4)
    return (jnp.concatenate([x, x + 32], 1), jnp.concatenate([y, y]), 8, 7,
            jnp.concatenate([here, here & second], 1))


@obj("FloatingBlock", 24)
def floating_block(r):  # row by row, left to right
    k = jnp.arange(24)
    whole = r[:, 30:31] == 8
    row = where(whole, k // 3, k // 6)
    plate = where(whole, k % 3, k % 6)
    start = jnp.take_along_axis(at(r, range(31, 35)), jnp.minimum(row, 3), axis=1)
    space = jnp.abs(r[:, 30:31] - 8)
    halves = where(plate % 2 == 0, -8 - jnp.maximum(0, space - 4), -16 + jnp.minimum(space, 4))
    x = (start + plate * where(whole, 32, 16) + where(whole, -8, halves)) % 160
    return x, 174 - 26 * row, where(whole, 24, 16), 7, where(whole, k < 12, True)


GAME = table("frostbite", player, house, bird, floating_block,
             notes="The bear, the igloo's door, crabs, clams and fish are left out (none on "
                   "the recorded trajectory).")
