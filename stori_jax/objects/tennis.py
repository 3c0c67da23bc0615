"""Tennis: the two players (the orange player is on the side RAM[80] says), the ball and its
shadow (both hidden behind the net)."""

from stori_jax.objects.table import obj, table, where


def _side(r, up):  # RAM[80]: 0 while the player plays from the top half
    top = r[:, 80] == 0
    return (where(top == up, r[:, 26], r[:, 27]) - 1,
            166 - where(top == up, r[:, 24], r[:, 25]), 13, 23, True)


@obj("Player")
def player(r):
    return _side(r, True)


@obj("Enemy")
def enemy(r):
    return _side(r, False)


def _ball_y(r):
    return 189 - r[:, 54]


@obj("Ball")
def ball(r):
    y = _ball_y(r)
    return r[:, 16] - 2, y, 2, 2, (r[:, 16] > 2) & ~((98 < y) & (y < 113))


@obj("BallShadow")
def ball_shadow(r):
    y = 189 - r[:, 55]
    hidden = ((100 < y) & (y < 113)) | (y == _ball_y(r)) | (y == 0)
    return r[:, 16] - 2, y, 2, 2, (r[:, 16] > 2) & ~hidden


GAME = table("tennis", player, enemy, ball, ball_shadow)
