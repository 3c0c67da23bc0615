"""Pitfall!: Harry, the scene's wall or scorpion (RAM[29]: 0 the scorpion, 1 or 255 the wall, at
column RAM[99]), its logs (RAM[19] their pattern, RAM[98] the first's column), the ladder hole
and ladder, the swinging rope, the water hole and its crocodiles (the scene's kind RAM[20]) and
the ground's platforms: the floor below and the ground on either side of the scene's holes."""

import numpy as np
import jax.numpy as jnp

from stori_jax.objects.table import at, bit, obj, table, where


def _rope_columns():  # (sign, RAM[92], |drop|) -> the rope's column; float64, as OCAtari's
    theta = -0.0060223306193817605 + 0.003809046734072426 * np.arange(256.0)
    drop = np.arange(256.0)
    length = np.abs(drop[None, :] / np.cos(theta)[:, None])
    return jnp.asarray(np.stack([np.trunc(78 + (np.sin(theta) * sign)[:, None] * length)
                                 for sign in (-1, 1)]).astype(np.int32).reshape(-1))


ROPE_X = _rope_columns()
ROPE_SCENES = (2, 3, 6, 10, 11, 12, 14, 17)


@obj("Player")
def player(r):
    return r[:, 97], r[:, 105] + 72, 8, 21, True


@obj("Wall")
def wall(r):
    return r[:, 99], 148, 7, 32, (r[:, 29] == 1) | (r[:, 29] == 255)


@obj("Logs", 5)
def logs(r):
    pattern, x = r[:, 19:20], r[:, 98:99]
    crocodiles = r[:, 20:21] == 4
    apart = where(pattern == 1, 16, 32)
    xs = jnp.concatenate([where(pattern == 3, x + 1, (x + 1) % 160), (x + apart + 1) % 160,
                          (x + 65) % 160], 1)
    one = ((pattern == 0) | (pattern == 4)) & ~crocodiles
    count = where(one, 1, where((pattern == 1) | (pattern == 2), 2, where(pattern == 3, 3, 0)))
    y = jnp.concatenate([where(pattern == 3, 119, 118), 118 + 0 * x, 118 + 0 * x], 1)
    return xs, y, 6, 14, (jnp.arange(3) < count) & ~crocodiles


def _ladder(r):
    return (r[:, 20] == 0) | (r[:, 20] == 1)


@obj("StairPit")
def stair_pit(r):
    return 76, 122, 8, 6, _ladder(r)


@obj("Stair")
def stair(r):
    return 78, 136, 4, 42, _ladder(r)


@obj("Scorpion")
def scorpion(r):
    low = r[:, 65] == 160
    return (r[:, 99], where(low, 170, 169), where(low, 7, 8), where(low, 8, 9),
            r[:, 29] == 0)


@obj("Rope")
def rope(r):
    y = 116 - r[:, 18]
    drop = jnp.abs(y - 34)
    x = ROPE_X[(r[:, 93] > 16) * 65536 + r[:, 92] * 256 + drop]
    scene = r[:, 20]
    here = jnp.isin(scene, jnp.asarray(ROPE_SCENES)) | (
        (scene == 4) & ((r[:, 19] == 2) | (r[:, 19] == 3)))
    return x, y, 1, 1, here


@obj("Waterhole")
def waterhole(r):
    scene = r[:, 20]
    shrinking = scene == 7
    ram = at(r, range(32, 36))
    half = (ram == jnp.array([1, 3, 15, 127])).all(1)
    whole = (ram == jnp.array([0, 1, 3, 15])).all(1)
    x = where(shrinking & ~whole, where(half, 52, 0), 48)
    y = where(shrinking & ~whole, where(half, 121, 0), 120)
    w, h = where(shrinking & half & ~whole, 56, 64), where(shrinking & half & ~whole, 9, 10)
    return x, y, w, h, (scene == 3) | (scene == 4) | (shrinking & ~(ram == 255).all(1))


@obj("Crocodile", 3)
def crocodile(r):
    shut = r[:, 46:47] == 255
    return (jnp.array([60, 76, 92]), where(shut, 122, 119), 8, where(shut, 6, 9),
            r[:, 20:21] == 4)


@obj("Platform", 5)
def platform(r):  # the floor, then the ground pieces left to right
    scene = r[:, 20:21]
    tar = (scene == 5) | (scene == 6)
    open_ = tar & ~bit(r[:, 32:33], 7)
    widths = jnp.array([12, 8, 4, 4])
    gone = (~bit(at(r, range(33, 37)), 7) * widths).sum(1, keepdims=True)
    px, pw = 76 - gone, 8 + 2 * gone
    holes = (scene >= 2) & (scene <= 4)

    def pick(ladder, pits, hole, tarpit, closed):
        return where(scene == 0, ladder, where(scene == 1, pits, where(
            holes, hole, where(open_, tarpit, closed))))

    x = jnp.concatenate([8 + 0 * scene,
                         pick(8, 8, 8, 8, 8),
                         pick(84, 60, 112, px + pw, 0),
                         pick(0, 84, 0, 0, 0),
                         pick(0, 112, 0, 0, 0)], 1)
    w = jnp.concatenate([152 + 0 * scene,
                         pick(68, 40, 40, px - 7, 152),
                         pick(77, 16, 48, 160 - (px + pw), 0),
                         pick(0, 16, 0, 0, 0),
                         pick(0, 48, 0, 0, 0)], 1)
    h = jnp.array([1, 8, 8, 8, 8])
    y = jnp.array([180, 125, 125, 125, 125])
    low = scene <= 4
    here = jnp.concatenate([scene >= 0, low | tar,
                            low | open_, scene == 1, scene == 1], 1)
    return x, y, w, h, here


GAME = table("pitfall", player, wall, logs, stair_pit, stair, scorpion, rope, waterhole,
             crocodile, platform,
             notes="The pits, the snake, the tar pits, the fire and the treasures are left out "
                   "(none on the recorded trajectory; the platforms beside a tar pit are in).")
