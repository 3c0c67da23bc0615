"""Phoenix: the player's ship and its shot, the phoenixes (the first waves: four on the left,
RAM[99..102], four on the right, RAM[103..106], row by row RAM[41..44]) and the enemy shots
(RAM[58..61] their heights, RAM[80..83] their columns as a coarse / fine byte)."""

import jax.numpy as jnp

from stori_jax.objects.table import at, obj, table, where


@obj("Player")
def player(r):
    return r[:, 94] - 70, 173, 7, 10, True


@obj("Player_Projectile")
def player_projectile(r):  # RAM[84] == 0: the shot is the player's to fire or in flight
    return r[:, 93] - 71, 201 - r[:, 89], 1, 6, r[:, 84] == 0


def _phoenix_wave(r):  # RAM[11]: not the boss; bit 6 of RAM[27]: phoenixes, not bats
    return (r[:, 11:12] != 0) & ((r[:, 27:28] & 64) != 0)


@obj("Phoenix", 8)
def phoenix(r):  # the left four, then the right four; type bits 1 and 2 both set: none
    x = jnp.concatenate([at(r, range(99, 103)), at(r, range(103, 107))], axis=1) - 70
    y = 204 - jnp.tile(at(r, range(41, 45)), 2)
    kind = jnp.concatenate([at(r, range(27, 31)), at(r, range(34, 38))], axis=1)
    return x, y, 8, 8, _phoenix_wave(r) & (kind & 6 != 6)


@obj("Enemy_Projectile", 4)
def enemy_projectile(r):
    v = at(r, range(80, 84))
    fine, coarse = v >> 4, v & 15
    x = 5 + (coarse - 3) * 15 + where(fine & 8 != 0, (fine ^ 15) + 1, -fine)
    height = at(r, range(58, 62))
    return x, 189 - height, 1, 6, height < 250


GAME = table("phoenix", player, player_projectile, phoenix, enemy_projectile,
             notes="Only the phoenix waves: the bats and the boss with its blocks never appear "
                   "on the recorded trajectory, so they are left out.  The player's shot is "
                   "present while RAM[84] == 0 (OCAtari keeps it at its last box otherwise); "
                   "the fourth enemy shot (RAM[61]) is here too, where OCAtari overwrites it "
                   "with the first phoenix.")
