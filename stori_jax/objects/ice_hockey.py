"""Ice Hockey: the two players of each team and the puck."""


from stori_jax.objects.table import at, obj, table


def _skaters(xs, ys):
    return lambda r: (at(r, xs) - 13, 168 - at(r, ys), 16, 20, True)


player = obj("Player", 2)(_skaters((59, 57), (55, 53)))
enemy = obj("Enemy", 2)(_skaters((60, 58), (56, 54)))


@obj("Ball")
def ball(r):
    return r[:, 52] - 10, 188 - r[:, 91], 2, 2, True


GAME = table("ice_hockey", player, enemy, ball)
