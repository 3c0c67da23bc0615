"""Venture: Winky (RAM[90] the room: 8 or 9 the hallway, where Winky is a dot at RAM[85],
RAM[26]; in a room the first sprite, RAM[79], RAM[20], is Winky) and the hallway's six monsters
(sprites 0 to 5: columns RAM[79 .. 84], rows from RAM[20 .. 25])."""

import jax.numpy as jnp

from stori_jax.objects.table import at, obj, table, where

SPRITE_DX = jnp.array([-1, -1, -7, -1, -1, -7])
SPRITE_DY = jnp.array([26, 27, 27, 26, 27, 27])


def _hallway(r):
    return (r[:, 90] == 8) | (r[:, 90] == 9)


@obj("Player")
def player(r):
    hall = _hallway(r)
    return (where(hall, r[:, 85] - 1, r[:, 79] - 1),
            where(hall, r[:, 26] * 2 + 25, (r[:, 20] * 2 + 26) % 255),
            where(hall, 1, 8), where(hall, 2, 12), True)


@obj("Hallmonsters", 6)
def hallmonsters(r):
    return (at(r, range(79, 85)) + SPRITE_DX, (at(r, range(20, 26)) * 2 + SPRITE_DY) % 255, 5, 8,
            _hallway(r)[:, None])


GAME = table("venture", player, hallmonsters,
             notes="Winky's shot, the rooms' monsters, walls and treasures are left out (the "
                   "recorded trajectory stays in the hallway).")
