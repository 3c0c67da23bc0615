"""Battle Zone: the player's tank (the view's lower frame), the first enemy (a blue tank, whose
box depends on its sprite RAM[46]), the crosshair, the radar and the enemy on the radar."""

import jax.numpy as jnp

from stori_jax.objects.table import obj, table

# the blue tank's sprite RAM[46] -> (dx, dy, dw, dh) on the box (RAM[48] + 1, 97 - RAM[47], 16, 10)
TANK_SPRITES = {6: (3, -1, -12, -6), 7: (2, -1, -11, -6), 11: (1, -1, -10, -6),
                12: (-1, -1, -8, -5), 13: (-1, -1, -8, -5), 18: (4, 0, -4, -3),
                21: (0, 0, -5, -1), 26: (0, 0, -4, 0), 27: (4, 0, -4, 0), 28: (2, 0, -2, 0),
                30: (12, 0, 4, 0), 32: (2, 0, -2, 0), 33: (0, 0, 0, 5), 34: (0, 0, 0, 4),
                35: (7, 0, 4, 4), 36: (9, 0, 8, 4), 39: (0, 0, 0, 6), 40: (0, 0, 0, 6),
                41: (12, 0, 4, 7), 46: (12, 0, 4, 7)}


def _sprite_table():
    out = [[0, 0, 0, 0] for _ in range(256)]
    for sprite, d in TANK_SPRITES.items():
        out[sprite] = list(d)
    return jnp.array(out, jnp.int32)


@obj("Player")
def player(r):
    return 19, 140, 122, 38, True


@obj("Blue_Tank")
def blue_tank(r):
    d = _sprite_table()[r[:, 46]]
    here = (r[:, 73] == 1) & (r[:, 48] > 0) & (r[:, 46] > 0)
    return (r[:, 48] + 1 + d[:, 0], 97 - r[:, 47] + d[:, 1], 16 + d[:, 2], 10 + d[:, 3],
            here)


@obj("Crosshair")
def crosshair(r):
    return 78, 79, 1, 6, True


@obj("Radar")
def radar(r):
    return 74, 3, 22, 33, True


@obj("Radar_Content", 10)
def radar_content(r):
    y = r[:, 82:83]  # one enemy on the radar (OCAtari's 10 slots: one used)
    return 94 - r[:, 74:75] // 9, 34 - y, 7, 7, y != 255


GAME = table("battle_zone", player, blue_tank, crosshair, radar, radar_content,
             notes="Only the first enemy, as a blue tank (RAM[73] == 1): the second enemy "
                   "(RAM[81]) and the other kinds OCAtari has (the yellow-blue tank, the red "
                   "saucer, the boss) never appear on the recorded trajectory, so they are left "
                   "out.  The crosshair is on screen on every frame; OCAtari drops it once the "
                   "first enemy takes its place in its object list.")
