"""Private Eye: the detective, his car and the clue.

RAM[58] is the car's heading (1 or 5: seen end on, the detective riding on its roof; 49: to the
left, 121: to the right), RAM[63] its column, RAM[88] (end on) or RAM[84] (sideways) its
height: high bit clear, ``150 - value / 4`` above the road; set, the car has dropped below it."""

from stori_jax.objects.table import obj, table, where


def _end_on(r):
    return (r[:, 58] == 1) | (r[:, 58] == 5)


def _top(r, v, heading):  # top row of the car (+ 0) from its height byte ``v``
    up = where(heading == 5, 136 + (v >> 3), 163 - (v >> 2))
    return where(v >= 128, 132 + ((v - 128) >> 2), up)


@obj("Player")
def player(r):  # on the car's roof while it is seen end on
    riding = _top(r, r[:, 88], r[:, 58]) - 14
    y = where(_end_on(r), riding, 150 - r[:, 97])
    return r[:, 63], y, 8, where(r[:, 97] == 0, 12, 25), True


@obj("Car")
def car(r):
    end_on = _end_on(r)
    y = where(end_on, _top(r, r[:, 88], r[:, 58]), _top(r, r[:, 84], 0))
    x = r[:, 63] - where(end_on, 0, where(r[:, 58] == 49, 3, 9))
    return x, y, where(end_on, 8, 20), 14, True


@obj("Clue")
def clue(r):
    return 15 + r[:, 49], 169 - r[:, 40], 8, 14, (r[:, 43] == 30) | (r[:, 43] == 31)


GAME = table("private_eye", player, car, clue,
             notes="Only the detective, the car and the clue: the scenery and items OCAtari "
                   "lists (mud, bricks, doves, the bad guy, the items to return ...) never "
                   "appear on the recorded trajectory, so they are left out.")
