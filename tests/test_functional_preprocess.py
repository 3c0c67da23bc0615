"""Observation preprocessing (stori_jax.functional.preprocess) against slow numpy references."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from _env_support import new_ale

from stori_jax.functional import (atari84_frame, dreamer64, max_pool, pool_screens, push_frame,
                                  reset_stack, to_gray)
from stori_jax.functional.preprocess import area_resize

H, W = 210, 160

# The env runs these jitted; eager dispatch of the resize is much slower to compile, so the tests
# below use the jitted functions (test_preprocess_jit_and_vmap compares with the eager ones).
ATARI84 = jax.jit(atari84_frame)
DREAMER64 = jax.jit(dreamer64)
RESIZE = jax.jit(area_resize, static_argnums=(1, 2), static_argnames=("y_axis", "x_axis"))


@functools.lru_cache(maxsize=None)
def real_screens(n: int = 4) -> np.ndarray:
    ale = new_ale("bank_heist")
    actions = ale.getMinimalActionSet()
    rng = np.random.default_rng(0)
    screens = []
    for frame in range(1, 400):
        ale.act(actions[rng.integers(len(actions))])
        if frame % 97 == 0:
            screens.append(ale.getScreenRGB().copy())
    return np.stack(screens[:n])


def random_frames(seed, b=2):
    return np.random.default_rng(seed).integers(0, 256, (b, 2, H, W, 3), dtype=np.uint8)


# -- numpy references --------------------------------------------------------------------------

def gray_reference(rgb):
    rgb = rgb.astype(np.int64)
    return ((77 * rgb[..., 0] + 150 * rgb[..., 1] + 29 * rgb[..., 2] + 128) >> 8).astype(np.uint8)


def area_matrix(n_in, n_out):
    """A[i, j] = |[j, j+1) intersect [i s, (i+1) s)| / s with s = n_in / n_out (float64)."""
    s = n_in / n_out
    lo = np.arange(n_out)[:, None] * s
    hi = lo + s
    j = np.arange(n_in)[None, :]
    return np.clip(np.minimum(hi, j + 1) - np.maximum(lo, j), 0, None) / s


def area_reference(img, h_out, w_out):
    """Exact area averaging of (B, H, W) or (B, H, W, C) uint8 images, float64 (unrounded)."""
    img = img.astype(np.float64)
    ay, ax = area_matrix(img.shape[1], h_out), area_matrix(img.shape[2], w_out)
    out = np.einsum("iy,byx...->bix...", ay, img, optimize=True)
    return np.einsum("jx,bix...->bij...", ax, out, optimize=True)


def rounded(x):
    """Round half up, as the integer implementation does."""
    return np.floor(x + 0.5 + 1e-9).astype(np.int64)


def test_area_matrix_reference_is_a_partition():
    for n_in, n_out in ((210, 84), (160, 84), (210, 64), (160, 64)):
        a = area_matrix(n_in, n_out)
        np.testing.assert_allclose(a.sum(1), 1.0, atol=1e-12)  # every output is an average
        np.testing.assert_allclose(a.sum(0), n_out / n_in, atol=1e-12)  # every input counts


# -- tests -------------------------------------------------------------------------------------

def test_max_pool_is_elementwise_max():
    frames = random_frames(0)
    out = np.asarray(max_pool(jnp.asarray(frames)))
    assert out.shape == (2, H, W, 3) and out.dtype == np.uint8
    np.testing.assert_array_equal(out, np.maximum(frames[:, 0], frames[:, 1]))
    real = real_screens().reshape(2, 2, H, W, 3)
    np.testing.assert_array_equal(np.asarray(max_pool(jnp.asarray(real))),
                                  np.maximum(real[:, 0], real[:, 1]))


def test_to_gray_integer_luma():
    rng = np.random.default_rng(1)
    rgb = rng.integers(0, 256, (200000, 3), dtype=np.uint8)
    extremes = np.array(np.meshgrid([0, 1, 127, 128, 254, 255], [0, 1, 127, 128, 254, 255],
                                    [0, 1, 127, 128, 254, 255])).reshape(3, -1).T.astype(np.uint8)
    rgb = np.concatenate([rgb, extremes, real_screens().reshape(-1, 3)])
    out = np.asarray(to_gray(jnp.asarray(rgb)))
    assert out.dtype == np.uint8 and out.shape == rgb.shape[:1]
    np.testing.assert_array_equal(out, gray_reference(rgb))
    assert int(to_gray(jnp.array([255, 255, 255], jnp.uint8))) == 255
    assert int(to_gray(jnp.array([0, 0, 0], jnp.uint8))) == 0
    assert int(to_gray(jnp.array([255, 0, 0], jnp.uint8))) == (77 * 255 + 128) >> 8


@pytest.mark.parametrize("size", [(84, 84), (64, 64)])
def test_area_resize_constant_images_exact(size):
    values = np.arange(256, dtype=np.uint8)
    img = np.broadcast_to(values[:, None, None], (256, H, W)).copy()
    out = np.asarray(RESIZE(jnp.asarray(img), *size, y_axis=1, x_axis=2))
    assert out.shape == (256, *size) and out.dtype == np.uint8
    np.testing.assert_array_equal(out, np.broadcast_to(values[:, None, None], out.shape))


@pytest.mark.parametrize("size", [(84, 84), (64, 64)])
def test_area_resize_matches_exact_area_average(size):
    rng = np.random.default_rng(2)
    img = np.concatenate([rng.integers(0, 256, (3, H, W), dtype=np.uint8),
                          gray_reference(real_screens())])
    out = np.asarray(RESIZE(jnp.asarray(img), *size, y_axis=1, x_axis=2)).astype(np.int64)
    ref = area_reference(img, *size)
    np.testing.assert_array_equal(out, rounded(ref))  # integer arithmetic: exact
    # exact area averaging preserves the image mean (up to the final rounding)
    assert np.all(np.abs(out.mean(axis=(1, 2)) - img.mean(axis=(1, 2))) <= 0.5 + 1e-6)


def test_area_resize_other_axes_and_rgb():
    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (2, H, W, 3), dtype=np.uint8)
    out = np.asarray(RESIZE(jnp.asarray(img), 64, 64, y_axis=1, x_axis=2))
    assert out.shape == (2, 64, 64, 3)
    np.testing.assert_array_equal(out, rounded(area_reference(img, 64, 64)))
    # a single image with the axes given explicitly
    single = np.asarray(RESIZE(jnp.asarray(img[0, ..., 0]), 84, 84, y_axis=0, x_axis=1))
    np.testing.assert_array_equal(single, rounded(area_reference(img[:1, ..., 0], 84, 84)[0]))


def test_atari84_frame_pipeline():
    """atari84 = luma of the max-pooled RGB screen, area-resized to 84x84."""
    frames = np.concatenate([random_frames(4, 1), real_screens().reshape(2, 2, H, W, 3)])
    screen = np.maximum(frames[:, 0], frames[:, 1])
    out = np.asarray(ATARI84(jnp.asarray(screen)))
    assert out.shape == (3, 84, 84) and out.dtype == np.uint8
    np.testing.assert_array_equal(out, rounded(area_reference(gray_reference(screen), 84, 84)))
    const = np.full((1, H, W, 3), 0, np.uint8)
    const[0] = (200, 200, 30)
    np.testing.assert_array_equal(np.asarray(ATARI84(jnp.asarray(const))),
                                  np.full((1, 84, 84), gray_reference(np.array([200, 200, 30]))))


def test_dreamer64_pipeline():
    frames = np.concatenate([random_frames(5, 1), real_screens().reshape(2, 2, H, W, 3)])
    screen = np.maximum(frames[:, 0], frames[:, 1])
    out = np.asarray(DREAMER64(jnp.asarray(screen)))
    assert out.shape == (3, 64, 64, 3) and out.dtype == np.uint8
    np.testing.assert_array_equal(out, rounded(area_reference(screen, 64, 64)))
    const = np.zeros((1, H, W, 3), np.uint8)
    const[0] = (100, 200, 77)
    np.testing.assert_array_equal(np.asarray(DREAMER64(jnp.asarray(const))),
                                  np.broadcast_to(np.array([100, 200, 77], np.uint8),
                                                  (1, 64, 64, 3)))


def test_push_frame_and_reset_stack():
    b = 3
    frames = [np.full((b, 84, 84), 10 * (t + 1), np.uint8) + np.arange(b, dtype=np.uint8)[:, None,
                                                                                          None]
              for t in range(6)]
    stack = reset_stack(jnp.asarray(frames[0]))
    assert stack.shape == (b, 84, 84, 4) and stack.dtype == jnp.uint8
    np.testing.assert_array_equal(np.asarray(stack), np.repeat(frames[0][..., None], 4, -1))
    no = jnp.zeros(b, bool)
    for t in range(1, 5):
        stack = push_frame(stack, jnp.asarray(frames[t]), no)
    assert stack.shape == (b, 84, 84, 4) and stack.dtype == jnp.uint8
    np.testing.assert_array_equal(np.asarray(stack), np.stack(frames[1:5], -1))  # oldest first
    new_episode = jnp.array([False, True, False])
    stack = push_frame(stack, jnp.asarray(frames[5]), new_episode)
    s = np.asarray(stack)
    np.testing.assert_array_equal(s[1], np.repeat(frames[5][1][..., None], 4, -1))  # restarted
    for i in (0, 2):
        np.testing.assert_array_equal(s[i], np.stack(frames[2:6], -1)[i])  # shifted


def test_preprocess_jit_and_vmap():
    frames = jnp.asarray(np.stack([random_frames(6), random_frames(7)]))  # (T, B, 2, H, W, 3)
    screens = jnp.maximum(frames[:, :, 0], frames[:, :, 1])
    out84 = np.asarray(jax.jit(jax.vmap(atari84_frame))(screens))
    out64 = np.asarray(jax.jit(jax.vmap(dreamer64))(screens))
    assert out84.shape == (2, 2, 84, 84) and out64.shape == (2, 2, 64, 64, 3)
    assert out84.dtype == np.uint8 and out64.dtype == np.uint8
    for t in range(2):
        # integer arithmetic: every compilation (jit, vmap, eager) gives the same bits
        for got, want in ((out84[t], ATARI84(screens[t])), (out64[t], DREAMER64(screens[t])),
                          (out84[t], atari84_frame(screens[t])), (out64[t], dreamer64(screens[t]))):
            np.testing.assert_array_equal(got, np.asarray(want))
    stack = reset_stack(jnp.asarray(out84[0]))
    pushed = jax.jit(push_frame)(stack, jnp.asarray(out84[1]), jnp.array([True, False]))
    np.testing.assert_array_equal(np.asarray(pushed),
                                  np.asarray(push_frame(stack, jnp.asarray(out84[1]),
                                                        jnp.array([True, False]))))
    vstack = jax.jit(jax.vmap(reset_stack))(jnp.asarray(out84))
    assert vstack.shape == (2, 2, 84, 84, 4)
    gray = jax.jit(jax.vmap(to_gray))(frames)
    np.testing.assert_array_equal(np.asarray(gray), gray_reference(np.asarray(frames)))
    np.testing.assert_array_equal(np.asarray(jax.jit(jax.vmap(max_pool))(frames)),
                                  np.maximum(np.asarray(frames)[:, :, 0],
                                             np.asarray(frames)[:, :, 1]))


def test_pool_screens_of_each_frames_layout():
    """``pair`` (2, B, H, W, 3) is the pixel-wise max of the two screens, ``pooled`` is itself and
    ``pooled_chw`` (B, 3, H, W) is moved to channels last; an unknown layout is refused."""
    pair = np.random.default_rng(0).integers(0, 256, (2, 3, 210, 160, 3), dtype=np.uint8)
    pooled = np.maximum(pair[0], pair[1])
    assert (pooled != pair[1]).any() and (pooled != pair[0]).any()
    np.testing.assert_array_equal(pool_screens(jnp.asarray(pair), "pair"), pooled)
    np.testing.assert_array_equal(pool_screens(jnp.asarray(pooled), "pooled"), pooled)
    chw = np.ascontiguousarray(pooled.transpose(0, 3, 1, 2))
    np.testing.assert_array_equal(pool_screens(jnp.asarray(chw), "pooled_chw"), pooled)
    with pytest.raises(ValueError, match="frames layout must be one of"):
        pool_screens(jnp.asarray(pooled), "planar")


@pytest.mark.parametrize("name", ["atari84", "dreamer64"])
def test_the_emulating_processes_frame_work_is_bit_identical_to_jax(name):
    """stori_jax.pixels (numpy, run where the frames are made) against the jitted functions
    the caller runs: real screens, random ones, and the extremes (all 0, all 255)."""
    from stori_jax import pixels

    real = real_screens()
    pairs = np.concatenate([np.stack([real, real[::-1]], 1), random_frames(5, b=3),
                            np.zeros((1, 2, H, W, 3), np.uint8),
                            np.full((1, 2, H, W, 3), 255, np.uint8)])
    expected = np.asarray({"atari84": ATARI84, "dreamer64": DREAMER64}[name](
        jnp.maximum(pairs[:, 0], pairs[:, 1])))
    out = np.zeros((len(pairs),) + pixels.OBSERVATION_SHAPES[name], np.uint8)
    for pair, row in zip(pairs, out):
        pixels.OBSERVE[name](pair, row)
    np.testing.assert_array_equal(out, expected)
