"""Mario Bros.: Mario, the pests (four slots, their sprite RAM[107 + i] gives the box), the
fireball, the POW block, the bonus block, the platforms and, in the bonus stage (RAM[3] == 3),
the bonus coins."""

import jax.numpy as jnp

from stori_jax.objects.table import obj, table, where

# pest sprites: (first, last sprite number, dy from RAM[89 + i], w, h); others: dy 27, 9 x 9
PEST_SPRITES = (
    (128, 131, 27, 9, 10), (74, 75, 27, 9, 10), (68, 69, 27, 9, 10), (70, 73, 24, 9, 13),
    (144, 154, 21, 10, 17), (92, 92, 22, 10, 15), (94, 94, 20, 10, 17), (160, 161, 24, 9, 14),
    (162, 163, 25, 9, 11), (164, 165, 18, 9, 14), (166, 167, 20, 9, 11), (168, 169, 19, 9, 12),
    (170, 171, 25, 9, 11), (110, 110, 27, 9, 11), (108, 108, 24, 9, 15), (176, 177, 20, 10, 17),
    (114, 118, 24, 10, 13), (120, 122, 31, 10, 6), (124, 124, 34, 10, 3),
)
PLATFORMS = ((0, 57, 64), (96, 57, 68), (31, 95, 97), (0, 95, 16), (144, 95, 18), (0, 135, 48),
             (112, 135, 48))
COINS = ((136, 26), (151, 68), (98, 104), (148, 148), (16, 26), (1, 68), (54, 104), (4, 148))


def _bonus_stage(r):
    return r[:, 3] == 3


@obj("Player")
def player(r):
    return r[:, 44] - 6, r[:, 42] + 13, 9, where(r[:, 27] >= 128, 21, 24), True


@obj("Pest", 4)
def pest(r):
    sprite = r[:, 107:111]
    dy, w, h = jnp.full_like(sprite, 27), jnp.full_like(sprite, 9), jnp.full_like(sprite, 9)
    for first, last, d, ww, hh in reversed(PEST_SPRITES):  # the first match wins
        match = (first <= sprite) & (sprite <= last)
        dy, w, h = where(match, d, dy), where(match, ww, w), where(match, hh, h)
    return (r[:, 95:99] - 7, r[:, 89:93] + dy, w, h,
            (sprite != 0) & ~_bonus_stage(r)[:, None])


@obj("Fireball")
def fireball(r):  # on floor RAM[117] (0..3); elsewhere OCAtari's fixed box
    floor = r[:, 117]
    on = floor < 4
    return (where(on, r[:, 115] - 6, 154), where(on, jnp.array([30, 68, 108, 148])[floor % 4], 84),
            9, 14, ~_bonus_stage(r))


@obj("PowBlock")
def pow_block(r):
    return 72, 141, 16, 7, r[:, 121] > 0


@obj("BonusBlock")
def bonus_block(r):
    return r[:, 99] - 4, r[:, 93] + 26, 9, 12, (r[:, 111] != 0) & ~_bonus_stage(r)


@obj("Platform", len(PLATFORMS))
def platform(r):
    x, y, w = (jnp.array(v) for v in zip(*PLATFORMS))
    return x, y, w, 3, True


@obj("BonusCoin", 8)
def bonus_coin(r):
    x, y = (jnp.array(v) for v in zip(*COINS))
    here = jnp.concatenate([r[:, 101:105], r[:, 107:111]], axis=1) > 0
    return x, y, 9, 13, here & _bonus_stage(r)[:, None]


GAME = table("mario_bros", player, pest, fireball, pow_block, bonus_block, platform, bonus_coin)
