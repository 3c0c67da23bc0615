"""Montezuma's Revenge: Panama Joe, the key, the skulls, the barriers and each room's ropes,
walls, ladders, platforms and conveyor belts (RAM[3]: the room, 0 .. 23 on the first level;
rooms 16 and on are dark, their layout hidden, unless bit 7 of RAM[65] (the torch) lights
them).  RAM[49] is the room's item or enemy (4 a key, 5 a skull, ...) at column RAM[44] and
height RAM[45]; RAM[84]'s bits 0, 1, 2 a second one 16, 32 or 64 columns on."""

import jax.numpy as jnp

from stori_jax.objects.table import obj, table, where

ROOMS = 24
# per room: (ropes, walls, ladders, platforms, conveyor belts), each a tuple of (x, y, w, h)
_FLOOR_93 = ((0, 93, 160, 1),)
_LADDER_53 = ((72, 53, 16, 38),)
_DOWN_UP = ((72, 52, 16, 39), (72, 93, 16, 102))
LAYOUT = {
    0: ((), ((0, 53, 4, 42),), ((72, 94, 16, 102),), ((4, 94, 154, 1),), ()),
    1: (((112, 96, 1, 39),),
        ((0, 96, 8, 40), (0, 136, 16, 45), (152, 96, 8, 40), (144, 136, 16, 45)),
        ((72, 93, 16, 42), (16, 136, 16, 45), (128, 136, 16, 45)),
        ((0, 93, 56, 2), (104, 93, 56, 2), (68, 93, 23, 2), (76, 136, 8, 5), (8, 136, 28, 2),
         (124, 136, 28, 2), (16, 180, 128, 1)),
        ((60, 136, 15, 5), (85, 136, 15, 5))),
    2: ((), ((156, 52, 4, 42),), ((72, 93, 16, 102),), ((4, 93, 154, 1),), ()),
    3: ((), ((0, 53, 4, 41),), ((72, 93, 16, 102),), ((4, 93, 154, 1),), ()),
    4: ((), (), _DOWN_UP, ((4, 93, 154, 1),), ()),
    5: (((41, 97, 1, 24), (125, 95, 2, 52)),
        ((32, 53, 4, 40), (124, 53, 4, 40), (0, 96, 4, 77), (156, 96, 4, 77)),
        ((72, 171, 16, 26),),
        ((0, 93, 48, 2), (112, 93, 48, 2), (48, 130, 64, 3), (4, 171, 154, 1), (76, 93, 8, 5)),
        ((60, 93, 15, 5), (85, 93, 15, 5))),
    6: ((), (), _LADDER_53, _FLOOR_93, ()),
    7: ((), ((156, 53, 4, 42),), ((72, 94, 16, 102),), ((4, 94, 154, 1),), ()),
    8: (((80, 96, 1, 51),), ((0, 53, 4, 121), (156, 97, 4, 77)), (),
        ((4, 143, 12, 4), (144, 143, 12, 4), (4, 93, 43, 3), (76, 93, 8, 3), (112, 93, 48, 3),
         (4, 173, 152, 1)), ()),
    9: ((), ((156, 52, 3, 41),), _LADDER_53, ((0, 93, 158, 1),), ()),
    10: ((), ((0, 53, 3, 40),), _LADDER_53, ((0, 93, 36, 1), (124, 93, 36, 1)), ()),
    11: ((), (), _DOWN_UP, _FLOOR_93, ()),
    12: ((), (), (), ((0, 94, 160, 1),), ()),
    13: ((), (), _DOWN_UP, _FLOOR_93, ()),
    14: (((71, 96, 1, 48), (87, 97, 2, 33)), (), ((72, 169, 16, 25),),
         ((0, 93, 40, 3), (68, 93, 24, 3), (120, 93, 40, 3), (16, 168, 128, 1),
          (0, 97, 16, 73), (144, 97, 16, 73)), ()),
    15: ((), (), (), ((0, 94, 160, 1),), ()),
    16: ((), (), (), _FLOOR_93, ()),
    17: ((), (), (), ((0, 94, 160, 1),), ()),
    18: ((), (), (), ((0, 94, 36, 1), (124, 94, 36, 1)), ()),
    19: ((), (), _LADDER_53, _FLOOR_93, ()),
    20: ((), ((156, 52, 3, 42),), (), ((0, 94, 36, 1), (124, 94, 32, 1)), ()),
    21: ((), ((0, 53, 3, 40),), _LADDER_53, ((0, 93, 158, 1),), ()),
    22: ((), (), _LADDER_53, ((0, 93, 36, 1), (124, 93, 36, 1)), ()),
    23: ((), ((156, 53, 3, 40),), (), ((0, 93, 158, 1),), ()),
}


