"""Pong: the two paddles and the ball."""

from stori_jax.objects.table import obj, table, where

BALL_X, BALL_Y, ENEMY_Y, PLAYER_Y = 49, 54, 50, 51


@obj("Player")
def player(r):  # the right paddle; clipped at the top and bottom walls
    y = r[:, PLAYER_Y]
    top, bottom = y < 47, y > 192
    return (140, where(top, 34, y - 13), 4, where(top, y - 33, where(bottom, 207 - y, 15)),
            y > 13)


@obj("Ball")
def ball(r):
    x, y = r[:, BALL_X], r[:, BALL_Y]
    return x - 49, y - 14, 2, 4, (y != 0) & (x > 49)


@obj("Enemy")
def enemy(r):  # the left paddle
    y = r[:, ENEMY_Y]
    top, bottom = y < 49, y > 194
    return (16, where(top, 34, y - 15), 4, where(top, y - 33, where(bottom, 209 - y, 15)),
            y > 33)


GAME = table("pong", player, ball, enemy)
