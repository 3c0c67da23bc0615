"""Bowling: the bowler, the ball and the ten pins (knocked-down pins are gone)."""

from stori_jax.objects.table import at, obj, table, where


@obj("Player")
def player(r):
    return r[:, 29] + 8, 139 - 2 * (r[:, 40] - 1), 8, 32, True


@obj("Ball")
def ball(r):
    return r[:, 30] + 7, 161 - 2 * (r[:, 41] - 1), 4, 10, True


@obj("Pin", 10)
def pin(r):
    column, row = at(r, range(57, 67)), at(r, range(47, 57))
    x = where(column <= 120, 126 - 2 * column, 255) + 9
    return x, 169 - 2 * row, 2, 4, column < 250


GAME = table("bowling", player, ball, pin)
