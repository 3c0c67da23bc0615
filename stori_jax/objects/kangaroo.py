"""Kangaroo: the mother kangaroo, her child at the top, the monkeys, the falling and thrown
coconuts, the fruit, the bell and the level's ladders and platforms (RAM[36]: the level, 0, 1
or 2; rows are RAM values times 8)."""

import jax.numpy as jnp

from stori_jax.objects.table import at, obj, table, where

# per level: its ladders (x, y, w, h) and platforms (x, y, w, h)
LADDERS = (
    ((132, 132, 8, 35), (20, 85, 8, 35), (132, 37, 8, 35)),
    ((120, 132, 8, 4), (24, 116, 8, 4), (128, 36, 8, 4)),
    ((20, 36, 8, 28), (20, 148, 8, 4), (36, 116, 8, 20), (104, 36, 8, 20), (120, 68, 8, 4),
     (132, 84, 8, 4)),
)
_FLOOR_CEILING = ((16, 172, 128), (16, 28, 128))
PLATFORMS = tuple(tuple((x, y, w, 4) for x, y, w in _FLOOR_CEILING + level) for level in (
    ((16, 76, 128), (16, 124, 128)),
    ((16, 124, 28), (52, 124, 92), (16, 76, 60), (84, 76, 60), (28, 164, 24), (112, 84, 24),
     (120, 44, 24), (48, 156, 32), (76, 148, 32), (104, 140, 32), (16, 108, 32), (56, 100, 20),
     (84, 92, 20), (64, 60, 20), (92, 52, 20), (28, 68, 28)),
    ((88, 140, 16), (64, 148, 16), (100, 116, 16), (48, 100, 16), (76, 52, 16), (80, 36, 16),
     (104, 132, 20), (84, 156, 20), (124, 124, 20), (52, 84, 20), (108, 164, 36), (16, 108, 80),
     (16, 92, 28), (76, 92, 68), (16, 140, 32), (96, 60, 36), (100, 76, 44), (60, 44, 12)),
))


def _level_table(rows, slots):  # (levels, slots, 5): x, y, w, h, present
    out = [[list(box) + [1] for box in level] + [[0] * 5] * (slots - len(level))
           for level in rows]
    return jnp.array(out, jnp.int32)


def _layout(r, rows, slots):
    level = jnp.minimum(r[:, 36], 2)
    v = _level_table(rows, slots)[level]  # (B, slots, 5)
    return v[..., 0], v[..., 1], v[..., 2], v[..., 3], v[..., 4] == 1


@obj("Player")
def player(r):
    pose = r[:, 18]
    ducking, stooped = (pose == 20) | (pose == 28), (pose == 66) | (pose == 74)
    stretched = (pose == 65) | (pose == 73)
    h = where(ducking, 16, where(stooped, 15, where(stretched, 23, 24)))
    return r[:, 17] + 15, r[:, 16] * 8 + 4, 8, h, True


@obj("Child")
def child(r):
    return r[:, 83] + 15, 12, 8, 15, True


@obj("Monkey", 4)
def monkey(r):  # monkey i: row RAM[11 - i], column RAM[15 - i]
    row = at(r, range(11, 7, -1))
    return at(r, range(15, 11, -1)) + 16, row * 8 + 5, 6, 15, (row != 255) & (row != 127)


@obj("FallingCoconut")
def falling_coconut(r):
    return r[:, 34] + 14, (r[:, 33] - 22 * r[:, 36]) * 8 + 9, 2, 3, r[:, 33] != 255


@obj("ThrownCoconut", 3)
def thrown_coconut(r):
    row = at(r, range(25, 28))
    return at(r, range(28, 31)) + 15, row * 8 + 1, 2, 3, row != 255


@obj("Fruit", 3)
def fruit(r):  # RAM[42 + i] < 128: fruit i, its kind the low two bits; the rows and columns are
    kind = at(r, range(42, 45))  # read one byte on while RAM[86] / RAM[91] lag a step behind
    row = where(r[:, 87:88] == r[:, 86:87], at(r, range(84, 87)), at(r, range(85, 88)))
    x = where(r[:, 92:93] == r[:, 91:92], at(r, range(89, 92)), at(r, range(90, 93)))
    w = where(kind % 4 < 2, 7, 8)
    return x + 15, row * 8 + 4, w, where(kind % 4 == 1, 9, 11), kind < 128


@obj("Bell")
def bell(r):
    x = jnp.array([93, 31, 130])[jnp.minimum(r[:, 36], 2)]
    return x, 36, 6, 11, r[:, 41] != 128


@obj("Ladder", 6)
def ladder(r):
    return _layout(r, LADDERS, 6)


@obj("Platform", 20)
def platform(r):
    return _layout(r, PLATFORMS, 20)


GAME = table("kangaroo", player, child, monkey, falling_coconut, thrown_coconut, fruit, bell,
             ladder, platform,
             notes="The child is where RAM[83] says on every frame; OCAtari moves it only on "
                   "some frames (the mother's row RAM[16] past 3, or RAM[68] the fruit count) "
                   "and brings back the bell only when the game restarts.")
