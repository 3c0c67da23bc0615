"""River Raid: the plane, its missile and the river's objects.  The river's six object slots
(RAM[32 + i] the kind: 4 a jet, 5 or 6 a helicopter, 7 a tanker, 8 a bridge, 9 a house, 10 a
fuel depot, below 4 nothing or an explosion) hold one object each, slot 0 the lowest on the
screen: its row is 32 * (5 - i) + RAM[11] (the scroll) less the kind's offset, its column
15 * RAM[20 + i] less the signed high nibble of RAM[26 + i] (and 6 more); an object is cut at
row 2 above and row 162 below, and one coming in at the top (slot 5) is shown once RAM[11] is
past its kind's entry row + 2."""

import jax.numpy as jnp

from stori_jax.objects.table import at, obj, table

SLOTS = 6


@obj("Player")
def player(r):
    return r[:, 51] + 1, 145, 7, 13, r[:, 58] != 0


@obj("PlayerMissile")
def player_missile(r):
    y = 162 - r[:, 50]
    return r[:, 117] - 1, y, 1, 8, (r[:, 117] != 0) & (y >= 0)


def _river(kinds, w, h, offset, entry):
    def boxes(r):
        kind = at(r, range(32, 32 + SLOTS))
        nibble = at(r, range(26, 26 + SLOTS)) >> 4
        x = 15 * at(r, range(20, 20 + SLOTS)) - jnp.where(nibble > 7, nibble - 16, nibble) + 6
        y = 32 * (5 - jnp.arange(SLOTS)) + r[:, 11:12] - offset
        cut = jnp.where(y + h >= 162, 163 - y, h)
        top = y <= 2
        cut = jnp.where(top, h + y - 2, cut)
        entered = 32 * (5 - jnp.arange(SLOTS)) + r[:, 11:12] - entry > 2
        here = jnp.isin(kind, jnp.asarray(kinds)) & (cut > 0) & entered
        return x, jnp.where(top, 2, y), w, cut, here
    return boxes


fuel_depot = obj("FuelDepot", 4)(_river((10,), 7, 24, 23, 0))
tanker = obj("Tanker", 4)(_river((7,), 17, 9, 13, 5))
helicopter = obj("Helicopter", 4)(_river((5, 6), 8, 10, 16, 6))
house = obj("House", 4)(_river((9,), 17, 20, 20, 1))

GAME = table("riverraid", player, player_missile, fuel_depot, tanker, helicopter, house,
             notes="Jets and bridges are left out (none on the recorded trajectory).  OCAtari "
                   "follows each object from the frame it comes in, so it keeps the height an "
                   "object was cut to at the top on later frames and orders a class by the slot "
                   "it gave each; here every box is the RAM's of its frame, lowest on the "
                   "screen first.")
