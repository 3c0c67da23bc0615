"""Kung-Fu Master: the player (its pose RAM[93] gives its size and shifts it, by the way it faces,
bit 3 of RAM[90]), the one enemy in front at column RAM[72] - 49 (while RAM[72] > 49; its kind
RAM[50]: 177 a henchman, the kinds not listed below a knife thrower) with up to two henchmen
behind it (bits 0 and 1 of RAM[63], 16 and 32 columns on), and the thrown knife (RAM[73],
RAM[96]; 188 none)."""

import jax.numpy as jnp

from stori_jax.objects.table import bit, obj, table, where

# the kinds of RAM[50] that are not a knife thrower (balls, snake, small enemies, henchman,
# dragon, smoke, final fighter, moth)
OTHER_KINDS = (85, 97, 134, 160, *range(70, 84), 177, 154, 188, 204, 227, 247)
# pose: (shift facing right (bit 3 of RAM[90] set), shift facing left, w, h)
POSES = ((0, -7, 15, 29), (-3, 0, 11, 29), (-2, -6, 16, 34), (-1, -5, 14, 34), (-3, -5, 16, 29))


@obj("Player")
def player(r):
    pose = r[:, 93]
    right, left, w, h = (jnp.asarray(v + (0,))[jnp.minimum(pose, 5)]
                         for v in zip(*POSES))
    w, h = where(pose < 5, w, 8), where(pose < 5, h, 34)
    return r[:, 74] - 49 + where(bit(r[:, 90], 3), right, left), r[:, 46] - 53, w, h, True


def _enemy(r):
    return r[:, 72] - 49, r[:, 72] > 49


@obj("Knife_Throwers")
def knife_throwers(r):
    x, here = _enemy(r)
    return x, 126, 8, 34, here & ~jnp.isin(r[:, 50], jnp.asarray(OTHER_KINDS))


@obj("Henchmen", 3)
def henchmen(r):  # the one in front, then the two behind
    x, here = _enemy(r)
    behind = jnp.stack([bit(r[:, 63], 0), bit(r[:, 63], 1)], 1) & here[:, None]
    return (x[:, None] + jnp.array([0, 16, 32]), 126, 8, 34,
            jnp.concatenate([(here & (r[:, 50] == 177))[:, None], behind], 1))


@obj("Knifes")
def knifes(r):
    final = r[:, 50] == 204
    return (r[:, 73] - where(final, 50, 52), where(final, 121, 123) + r[:, 96],
            where(final, 3, 5), where(final, 4, 2), (r[:, 96] != 188) & (r[:, 50] != 154))


GAME = table("kung_fu_master", player, knife_throwers, henchmen, knifes,
             notes="The other enemies (snake, dragon and its smoke, balls and fire, small "
                   "enemies, moth, final fighter) are left out (none on the recorded "
                   "trajectory).")
