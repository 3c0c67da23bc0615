"""Type 3.2 screen masks: crop (halves and torch) and blackout of a game's regions."""

from __future__ import annotations

from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from stori_jax.checks import (check_bool, check_draw_probability, check_dtype, shown,
                              unless_traced)
from stori_jax.games.base import (CROP_REGIONS, SCREEN_HEIGHT, SCREEN_WIDTH,  # noqa: F401
                                  TORCH_MODE, TORCH_RADIUS, Region)


def region_mask(regions: Sequence[Region]) -> tuple[np.ndarray, np.ndarray]:
    """Static (hidden (210, 160) bool, fill (210, 160, 3) uint8), regions painted in order."""
    regions = list(regions) if not isinstance(regions, Region) else [regions]
    for r in regions:
        if not isinstance(r, Region):
            raise ValueError(f"region_mask takes Regions (a game's CROP_REGIONS[mode], "
                             f"blackout_regions or the like), got {shown(r)}")
    hidden = np.zeros((SCREEN_HEIGHT, SCREEN_WIDTH), bool)
    fill = np.zeros((SCREEN_HEIGHT, SCREEN_WIDTH, 3), np.uint8)
    for r in regions:
        hidden[r.y0:r.y1 + 1, r.x0:r.x1 + 1] = True
        fill[r.y0:r.y1 + 1, r.x0:r.x1 + 1] = r.fill
    return hidden, fill


def _check_shape(name: str, array, expected: tuple) -> tuple:
    """``array``'s shape if it matches ``expected`` (a name there: any size), else a
    ValueError."""
    shape = tuple(np.shape(array))
    if len(shape) != len(expected) or any(isinstance(e, int) and s != e
                                          for s, e in zip(shape, expected)):
        wanted = "(" + ", ".join(str(e) for e in expected) + ")"
        raise ValueError(f"{name} must have shape {wanted}, got {shape}")
    return shape


def torch_mask(centres: jax.Array) -> jax.Array:
    """hidden (..., 210, 160) bool: pixels farther than 75 from centre (x, y) (int32 (..., 2))."""
    check_dtype("centres", centres, "iu", "integer pixel coordinates (x, y)")
    if np.ndim(centres) < 1 or np.shape(centres)[-1] != 2:
        raise ValueError(f"centres must have shape (..., 2) (x, y per torch), got "
                         f"{tuple(np.shape(centres))}")
    cx = centres[..., 0, None, None]
    cy = centres[..., 1, None, None]
    ys = jnp.arange(SCREEN_HEIGHT, dtype=jnp.int32)[:, None]
    xs = jnp.arange(SCREEN_WIDTH, dtype=jnp.int32)[None, :]
    return (xs - cx) ** 2 + (ys - cy) ** 2 > TORCH_RADIUS ** 2


def draw_mask_decisions(keys: jax.Array, *, prob: float, per_frame: bool, torch: bool):
    """Per env, for the two screens that make an observation: apply? (B, 2) bool and torch
    centres (B, 2, 2) int32 (x in [0,160), y in [0,210)).  At step granularity
    (``per_frame=False``) one draw covers both screens."""
    prob = unless_traced(check_draw_probability, "prob", prob)
    per_frame, torch = check_bool("per_frame", per_frame), check_bool("torch", torch)
    n = 2 if per_frame else 1

    def one_env(key):
        k_apply, k_x, k_y = jax.random.split(key, 3)
        apply = jax.random.uniform(k_apply, (n,), jnp.float32) < prob
        cx = jax.random.randint(k_x, (n,), 0, SCREEN_WIDTH, jnp.int32)
        cy = jax.random.randint(k_y, (n,), 0, SCREEN_HEIGHT, jnp.int32)
        centres = jnp.stack([cx, cy], axis=-1)
        if n == 1:
            apply, centres = jnp.repeat(apply, 2, 0), jnp.repeat(centres, 2, 0)
        return apply, centres if torch else jnp.zeros_like(centres)

    return jax.vmap(one_env)(keys)


def apply_masks(frames: jax.Array, apply: jax.Array, *, hidden: np.ndarray | None = None,
                fill: np.ndarray | None = None, centres: jax.Array | None = None) -> jax.Array:
    """Mask frames (B, S, 210, 160, 3) where ``apply`` (B, S) (S screens per env, usually the 2
    pooled into an observation): either the static ``hidden`` (210, 160) region with ``fill``
    (210, 160, 3), or the torch at ``centres`` (B, S, 2) (everything outside black)."""
    given = [value is not None for value in (hidden, fill, centres)]
    if given not in ([True, True, False], [False, False, True]):
        raise ValueError("apply_masks takes either hidden= and fill= (a static region) or "
                         "centres= (the torch), got "
                         + ", ".join(f"{name}={'None' if value is None else '...'}" for name, value
                                     in (("hidden", hidden), ("fill", fill),
                                         ("centres", centres))))
    b, s = _check_shape("frames", frames, ("B", "S", SCREEN_HEIGHT, SCREEN_WIDTH, 3))[:2]
    _check_shape("apply", apply, (b, s))
    check_dtype("apply", apply, "b", f"bools ({b}, {s}) (where to mask; an int would be "
                "combined bit by bit)")
    check_dtype("frames", frames, "B", "uint8 RGB screens")
    if centres is not None:
        _check_shape("centres", centres, (b, s, 2))
        pixel_hidden = torch_mask(centres) & apply[:, :, None, None]
        return jnp.where(pixel_hidden[..., None], jnp.uint8(0), frames)
    _check_shape("hidden", hidden, (SCREEN_HEIGHT, SCREEN_WIDTH))
    _check_shape("fill", fill, (SCREEN_HEIGHT, SCREEN_WIDTH, 3))
    check_dtype("hidden", hidden, "b", "bools (region_mask's first array)")
    check_dtype("fill", fill, "B", "uint8 colours (region_mask's second array)")
    pixel_hidden = jnp.asarray(hidden)[None, None] & apply[:, :, None, None]
    return jnp.where(pixel_hidden[..., None], jnp.asarray(fill)[None, None], frames)