def _room(r):
    return r[:, 3]


def _lit(r):  # the room's layout is shown
    return (_room(r) < 16) | ((r[:, 65] & 128) != 0)


def _layout(part, slots):
    def boxes(r):
        rows = [list(LAYOUT.get(room, ((),) * 5)[part]) for room in range(ROOMS + 1)]
        table_ = jnp.array([[list(b) + [1] for b in row] + [[0] * 5] * (slots - len(row))
                            for row in rows], jnp.int32)
        v = table_[jnp.minimum(_room(r), ROOMS)]  # (B, slots, 5); room 24 and on: none
        return v[..., 0], v[..., 1], v[..., 2], v[..., 3], (v[..., 4] == 1) & _lit(r)[:, None]
    return boxes


def _thing(r):  # the room's item or enemy: its column and its row
    room = _room(r)
    base = where(room == 0, 55, where(room == 1, 98, where(room == 7, 54, 53)))
    low = r[:, 45]
    y = base + 255 - low + where(low < 216, 4, 0)
    return r[:, 44] - 1, y, r[:, 49]


def _things_shown(r):
    kind = r[:, 49]
    return _lit(r) | (kind == 5) | ((8 < kind) & (kind < 11))


@obj("Player")
def player(r):
    return r[:, 42] - 1, 255 - r[:, 43] + 53, 8, 20, True


@obj("Key")
def key(r):
    x, y, kind = _thing(r)
    return x, y, 7, 15, _things_shown(r) & (kind == 4)


@obj("Skull", 2)
def skull(r):  # rooms 1, 5 and 18 have their own rolling skull; elsewhere the room's enemy
    x, y, kind = _thing(r)
    y = y + where(r[:, 45] < 216, 4, 0)  # an enemy's row: 4 more than an item's
    second = r[:, 84]
    x2 = where(second & 4 != 0, x + 64, where(second & 2 != 0, x + 32, x + 16))
    enemy = _things_shown(r) & (kind == 5)
    room = _room(r)
    lit = _lit(r)
    own = [(lit & (room == 1), r[:, 67] & 2, r[:, 47] + 32, 406 - r[:, 46]),
           (lit & (room == 5), r[:, 69] & 2, r[:, 47] + 33, 358 - r[:, 46]),
           (room == 18, r[:, 76] & 32, r[:, 47] - 1, r[:, 46] - 147)]
    x1, y1, here1 = x, y, enemy
    for in_room, rolling, rx, ry in own:
        x1, y1 = where(in_room, rx, x1), where(in_room, ry, y1)
        here1 = where(in_room, rolling != 0, here1)
    return (jnp.stack([x1, x2], 1), jnp.stack([y1, y], 1), 7, 13,
            jnp.stack([here1, enemy & (second != 0)], 1))


@obj("Barrier", 2)
def barrier(r):  # the laser gates of rooms 1 and 17 and the doors of room 5
    room = _room(r)
    five = room == 5
    x = jnp.stack([where(five, 56, 20), where(five, 100, 136)], 1)
    y = where(five, 135, 54)[:, None]
    shown = _lit(r) & ((room == 1) | five | (room == 17))
    here = jnp.stack([r[:, 26] != 117, r[:, 28] != 117], 1) & shown[:, None]
    return x, y, 4, 37, here


@obj("Rope", 2)
def rope(r):
    return _layout(0, 2)(r)


@obj("Wall", 4)
def wall(r):
    return _layout(1, 4)(r)


@obj("Ladder", 3)
def ladder(r):
    return _layout(2, 3)(r)


@obj("Platform", 7)
def platform(r):
    return _layout(3, 7)(r)


@obj("Conveyer_Belt", 2)
def conveyer_belt(r):
    return _layout(4, 2)(r)


GAME = table("montezuma_revenge", player, key, skull, barrier, rope, wall, ladder, platform,
             conveyer_belt,
             notes="The first level's 24 rooms; only the first room is on the recorded "
                   "trajectory.  Left out, never seen there: the amulet, sword, torch and "
                   "rubies, the spider and snakes, the beams, the disappearing platforms and "
                   "the HUD.  Every object is where its frame's RAM says; OCAtari builds a "
                   "room's layout and items on entering it (so on that frame it has no key) "
                   "and keeps an item's first box.  Room 8's rope is its (80, 96, 1, 51), "
                   "where OCAtari stores a default rope, and room 20's wall is a wall (OCAtari "
                   "puts it among the ladders).")
