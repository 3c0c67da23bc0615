"""Donkey Kong: Mario, Donkey Kong, the girlfriend, the hammer, the barrels, the ladders."""

import jax.numpy as jnp

from stori_jax.objects.table import at, obj, table, where

LADDERS = ((108, 176), (48, 148), (80, 148), (88, 120), (108, 120), (48, 92), (68, 92),
           (108, 64), (76, 40), (32, 40))


@obj("Player")
def player(r):
    jumping = (1 < r[:, 11]) & (r[:, 11] < 255)
    return r[:, 19] - 4, r[:, 27] + where(jumping, 24, 22), 8, where(jumping, 15, 17), True


@obj("DonkeyKong")
def donkey_kong(r):
    return 34, 15, 16, 19, True


@obj("Girlfriend")
def girlfriend(r):
    return 63, 18, 8, 16, True


@obj("Hammer")
def hammer(r):  # gone while Mario holds it (RAM[21] == RAM[23] == 112)
    return 39, 68, 4, 7, ~((r[:, 21] == 112) & (r[:, 23] == 112))


@obj("Barrel", 4)
def barrel(r):
    y = at(r, range(4))
    return at(r, range(65, 69)) - 4, y + 40, 8, 8, y != 0


@obj("Ladder", len(LADDERS))
def ladder(r):
    return jnp.array([x for x, _ in LADDERS]), jnp.array([y for _, y in LADDERS]), 4, 17, True


GAME = table("donkey_kong", player, donkey_kong, girlfriend, hammer, barrel, ladder,
             notes="Hammer: OCAtari keeps the hammer where it first saw it; here it is at its "
                   "place on the girders, (39, 68), whenever Mario does not hold it.")
