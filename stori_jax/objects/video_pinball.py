"""Video Pinball: the flippers, the ball, the spinners, the drop targets and the bumpers."""

import jax.numpy as jnp

from stori_jax.objects.table import at, obj, table, where

BUMPERS = ((104, 112, 16, 32), (104, 48, 4, 32), (116, 48, 4, 32), (40, 112, 16, 32),
           (40, 48, 4, 32), (52, 48, 4, 32), (72, 104, 16, 8), (72, 48, 16, 32))
# drop target -> (x, y, w, h) and the RAM byte saying it stands (non-zero)
DROP_TARGETS = ((60, 24, 7, 14), (76, 24, 7, 14), (92, 24, 7, 14), (47, 58, 3, 12),
                (79, 58, 3, 12), (109, 58, 7, 12), (47, 122, 3, 12), (77, 122, 7, 12),
                (111, 122, 3, 12), (60, 154, 7, 12), (76, 154, 7, 12), (92, 154, 7, 12))
DROP_TARGET_RAM = (72, 73, 74, 75, 76, 77, 81, 82, 83, 84, 85, 86)


def _columns(rows):
    return tuple(jnp.array([row[k] for row in rows]) for k in range(4))


@obj("Flipper", 2)
def flipper(r):  # left (RAM[98]: 0 down, 16..48 up), right (RAM[102]: 128 down, 144..176 up)
    down = jnp.stack([r[:, 98] == 0, r[:, 102] == 128], 1)
    return jnp.array([64, 83]), where(down, 184, 181), 13, where(down, 6, 9), True


@obj("Ball")
def ball(r):
    return r[:, 67], r[:, 68] - 3, 2, 4, True


@obj("Spinner", 2)
def spinner(r):
    return jnp.array([30, 126]), 91, 6, 10, True


@obj("DropTarget", len(DROP_TARGETS))
def drop_target(r):
    return (*_columns(DROP_TARGETS), at(r, DROP_TARGET_RAM) != 0)


@obj("Bumper", len(BUMPERS))
def bumper(r):
    return (*_columns(BUMPERS), True)


GAME = table("video_pinball", flipper, ball, spinner, drop_target, bumper,
             notes="OCAtari 2.2.1 lists Fishing Derby's classes (Player1FishingString, Fish, "
                   "...) as Video Pinball's and never reports them; they are left out.")
