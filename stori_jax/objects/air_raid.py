"""Air Raid: the player's ship, the buildings (two, plus the part of one that wraps round the
left edge), the enemies by kind (RAM[63 + i]: 0-1, 2-3, 4-5, 6-7 are the 25, 50, 75 and 100
point ships) and the two missiles (the player's, the enemies')."""

import jax.numpy as jnp

from stori_jax.objects.table import at, obj, table, where

# a building's damage (RAM[27], RAM[28]) -> its top and height
Y_BY_DAMAGE = (178, 181, 181, 181, 183, 187, 189, 191, 195, 191, 187, 185, 185, 202, 178)
H_BY_DAMAGE = (32, 29, 29, 29, 27, 23, 21, 19, 15, 19, 23, 25, 25, 8, 32)


@obj("Player")
def player(r):
    grey = r[:, 84] != 248
    return r[:, 19] - 3, 157 - grey, 14, 12, True


@obj("Building", 3)
def building(r):
    x0 = at(r, (20, 21))
    damage = jnp.clip(at(r, (27, 28)), 0, len(Y_BY_DAMAGE) - 1)
    x = where(x0 > 3, x0 - 3, x0 + 156)
    y, h = jnp.array(Y_BY_DAMAGE)[damage], jnp.array(H_BY_DAMAGE)[damage]
    w = jnp.minimum(32, 160 - x)
    wraps = x > 128
    k = where(wraps[:, 0], 0, 1)  # the wrapped part is the first building's, if it wraps
    pick = lambda v: jnp.take_along_axis(v, k[:, None], axis=1)[:, 0]
    zero = jnp.zeros_like(k)
    return (jnp.stack([x[:, 0], x[:, 1], zero], 1), jnp.stack([y[:, 0], y[:, 1], pick(y)], 1),
            jnp.stack([w[:, 0], w[:, 1], 32 - pick(w)], 1),
            jnp.stack([h[:, 0], h[:, 1], pick(h)], 1),
            jnp.stack([zero == 0, zero == 0, wraps.any(1)], 1))


def _enemies(kinds, x_offsets, w, h_max, middle_shift):
    def boxes(r):
        y = 195 - at(r, range(29, 32))
        x = at(r, range(66, 69)) - 3 + jnp.array(x_offsets) + (
            jnp.array([0, 1, 0]) if middle_shift else 0)
        kind = at(r, range(63, 66))
        shown = (at(r, range(29, 32)) != 44) & (at(r, range(78, 81)) != 236)
        return x, y, w, jnp.minimum(h_max, 151 - y), shown & ((kind == kinds[0]) | (kind == kinds[1]))
    return boxes


enemy25 = obj("Enemy25", 3)(_enemies((0, 1), (2, 0, 0), 16, 18, False))
enemy50 = obj("Enemy50", 3)(_enemies((2, 3), (0, -1, 0), 14, 16, True))
enemy75 = obj("Enemy75", 3)(_enemies((4, 5), (2, 1, 2), 14, 16, True))
enemy100 = obj("Enemy100", 3)(_enemies((6, 7), (0, 1, 0), 14, 14, True))


@obj("Missile", 2)
def missile(r):  # the player's, then the enemies'
    py, ey = r[:, 85], r[:, 83]
    return (jnp.stack([r[:, 86], r[:, 84]], 1) - 5, jnp.stack([194 - py, 193 - ey], 1), 2, 2,
            jnp.stack([(py != 35) & (py != 34), (ey != 0) & (ey != 248)], 1))


GAME = table("air_raid", player, building, enemy25, enemy50, enemy75, enemy100, missile)
