"""Breakout: the paddle, the ball and the wall, one Block per run of adjacent bricks in a row.

The wall is a bitmap in RAM 0..35: brick row q (0 = top, y = 57 + 6 q) is the six bytes
5 - q, 11 - q, ..., 35 - q (byte group j = 0..5 at address 6 j + 5 - q), and each of its 18
columns of 8 pixels (x = 8 + 8 c) is one bit of one of them (COLUMN_BITS).  A run of adjacent
bricks is one object 8 * (its length) wide, in the slot of its first column.
"""

import jax.numpy as jnp

from stori_jax.objects.table import obj, table

# column c -> (byte group j, bit) of its brick
COLUMN_BITS = ((5, 6), (4, 6), (4, 4), (4, 2), (4, 0), (3, 0), (3, 2), (3, 4), (3, 6), (2, 4),
               (2, 6), (1, 6), (1, 4), (1, 2), (1, 0), (0, 0), (0, 2), (0, 4))
ROWS, COLUMNS = 6, 18


def bricks(r):
    """(B, 6 rows, 18 columns) bool: where a brick is."""
    rows = jnp.arange(ROWS)
    groups = jnp.array([j for j, _ in COLUMN_BITS])
    bits = jnp.array([b for _, b in COLUMN_BITS])
    bytes_ = r[:, 6 * groups[None, :] + 5 - rows[:, None]]  # (B, 6, 18)
    return ((bytes_ >> bits) & 1) == 1


@obj("Player")
def player(r):
    return r[:, 72] - 47, 189, 16, 4, True


@obj("Ball")
def ball(r):
    y = r[:, 101]
    return r[:, 99] - 49, y + 9, 2, 4, (y != 0) & (y + 9 <= 196)


@obj("Block", ROWS * COLUMNS)
def block(r):  # slot 18 q + c: the run of row q starting at column c
    b = bricks(r)
    starts = b & ~jnp.pad(b, ((0, 0), (0, 0), (1, 0)))[:, :, :-1]
    length, run = b.astype(jnp.int32), b
    for k in range(1, COLUMNS):
        run = run & jnp.pad(b, ((0, 0), (0, 0), (0, k)))[:, :, k:]
        length = length + run
    c = jnp.arange(COLUMNS)
    q = jnp.arange(ROWS)[:, None]
    x = jnp.broadcast_to(8 + 8 * c, (ROWS, COLUMNS))
    y = jnp.broadcast_to(57 + 6 * q, (ROWS, COLUMNS))
    flat = (-1, ROWS * COLUMNS)
    return (x.reshape(1, -1), y.reshape(1, -1), (8 * length).reshape(flat), 6,
            starts.reshape(flat))


GAME = table("breakout", player, ball, block)
