"""Boxing: the two boxers (white: the player, black: the enemy)."""

from stori_jax.objects.table import obj, table


@obj("Player")
def player(r):
    return r[:, 32] + 5, r[:, 34] + 38, 14, 46, True


@obj("Enemy")
def enemy(r):
    return r[:, 33] + 4, r[:, 35] + 38, 14, 46, True


GAME = table("boxing", player, enemy)
