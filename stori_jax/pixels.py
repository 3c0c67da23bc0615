"""The frame work of one env in numpy: what an emulating process does to its own screens.

Bit-identical twins of ``stori_jax.functional.preprocess`` (max-pool, integer luma, exact area
resize; tests/test_functional_preprocess.py compares them), for the processes that emulate:
they import numpy only (no JAX), so a worker starts fast.  The integer facts both share (the
luma weights, the area-resize taps) live here, once.

Exactness: every intermediate value is an integer below 2**24, so float32 arithmetic (and the
BLAS matrix product, in whatever order it sums) computes it exactly.
"""

from __future__ import annotations

import functools

import numpy as np

LUMA_WEIGHTS = (77, 150, 29)  # ITU-R 601 luma in units of 1/256, rounded half up
ATARI84 = 84
DREAMER64 = 64
# how a backend hands over its frames (see stori_jax.functional.preprocess.pool_screens):
# the two last screens, the max-pooled screen (HWC or CHW), or the observation itself
SCREEN_LAYOUTS = ("pair", "pooled", "pooled_chw")


@functools.lru_cache(maxsize=None)
def area_taps(in_size: int, out_size: int) -> tuple[np.ndarray, np.ndarray]:
    """(index (out, K) int32, weight (out, K) int32): output i averages the input interval
    [i * in/out, (i + 1) * in/out); input cell j weighs its overlap with it, in units of 1/out,
    so every weight is an integer and each row sums to ``in_size``."""
    rows = []
    for i in range(out_size):
        lo, hi = i * in_size, (i + 1) * in_size  # the interval, scaled by out_size
        taps = [(j, min(hi, (j + 1) * out_size) - max(lo, j * out_size))
                for j in range(lo // out_size, -(-hi // out_size))]
        rows.append([(j, w) for j, w in taps if w > 0])
    k = max(len(t) for t in rows)
    index = np.zeros((out_size, k), np.int32)
    weight = np.zeros((out_size, k), np.int32)
    for i, taps in enumerate(rows):
        for t, (j, w) in enumerate(taps):
            index[i, t], weight[i, t] = j, w
        index[i, len(taps):] = taps[-1][0]
    return index, weight


@functools.lru_cache(maxsize=None)
def _taps(in_size: int, out_size: int, axis: int, ndim: int):
    """The taps of :func:`area_taps` as (index, weight shaped to broadcast along ``axis``)."""
    index, weight = area_taps(in_size, out_size)
    shape = [1] * ndim
    shape[axis] = out_size
    return tuple((index[:, t].copy(), weight[:, t].astype(np.float32).reshape(shape))
                 for t in range(index.shape[1]))


def _resize_axis(image: np.ndarray, axis: int, out_size: int) -> np.ndarray:
    out = None
    for index, weight in _taps(image.shape[axis], out_size, axis, image.ndim):
        term = np.take(image, index, axis=axis)
        term *= weight
        out = term if out is None else out.__iadd__(term)
    return out


_LUMA = np.array(LUMA_WEIGHTS, np.float32) / np.float32(256)  # exact: powers of two


def _area_resize(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """(H, W[, C]) exact integer values as float32 -> (height, width[, C]) uint8, rounding half
    up (``functional.preprocess.area_resize``); numpy's own loops, no BLAS (whose threads
    would compete with the emulators for the cores)."""
    count = image.shape[0] * image.shape[1]
    rows = _resize_axis(image, 0, height)
    # the columns as rows of the transpose: gathers along a contiguous axis are the fast ones
    x = _resize_axis(np.ascontiguousarray(np.swapaxes(rows, 0, 1)), 0, width)
    return np.swapaxes((x.astype(np.int32) + count // 2) // count, 0, 1).astype(np.uint8)


def atari84(screens: np.ndarray, out: np.ndarray) -> None:
    """``out`` (84, 84) uint8 <- the luma of the max-pool of ``screens`` (2, 210, 160, 3),
    area-resized."""
    pooled = np.maximum(screens[0], screens[1])
    gray = pooled.astype(np.float32) @ _LUMA  # a matrix-vector product: BLAS runs it on one thread
    gray += np.float32(0.5)
    np.floor(gray, out=gray)  # (77 r + 150 g + 29 b + 128) >> 8
    out[...] = _area_resize(gray, ATARI84, ATARI84)


def dreamer64(screens: np.ndarray, out: np.ndarray) -> None:
    """``out`` (64, 64, 3) uint8 <- the max-pool of ``screens`` (2, 210, 160, 3), area-resized."""
    pooled = np.maximum(screens[0], screens[1]).astype(np.float32)
    out[...] = _area_resize(pooled, DREAMER64, DREAMER64)


# the observations made where the frames are made: the function, its shape per env
OBSERVE = {"atari84": atari84, "dreamer64": dreamer64}
OBSERVATION_SHAPES = {"atari84": (ATARI84, ATARI84), "dreamer64": (DREAMER64, DREAMER64, 3)}
OBSERVATION_LAYOUTS = tuple(OBSERVE)
