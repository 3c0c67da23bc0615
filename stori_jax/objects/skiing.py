"""Skiing: the skier and the trees, moguls and gates' flags of the eight object slots of the
RAM (slot i: type RAM[70 + i] (85 tree, 5 mogul, 2 gate), column RAM[62 + i], row
178 - RAM[86 + i], visible height RAM[54 + i] (0 or 255: none), colour RAM[78 + i]); the slots
are in screen order, top first, and move up one as the top object leaves."""

import jax.numpy as jnp

from stori_jax.objects.table import at, obj, table, where

SLOTS = 8


def _slots(r, kind):
    x, row = at(r, range(62, 70)), 178 - at(r, range(86, 94))
    height = at(r, range(54, 62))
    here = ((at(r, range(70, 78)) == kind) & (height != 0) & (height != 255) & (row >= 0)
            & (row <= 177))
    return x, row, height, here


@obj("Player")
def player(r):
    return r[:, 25], r[:, 26] - 80, 10, 18, True


@obj("Tree", 6)
def tree(r):  # a tree past column 154 wraps round to the left edge
    x, row, height, here = _slots(r, 85)
    wraps = x > 154
    w = where(wraps, jnp.minimum(164 - x, 16), jnp.minimum(155 - x, 16))
    return where(wraps, 8, x - 3), row + 4, w, jnp.minimum(175 - row, height), here


@obj("Mogul", 3)
def mogul(r):
    x, row, height, here = _slots(r, 5)
    return x + 2, row + 3, 16, jnp.minimum(176 - row, height), here


@obj("Flag", 4)
def flag(r):  # each gate: its left flag, then its right one 32 columns on
    x, row, height, here = _slots(r, 2)
    left = x + 1 + 3 * (at(r, range(78, 86)) == 4)
    x = jnp.stack([left, left + 32], axis=-1).reshape(left.shape[0], 2 * SLOTS)
    pair = lambda v: jnp.repeat(v, 2, axis=1)  # noqa: E731
    return x, pair(row) + 4, 5, pair(jnp.minimum(177 - row, height)), pair(here)


GAME = table("skiing", player, tree, mogul, flag,
             notes="Every box from its frame's RAM, in screen order (top first); OCAtari "
                   "tracks the objects over time: it lists them in the order they found a free "
                   "slot, makes an object's first box otherwise (no wrap round, other height "
                   "limits, a flag's offset by its colour) and keeps a tree's first column.")
