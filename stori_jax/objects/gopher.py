"""Gopher: the farmer, the gopher, the three carrots, the holes in the field, the floor, the bird.

Holes: six columns (x = 12, 28, 44, 108, 124, 140), each dug in three layers (y = 176, 169,
161) whose bits are in RAM 0..17 (HOLE_LAYERS).  A hole's box spans the layers dug from the top
one down, as OCAtari builds it: 176 alone (8 x 7); 169 (8 x 14 with 176 below, else 8 x 7); 161
(8 x 22 when 169 and 176 are dug, 8 x 15 when only 169 is, 8 x 8 alone).
"""

import jax.numpy as jnp

from stori_jax.objects.table import obj, table, where


def _pair_odd(a, b, mod=None):  # (a mod m) odd and b odd
    return lambda r: ((r[:, a] % (mod or 256)) % 2 == 1) & (r[:, b] % 2 == 1)


def _both_bits(a, mod=None):  # bits 3 and 4 of (a mod m)
    return lambda r: ((r[:, a] % (mod or 256)) & 24) == 24


def _odd_and_top(a, b):  # (a mod 127) odd and bit 7 of b
    return lambda r: ((r[:, a] % 127) % 2 == 1) & ((r[:, b] & 128) == 128)


# column x -> its (176, 169, 161) layer conditions, in OCAtari's slot order
HOLE_LAYERS = (
    (12, (_odd_and_top(12, 13), _odd_and_top(6, 7), _odd_and_top(0, 1))),
    (28, (_both_bits(13, 127), _both_bits(7, 127), _both_bits(1, 127))),
    (44, (_pair_odd(13, 14, 128), _pair_odd(7, 8, 128), _pair_odd(1, 2, 128))),
    (108, (_both_bits(16), _both_bits(10), _both_bits(4))),
    (124, (_pair_odd(16, 17), _pair_odd(10, 11), _pair_odd(4, 5))),
    (140, (_both_bits(17), _both_bits(11), _both_bits(5))),
)


@obj("Player")
def player(r):
    return r[:, 31] - 10, 96, 11, 50, True


@obj("Gopher")
def gopher(r):
    x, up = r[:, 41], r[:, 85]
    low, peek = up <= 5, up == 35
    flat = low | peek
    return (where(flat, x - 2, x - 3), where(low, 184, where(peek, 149, 184 - up)),
            where(flat, 14, 7), where(flat, 10, 23), True)


@obj("Carrot", 3)
def carrot(r):
    return jnp.array([92, 76, 60]), 151, 8, 27, (r[:, 52:53] >> jnp.arange(3)) & 1 == 1


@obj("Hole", 6)
def hole(r):
    d176, d169, d161 = (jnp.stack([layers[k](r) for _, layers in HOLE_LAYERS], axis=1)
                        for k in range(3))
    h = where(d176, 7, 0)
    h = where(d169, where(d176, 14, 7), h)
    h = where(d161, where(d169 | d176, where(h > 13, 22, 15), 8), h)
    y = where(d161, 161, where(d169, 169, 176))
    return jnp.array([x for x, _ in HOLE_LAYERS]), y, 8, h, d176 | d169 | d161


@obj("Floor")
def floor(r):
    return 0, 183, 150, 12, True


@obj("Bird")
def bird(r):  # the duck that drops seeds
    x = r[:, 28]
    return x - 12, 30, 15, 18, x < 147


GAME = table("gopher", player, gopher, carrot, hole, floor, bird,
             notes="Bird: OCAtari 2.2.1 never reports it (the Bird it makes is not put in its "
                   "object list); the box here is the one its code means: x = RAM[28] - 12, "
                   "y = 30, present while RAM[28] < 147.")
