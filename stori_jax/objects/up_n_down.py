"""Up'n Down: four RAM slots (kind RAM[36 + i], x RAM[40 + i], y RAM[56 + i] + 16), each the
player's buggy (kind 16), a truck (kinds 0..7, the box trimmed per kind), a flag (8..15) or a
collectable (24..30)."""

import jax.numpy as jnp

from stori_jax.objects.table import at, obj, table

# truck kind -> (dx, dy, dw, dh) of its box against 16 x 16
TRUCK_TRIM = ((0, 0, 0, 0), (2, 0, -2, 0), (0, 1, 0, -1), (0, 0, 0, 0), (0, 0, 0, 0),
              (0, 0, -2, 0), (0, 2, 0, -2), (0, 0, 0, 0))


def _slots(r):
    return at(r, range(36, 40)), at(r, range(40, 44)), at(r, range(56, 60)) + 16


@obj("Player")
def player(r):
    kind, x, y = _slots(r)
    return x, y, 16, 16, kind == 16


@obj("Truck", 4)
def truck(r):
    kind, x, y = _slots(r)
    trim = jnp.array(TRUCK_TRIM)[jnp.clip(kind, 0, 7)]
    return (x + trim[..., 0], y + trim[..., 1], 16 + trim[..., 2], 16 + trim[..., 3], kind < 8)


@obj("Flag", 4)
def flag(r):
    kind, x, y = _slots(r)
    return x, y - 1, 7, 16, (kind >= 8) & (kind < 16)


@obj("Collectable", 4)
def collectable(r):
    kind, x, y = _slots(r)
    return x, y - 1, 7, 16, (kind > 23) & (kind < 31)


GAME = table("up_n_down", player, truck, flag, collectable)
