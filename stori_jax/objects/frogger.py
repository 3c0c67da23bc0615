"""Frogger: the frog (column RAM[48], row RAM[44]: 255 the start, 5 the middle bank) and the
cars of the road's five lanes, bottom lane first (lane 1: RAM[11], RAM[0]; lane 2: RAM[12],
RAM[1]; lane 3: RAM[13], RAM[13] + 32, RAM[2], RAM[13] + 112; lane 4: RAM[14], RAM[3]; lane 5,
the trucks: RAM[15], RAM[4]).  A car is cut at column 8 on the left and at the right edge; a
car cut to nothing is no car."""

import jax.numpy as jnp

from stori_jax.objects.table import obj, table, where

CAR_Y = jnp.array([161, 161, 148, 148, 135, 135, 135, 135, 122, 122])
CAR_W = jnp.array([8, 8, 7, 7, 8, 8, 8, 8, 8, 8])
CUT_FROM = jnp.array([146, 146] + [147] * 8)  # a car at a column past this is cut on the right


@obj("Frog")
def frog(r):
    row = r[:, 44]
    return (r[:, 48] - 1, where(row == 255, 171, where(row == 5, 95, 161 - 13 * row)), 7, 7,
            True)


def _cars(r):  # lanes 1 to 4: (B, 10) positions
    lane3 = r[:, 13]
    return jnp.stack([r[:, 11], r[:, 0], r[:, 12], r[:, 1], lane3, (lane3 + 32) % 160, r[:, 2],
                      (lane3 + 112) % 160, r[:, 14], r[:, 3]], 1)


@obj("Car", 26)
def car(r):
    pos = _cars(r)
    x = where(pos < 8, 8, pos - 1)
    w = where(pos < 8, pos - 1, where(pos > CUT_FROM, 153 - pos, CAR_W))
    here = (1 <= pos) & (pos <= 154)
    truck = jnp.stack([r[:, 15], r[:, 4]], 1)
    tx = where((truck < 8) | (truck > 155), 8, truck)
    tw = where(truck < 8, truck + 7,
               where(truck > 155, truck - 153, where(truck > 137, 152 - truck, 16)))
    x, w = jnp.concatenate([x, tx], 1), jnp.concatenate([w, tw], 1)
    here = jnp.concatenate([here, jnp.ones_like(truck, bool)], 1) & (w > 0)
    return x, jnp.concatenate([CAR_Y, jnp.array([109, 109])]), w, 7, here


GAME = table("frogger", frog, car,
             notes="The river's logs, turtles and alligators, the lady frog, fly, snakes and "
                   "the frogs home are left out (none on the recorded trajectory).  OCAtari "
                   "lists 26 cars of which 14 it never places (always at (0, 0)), keeps a car "
                   "that has left the road at its last box and gives cars cut to nothing a "
                   "width of 0 or less; here a car is there exactly while the RAM puts it on "
                   "the road.")
