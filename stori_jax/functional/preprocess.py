"""Observation preprocessing: max-pool of the last two screens, grayscale, area resize, stack.

Formulated for XLA on CPU: integer luma, static-index gathers with a few taps per output pixel
(exact area interpolation, as OpenCV's INTER_AREA), fused elementwise work.
"""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np

ATARI84 = 84
STACK = 4
DREAMER64 = 64


def max_pool(frames):
    """(B, 2, ...) -> (B, ...): elementwise max of the two screens."""
    return jnp.maximum(frames[:, 0], frames[:, 1])


def to_gray(rgb):
    """uint8 RGB (..., 3) -> uint8 luma (...,) with integer ITU-R 601 weights (77, 150, 29)/256."""
    rgb = rgb.astype(jnp.uint16)
    return ((rgb[..., 0] * 77 + rgb[..., 1] * 150 + rgb[..., 2] * 29 + 128) >> 8).astype(jnp.uint8)


@functools.lru_cache(maxsize=None)
def area_taps(in_size: int, out_size: int) -> tuple[np.ndarray, np.ndarray]:
    """(index (out, K) int32, weight (out, K) float32): output i averages the input interval
    [i * in/out, (i + 1) * in/out), each input cell weighted by its overlap."""
    scale = in_size / out_size
    rows = []
    for i in range(out_size):
        lo, hi = i * scale, (i + 1) * scale
        taps = []
        for j in range(int(np.floor(lo)), int(np.ceil(hi))):
            overlap = min(hi, j + 1) - max(lo, j)
            if overlap > 1e-9:
                taps.append((min(j, in_size - 1), overlap / scale))
        rows.append(taps)
    k = max(len(t) for t in rows)
    index = np.zeros((out_size, k), np.int32)
    weight = np.zeros((out_size, k), np.float32)
    for i, taps in enumerate(rows):
        for t, (j, w) in enumerate(taps):
            index[i, t], weight[i, t] = j, w
        index[i, len(taps):] = taps[-1][0]
    return index, weight


def _resize_axis(x, axis: int, out_size: int):
    index, weight = area_taps(x.shape[axis], out_size)
    shape = [1] * x.ndim
    shape[axis] = out_size
    out = None
    for t in range(index.shape[1]):
        term = jnp.take(x, jnp.asarray(index[:, t]), axis=axis) * weight[:, t].reshape(shape)
        out = term if out is None else out + term
    return out


def area_resize(image, height: int, width: int, *, y_axis: int, x_axis: int):
    """Exact area-average resize of uint8 images along (y_axis, x_axis); returns uint8."""
    x = image.astype(jnp.float32)
    x = _resize_axis(x, y_axis, height)
    x = _resize_axis(x, x_axis, width)
    return jnp.clip(jnp.round(x), 0, 255).astype(jnp.uint8)


def atari84_frame(frames):
    """(B, 2, 210, 160, 3) uint8 -> (B, 84, 84) uint8: gray each screen, max-pool, area resize."""
    gray = max_pool(to_gray(frames))
    return area_resize(gray, ATARI84, ATARI84, y_axis=1, x_axis=2)


def reset_stack(frame):
    """(B, 84, 84) -> (B, 84, 84, 4): the first frame of an episode repeated."""
    return jnp.repeat(frame[..., None], STACK, axis=-1)


def push_frame(stack, frame, new_episode):
    """Shift ``frame`` (B, 84, 84) into ``stack`` (B, 84, 84, 4); restart it where
    ``new_episode`` (B,) bool."""
    pushed = jnp.concatenate([stack[..., 1:], frame[..., None]], axis=-1)
    return jnp.where(new_episode[:, None, None, None], reset_stack(frame), pushed)


def dreamer64(frames):
    """(B, 2, 210, 160, 3) uint8 -> (B, 64, 64, 3) uint8: max-pool, area resize RGB."""
    return area_resize(max_pool(frames), DREAMER64, DREAMER64, y_axis=1, x_axis=2)
