"""Ms. Pac-Man: Ms. Pac-Man, the ghosts, the fruit, the four power pills (bits of RAM[117]) and
the pills (14 rows of 18 cells: bits of RAM[59 + 3 * row .. 61 + 3 * row], on the cells of the
maze that hold one; RAM[0] == 0: the first maze, else the second)."""

import jax.numpy as jnp

from stori_jax.objects.table import obj, table, where

MAZES = (
    ("111101111111101111", "100101000000101001", "111111111111111111", "010100100001001010",
     "110111111111111011", "010000100001000010", "011111100001111110", "010000100001000010",
     "110111111111111011", "010101010010101010", "111101011110101111", "100101110011101001",
     "100100010010001001", "111111111111111111"),
    ("111111111111111111", "100001000000100001", "110111011110111011", "010101010010101010",
     "010101111111101010", "111100100001001111", "100111100001111001", "100100100001001001",
     "100101111111101001", "111111000000111111", "001001011110100100", "111101110011101111",
     "100101000000101001", "111101111111101111"),
)
ROWS, CELLS = 14, 18
POWER_PILLS = ((2, 148, 146), (3, 148, 14), (4, 8, 147), (5, 8, 15))  # bit of RAM[117], x, y


def _cell_bits():  # per cell of a row: which of the row's three bytes, which bit
    byte, bit = [0] * CELLS, [0] * CELLS
    byte[0], bit[0], byte[17], bit[17] = 0, 6, 0, 4
    for c in range(1, 5):
        byte[c], bit[c] = 1, 2 * (4 - c) + 1
    for c in range(9, 13):
        byte[c], bit[c] = 1, 2 * (12 - c)
    for c in range(5, 9):
        byte[c], bit[c] = 2, 2 * (c - 5)
    for c in range(13, 17):
        byte[c], bit[c] = 2, 2 * (c - 13) + 1
    return byte, bit


@obj("Player")
def player(r):
    return r[:, 10] - 13, r[:, 16] + 1, 9, 10, True


@obj("Ghost", 4)
def ghost(r):  # RAM[47] > 0: the ghosts are out, the first one and RAM[19] more
    out = (r[:, 47:48] > 0) & (jnp.arange(4) <= r[:, 19:20])
    return r[:, 6:10] - 13, r[:, 12:16] + 1, 9, 10, out


@obj("Fruit")
def fruit(r):
    return r[:, 11] - 13, r[:, 17] + 1, 9, 10, (r[:, 11] > 0) & (r[:, 17] > 0)


@obj("PowerPill", 4)
def power_pill(r):
    bit, x, y = (jnp.array(v) for v in zip(*POWER_PILLS))
    return x, y, 4, 7, (r[:, 117:118] >> bit) & 1 == 1


@obj("Pill", ROWS * CELLS)
def pill(r):
    byte, bit = _cell_bits()
    row = jnp.repeat(jnp.arange(ROWS), CELLS)
    cell = jnp.tile(jnp.arange(CELLS), ROWS)
    byte, bit = jnp.array(byte)[cell], jnp.array(bit)[cell]
    mazes = jnp.array([[[int(c) for c in line] for line in maze] for maze in MAZES]).reshape(2, -1)
    on_maze = where(r[:, 0:1] == 0, mazes[0], mazes[1]) == 1
    here = (r[:, 59 + 3 * row + byte] >> bit) & 1 == 1
    return where(cell < 9, 8, 12) + 8 * cell, 7 + 12 * row, 4, 2, here & on_maze


GAME = table("ms_pacman", player, ghost, fruit, power_pill, pill,
             notes="On the frame a ghost, the fruit or a power pill appears OCAtari gives the "
                   "box it starts with ((0, 0), (125, 173), (125, 173)); here every object "
                   "follows the RAM of its frame.")
