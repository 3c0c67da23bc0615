"""Fishing Derby: the two hooks, the six fish (one per row, or on a hook) and the shark."""

import jax.numpy as jnp

from stori_jax.objects.table import obj, table, where

# a line's depth byte d -> int(d * 2.3), OCAtari's scale (as Python floors the float product)
DEPTH = jnp.array([int(d * 2.3) for d in range(256)])


def _hook(r, base, side, facing, depth, offset):
    left = r[:, facing] == 16
    x = offset + r[:, base] + where(left, -r[:, side], r[:, side] + 3)
    return x, DEPTH[r[:, depth]] + 78


@obj("PlayerOneHook")
def player_one_hook(r):
    return (*_hook(r, 23, 34, 30, 65, -2), 3, 3, True)


@obj("PlayerTwoHook")
def player_two_hook(r):
    return (*_hook(r, 24, 35, 31, 66, 2), 3, 3, True)


@obj("Fish", 6)
def fish(r):  # row i (top first): x RAM[74 - i]; a hooked fish hangs 4 above its hook
    row = jnp.arange(6)
    on1 = (r[:, 112:113] != 0) & (6 - r[:, 112:113] == row)
    on2 = (r[:, 113:114] != 0) & (6 - r[:, 113:114] == row)
    hook_y = where(6 - r[:, 112:113] == row, DEPTH[r[:, 65:66]], DEPTH[r[:, 66:67]]) + 77
    return r[:, 74 - row], where(on1 | on2, hook_y, 97 + 16 * row), 8, 10, True


@obj("Shark")
def shark(r):
    return r[:, 75], 80, 35, 13, r[:, 103] != 80


GAME = table("fishing_derby", player_one_hook, player_two_hook, fish, shark)
