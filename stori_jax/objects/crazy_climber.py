"""Crazy Climber: the climber, the building's windows (12 rows of up to six, which open and
close) and the red enemy in a window."""

import jax.numpy as jnp

from stori_jax.objects.table import obj, table, where

ROWS, COLUMNS = 12, 6


@obj("Player")
def player(r):  # stretched while climbing (RAM[19] or RAM[21] == 124)
    climbing = (r[:, 19] == 124) | (r[:, 21] == 124)
    return r[:, 24] - 8, where(climbing, 158, 160), 12, where(climbing, 23, 21), True


def _window_cells():
    i = jnp.repeat(jnp.arange(ROWS), COLUMNS)
    j = jnp.tile(jnp.arange(COLUMNS), ROWS)
    return i, j


@obj("Window", ROWS * COLUMNS)
def window(r):
    # RAM[46 + row]: the row's pattern (0 all six, 4 the middle four, 8 the outer four, 12 or 16
    # the middle two); rows 2..9 close: RAM[106 + row] says which windows, RAM[93 + row] how far
    i, j = _window_cells()
    kind = r[:, 46 + i]
    moving = r[:, 106 + i]
    inner = (2 <= i) & (i < 10)
    side = (j == 1) | (j == 4)
    middle = (kind == 12) | (kind == 16)
    here = (((kind == 4) & (0 < j) & (j < 5)) | ((kind == 8) & ((j < 2) | (j > 3)))
            | (middle & (1 < j) & (j < 4)) | (kind == 0))
    closes = where(kind == 4, inner & (((moving == 4) & side) | ((moving == 6) & ~side)),
             where(kind == 8, inner & (((moving == 8) & ~side) | ((moving == 10) & side)),
             where(middle, (inner & (moving == 12)) | (moving == 14) | (moving == 16)
                   | (moving == 18),
                   inner & (((moving == 0) & ~side) | ((moving == 2) & side)))))
    closing = where(closes, r[:, 93 + i], 0)
    x = where(j < 3, 44 + 12 * j, 48 + 12 * j)
    return x, 47 + 13 * i + closing + r[:, 58:59], 8, 8 - closing, here


@obj("Enemy_Red")
def enemy_red(r):  # RAM[14]: its column, RAM[15]: its row, RAM[16]: its height
    column, height = r[:, 14], r[:, 16]
    x = where(column < 6, 45 + 12 * (column - 3), where(column == 7, 49 + 12 * (column - 2),
                                                        49 + 12 * (column - 3)))
    return (x, 81 + 13 * r[:, 15] - height + r[:, 58], 8, height,
            (height != 0) & (column != 0) & (r[:, 84] == 253))


GAME = table("crazy_climber", player, window, enemy_red,
             notes="Player: OCAtari keeps the stretched height (23) on later frames; here it "
                   "follows the RAM of its frame.  The bird, the helicopter and the falling "
                   "objects are left out: OCAtari's boxes for them depend on earlier frames "
                   "(their facing), and none of them appears in the fixture.")
