"""Double Dunk: each team's small and big player, the ball, the basket and the backboard."""

from stori_jax.objects.table import obj, table


def _player(x, y, top, h):
    return lambda r: (r[:, x] + 11, top - r[:, y], 8, h, True)


player_small = obj("Player_Small")(_player(39, 35, 163, 19))
player_big = obj("Player_Big")(_player(37, 33, 159, 23))
opponent_small = obj("Opponent_Small")(_player(40, 36, 163, 19))
opponent_big = obj("Opponent_Big")(_player(38, 34, 159, 23))


@obj("Ball")
def ball(r):
    return r[:, 47] + 12, 178 - r[:, 46], 4, 4, True


@obj("Basket")
def basket(r):
    return 76, 42, 8, 9, True


@obj("Backboard")
def backboard(r):
    return 68, 28, 24, 16, True


GAME = table("double_dunk", player_small, player_big, opponent_small, opponent_big, ball,
             basket, backboard)
