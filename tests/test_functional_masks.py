"""Type 3.2 screen masks (stori_jax.functional.masks), pixel-exact on real ALE screens.

The expected pictures are computed here from docs/spec.md sections 4.1 and 5-8 (regions typed in
from it, painted per pixel with inclusive bounds), independently of the library's region tables.
"""

from __future__ import annotations

import functools
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from _env_support import new_ale

from stori_jax import get_game
from stori_jax.functional import apply_masks, draw_mask_decisions, region_mask, torch_mask
from stori_jax.functional.masks import CROP_REGIONS, TORCH_MODE, TORCH_RADIUS
from stori_jax.games.base import Region

H, W = 210, 160
SIGMAS = 5.0

# ---------------------------------------------------------------------------------------------
# The spec's tables, typed in from docs/spec.md (x0, x1, y0, y1, fill), inclusive
# ---------------------------------------------------------------------------------------------

BLACK = (0, 0, 0)
RING = (110, 156, 66)
BEFORE_DUG, AFTER_DUG = (187, 159, 71), (223, 183, 85)
ATTACK_FILLS = ((146, 150, (101, 209, 174)), (151, 155, (117, 231, 194)),
                (156, 160, (132, 252, 212)))
BLUE, BROWN = (0, 0, 148), (162, 98, 33)

_BREAKOUT = {
    "blocks": (8, 151, 57, 92, BLACK), "paddle": (7, 152, 189, 195, BLACK),
    "score": (2, 158, 3, 16, BLACK), "top": (8, 151, 105, 130, BLACK),
    "middle": (8, 151, 131, 156, BLACK), "bottom": (8, 151, 157, 182, BLACK),
}
_BOXING = {
    "full": (32, 127, 36, 176, RING), "left": (32, 80, 36, 176, RING),
    "right": (81, 127, 36, 176, RING), "enemy": (87, 134, 1, 16, RING),
    "player": (33, 69, 1, 16, RING), "clock": (57, 97, 14, 27, RING),
}
_GOPHER = {
    **{f"al{k}": (0, 59, y0, y1, c) for k, (y0, y1, c) in enumerate(ATTACK_FILLS)},
    **{f"ar{k}": (100, 159, y0, y1, c) for k, (y0, y1, c) in enumerate(ATTACK_FILLS)},
    "ug": (0, 159, 161, 200, BEFORE_DUG), "ug_off": (0, 159, 164, 200, BEFORE_DUG),
    **{f"row{k}": (0, 159, y0, y1, BEFORE_DUG)
       for k, (y0, y1) in enumerate(((161, 168), (168, 176), (176, 182), (183, 194)))},
    **{f"row{k}_dug": (0, 159, y0, y1, AFTER_DUG)
       for k, (y0, y1) in enumerate(((161, 168), (168, 176), (176, 182), (183, 194)))},
    "farmer": (0, 159, 87, 145, BLACK), "nose": (0, 159, 104, 145, BLACK),
    "duck": (0, 159, 26, 56, BLACK), "score": (0, 159, 0, 25, BLACK),
}
_BANKHEIST = {
    "top": (12, 147, 37, 44, BLACK), "left": (12, 15, 37, 177, BLACK),
    "bottom": (12, 147, 173, 177, BLACK), "right": (144, 147, 37, 177, BLACK),
    "fuel": (12, 73, 11, 36, BLUE), "lives": (78, 147, 11, 36, BLUE),
    "score": (12, 147, 178, 186, BROWN),
}
_ATTACK = ("al0", "al1", "al2", "ar0", "ar1", "ar2")
_WALLS = ("top", "left", "bottom", "right")

SPEC_BLACKOUT = {  # game: (regions, {mode: region names in paint order})
    "Breakout": (_BREAKOUT, {
        1: ("blocks", "paddle", "score", "top", "middle", "bottom"), 2: ("blocks",),
        3: ("paddle",), 4: ("score",), 5: ("top",), 6: ("middle",), 7: ("bottom",),
        8: ("blocks", "paddle"), 9: ("blocks", "score"), 10: ("top", "bottom"),
        11: ("top", "middle", "bottom")}),
    "Boxing": (_BOXING, {
        1: ("full", "left", "right", "enemy", "player", "clock"), 2: ("left",), 3: ("right",),
        4: ("full",), 5: ("enemy",), 6: ("player",), 7: ("enemy", "player"), 8: ("clock",),
        9: ("enemy", "player", "clock")}),
    "Gopher": (_GOPHER, {
        1: ("ug", "ug_off", "row0", "row1", "row2", "row3", "farmer", "nose", "duck", "score")
           + _ATTACK,
        2: _ATTACK, 3: _ATTACK[:3], 4: _ATTACK[3:], 5: ("ug",), 6: ("ug_off",),
        7: ("row0",), 8: ("row0_dug",), 9: ("row1",), 10: ("row1_dug",), 11: ("row2",),
        12: ("row2_dug",), 13: ("row3",), 14: ("row3_dug",), 15: ("farmer",), 16: ("nose",),
        17: ("duck",), 18: ("score",)}),
    "BankHeist": (_BANKHEIST, {
        1: _WALLS + ("fuel", "lives", "score"), 2: _WALLS, 3: ("top",), 4: ("left",),
        5: ("bottom",), 6: ("right",), 7: ("left", "right"), 8: ("fuel",), 9: ("lives",),
        10: ("score",)}),
}

SPEC_CROP = {  # crop modes 1..4 (section 4.1), fill black
    1: (0, 79, 0, 209, BLACK), 2: (80, 159, 0, 209, BLACK),
    3: (0, 159, 0, 104, BLACK), 4: (0, 159, 105, 209, BLACK),
}

BLACKOUT_CASES = [(g, m) for g, (_, modes) in SPEC_BLACKOUT.items() for m in modes]

# apply pattern of the 4 test envs x 2 screen slots: every combination
APPLY = np.array([[True, True], [True, False], [False, True], [False, False]])


# ---------------------------------------------------------------------------------------------
# Real screens
# ---------------------------------------------------------------------------------------------

@functools.lru_cache(maxsize=None)
def real_screens(rom_id: str, n: int = 8) -> np.ndarray:
    """``n`` real RGB screens (n, 210, 160, 3) of ``rom_id`` under random play (seeded)."""
    ale = new_ale(rom_id)
    actions = ale.getMinimalActionSet()
    rng = np.random.default_rng(0)
    screens = []
    frame = 0
    while len(screens) < n:
        ale.act(actions[rng.integers(len(actions))])
        frame += 1
        if ale.game_over():
            ale.reset_game()
        if frame >= 240 and frame % 17 == 0:  # past Gopher's intro, spread out
            screens.append(ale.getScreenRGB().copy())
    return np.stack(screens)


def sample_frames(rom_id: str) -> np.ndarray:
    """(4 envs, 2 slots, 210, 160, 3): 6 real screens and 2 uniform-noise screens (noise makes a
    pixel that already equals the fill colour practically impossible)."""
    screens = real_screens(rom_id).copy()
    rng = np.random.default_rng(sum(map(ord, rom_id)))
    screens[[0, 3]] = rng.integers(0, 256, (2, H, W, 3), dtype=np.uint8)
    return screens.reshape(4, 2, H, W, 3)


def paint(screen: np.ndarray, regions) -> np.ndarray:
    """Per-pixel reference: regions in order, inclusive bounds, later ones overwrite."""
    out = screen.copy()
    ys, xs = np.mgrid[0:H, 0:W]
    for x0, x1, y0, y1, fill in regions:
        inside = (xs >= x0) & (xs <= x1) & (ys >= y0) & (ys <= y1)
        out[inside] = fill
    return out


def inside_any(regions, x, y) -> bool:
    return any(x0 <= x <= x1 and y0 <= y <= y1 for x0, x1, y0, y1, _ in regions)


def check_masked(frames, out, regions, apply):
    out = np.asarray(out)
    assert out.shape == frames.shape and out.dtype == np.uint8
    for b in range(frames.shape[0]):
        for s in range(2):
            expected = paint(frames[b, s], regions) if apply[b, s] else frames[b, s]
            np.testing.assert_array_equal(out[b, s], expected, err_msg=f"env {b} slot {s}")
    # explicit inclusive-bounds check on a noise screen that was masked (env 0 slot 0)
    masked, original = out[0, 0], frames[0, 0]
    for k, (x0, x1, y0, y1, fill) in enumerate(regions):
        later = regions[k + 1:]
        for x, y in ((x0, y0), (x1, y1), (x0, y1), (x1, y0)):  # the corners are filled
            if not inside_any(later, x, y):
                assert tuple(masked[y, x]) == tuple(fill), ((x, y), fill)
        for x, y in ((x0 - 1, y0), (x1 + 1, y1), (x0, y0 - 1), (x1, y1 + 1)):  # just outside
            if 0 <= x < W and 0 <= y < H and not inside_any(regions, x, y):
                assert tuple(masked[y, x]) == tuple(original[y, x]), (x, y)


# ---------------------------------------------------------------------------------------------
# Blackout and crop halves
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("game_name", list(SPEC_BLACKOUT))
def test_blackout_mode_numbers(game_name):
    assert sorted(get_game(game_name).blackout_modes) == sorted(SPEC_BLACKOUT[game_name][1])


@pytest.mark.parametrize("game_name,mode", BLACKOUT_CASES)
def test_blackout_mode_pixel_exact(game_name, mode):
    game = get_game(game_name)
    table, modes = SPEC_BLACKOUT[game_name]
    regions = [table[n] for n in modes[mode]]
    frames = sample_frames(game.rom_id)
    hidden, fill = region_mask(game.blackout_modes[mode].regions)
    out = apply_masks(jnp.asarray(frames), jnp.asarray(APPLY), hidden=hidden, fill=fill)
    check_masked(frames, out, regions, APPLY)
    # the static mask itself: hidden is exactly the union, fill is zero outside it
    union = paint(np.zeros((H, W, 3), np.uint8), [r[:4] + ((1, 1, 1),) for r in regions])[..., 0]
    np.testing.assert_array_equal(hidden, union.astype(bool))
    assert not fill[~hidden].any()


@pytest.mark.parametrize("mode", [1, 2, 3, 4])
def test_crop_halves_pixel_exact(mode):
    frames = sample_frames("breakout")
    hidden, fill = region_mask(CROP_REGIONS[mode])
    out = apply_masks(jnp.asarray(frames), jnp.asarray(APPLY), hidden=hidden, fill=fill)
    check_masked(frames, out, [SPEC_CROP[mode]], APPLY)
    assert hidden.sum() == W * H // 2  # exactly half the screen


def test_crop_halves_are_complementary():
    left, right = region_mask(CROP_REGIONS[1])[0], region_mask(CROP_REGIONS[2])[0]
    top, bottom = region_mask(CROP_REGIONS[3])[0], region_mask(CROP_REGIONS[4])[0]
    assert not (left & right).any() and (left | right).all()
    assert not (top & bottom).any() and (top | bottom).all()
    assert left[:, 79].all() and not left[:, 80].any()
    assert top[104].all() and not top[105].any()


def test_regions_painted_in_order_later_overwrites():
    a = Region(0, 9, 0, 9, (1, 2, 3))
    b = Region(5, 14, 5, 14, (4, 5, 6))
    frames = np.full((1, 2, H, W, 3), 200, np.uint8)
    apply = jnp.array([[True, True]])
    for order, winner in (((a, b), (4, 5, 6)), ((b, a), (1, 2, 3))):
        hidden, fill = region_mask(order)
        out = np.asarray(apply_masks(jnp.asarray(frames), apply, hidden=hidden, fill=fill))
        assert tuple(out[0, 0, 7, 7]) == winner  # overlap
        assert tuple(out[0, 1, 0, 0]) == (1, 2, 3) and tuple(out[0, 1, 14, 14]) == (4, 5, 6)
        assert tuple(out[0, 0, 15, 15]) == (200, 200, 200) and tuple(out[0, 0, 0, 10]) == (200,) * 3
        assert hidden.sum() == 100 + 100 - 25


def test_blackout_jit_and_vmap():
    game = get_game("Boxing")
    hidden, fill = region_mask(game.blackout_modes[9].regions)
    frames = jnp.asarray(np.stack([sample_frames("boxing"), sample_frames("boxing")[::-1]]))
    apply = jnp.asarray(np.stack([APPLY, APPLY[::-1]]))
    f = jax.jit(lambda fr, ap: apply_masks(fr, ap, hidden=hidden, fill=fill))
    eager = [np.asarray(apply_masks(frames[t], apply[t], hidden=hidden, fill=fill))
             for t in range(2)]
    np.testing.assert_array_equal(np.asarray(f(frames[0], apply[0])), eager[0])
    np.testing.assert_array_equal(np.asarray(jax.vmap(f)(frames, apply)), np.stack(eager))


# ---------------------------------------------------------------------------------------------
# Torch (crop mode 5)
# ---------------------------------------------------------------------------------------------

def torch_reference(cx, cy):
    ys, xs = np.mgrid[0:H, 0:W]
    return (xs - cx) ** 2 + (ys - cy) ** 2 > 75 ** 2


def test_torch_constants():
    assert TORCH_MODE == 5 and TORCH_RADIUS == 75


@pytest.mark.parametrize("centre", [(80, 105), (0, 0), (159, 209), (3, 200), (100, 20)])
def test_torch_radius_exact(centre):
    cx, cy = centre
    hidden = np.asarray(torch_mask(jnp.array(centre, jnp.int32)))
    assert hidden.shape == (H, W)
    np.testing.assert_array_equal(hidden, torch_reference(cx, cy))
    # hand-picked points: distance exactly 75 is kept, just beyond it is hidden
    for dx, dy, kept in ((75, 0, True), (76, 0, False), (0, 75, True), (0, 76, False),
                         (45, 60, True), (45, 61, False), (-60, -45, True), (-61, -45, False),
                         (53, 53, True), (53, 54, False)):  # 53^2 * 2 = 5618, 53^2 + 54^2 = 5725
        x, y = cx + dx, cy + dy
        if 0 <= x < W and 0 <= y < H:
            assert hidden[y, x] == (not kept), (centre, dx, dy)


def test_torch_apply_masks_on_real_screens():
    frames = sample_frames("breakout")
    centres = np.array([[[80, 105], [0, 0]], [[159, 209], [40, 150]],
                        [[10, 10], [150, 30]], [[70, 70], [71, 71]]], np.int32)
    out = np.asarray(apply_masks(jnp.asarray(frames), jnp.asarray(APPLY),
                                 centres=jnp.asarray(centres)))
    assert out.shape == frames.shape and out.dtype == np.uint8
    for b in range(4):
        for s in range(2):
            if not APPLY[b, s]:
                np.testing.assert_array_equal(out[b, s], frames[b, s])
                continue
            hidden = torch_reference(*centres[b, s])
            assert not out[b, s][hidden].any()  # everything farther than 75 is black
            np.testing.assert_array_equal(out[b, s][~hidden], frames[b, s][~hidden])
    # a different centre per slot really gives a different picture
    assert not np.array_equal(out[0, 0] == 0, out[0, 1] == 0)


def chi2_upper(df: int, z: float = SIGMAS) -> float:
    """Wilson-Hilferty upper quantile of chi-square(df) at a z-sigma tail."""
    return df * (1 - 2 / (9 * df) + z * np.sqrt(2 / (9 * df))) ** 3


def chi2_stat(values, n_bins):
    counts = np.bincount(values, minlength=n_bins)
    assert counts.size == n_bins
    expected = values.size / n_bins
    return float(((counts - expected) ** 2 / expected).sum())


N_KEYS = 20000


@functools.lru_cache(maxsize=None)
def many_keys(seed: int = 0):
    return jax.random.split(jax.random.PRNGKey(seed), N_KEYS)


def test_torch_centres_uniform_and_independent_per_slot():
    apply, centres = draw_mask_decisions(many_keys(), prob=1.0, per_frame=True, torch=True)
    apply, centres = np.asarray(apply), np.asarray(centres)
    assert apply.shape == (N_KEYS, 2) and apply.all()
    assert centres.shape == (N_KEYS, 2, 2) and centres.dtype == np.int32
    x, y = centres[..., 0].ravel(), centres[..., 1].ravel()
    assert x.min() == 0 and x.max() == W - 1 and y.min() == 0 and y.max() == H - 1
    assert chi2_stat(x, W) < chi2_upper(W - 1)
    assert chi2_stat(y, H) < chi2_upper(H - 1)
    n = x.size
    for v, size in ((x, W), (y, H)):
        mean, var = (size - 1) / 2, (size ** 2 - 1) / 12
        assert abs(v.mean() - mean) < SIGMAS * np.sqrt(var / n)
        assert abs(v.var() - var) < SIGMAS * np.sqrt((size ** 4 / 80 - var ** 2) * 2 / n) + 1
    # the two slots of one observation get independent centres (a new centre per application)
    same = np.all(centres[:, 0] == centres[:, 1], axis=-1).sum()
    assert same <= 10  # expected N / (160 * 210) ~ 0.6
    for axis in (0, 1):
        r = np.corrcoef(centres[:, 0, axis], centres[:, 1, axis])[0, 1]
        assert abs(r) < SIGMAS / np.sqrt(N_KEYS)
    # and x, y are independent of each other
    assert abs(np.corrcoef(x, y)[0, 1]) < SIGMAS / np.sqrt(n)


def test_torch_step_granularity_shares_decision_and_centre():
    apply, centres = draw_mask_decisions(many_keys(1), prob=0.5, per_frame=False, torch=True)
    apply, centres = np.asarray(apply), np.asarray(centres)
    np.testing.assert_array_equal(apply[:, 0], apply[:, 1])
    np.testing.assert_array_equal(centres[:, 0], centres[:, 1])
    assert len({tuple(c) for c in centres[:, 0]}) > 0.8 * W * H * (1 - np.exp(-N_KEYS / (W * H)))
    assert abs(apply[:, 0].mean() - 0.5) < SIGMAS * np.sqrt(0.25 / N_KEYS)


def test_no_torch_centres_are_zero():
    for per_frame in (True, False):
        _, centres = draw_mask_decisions(many_keys(2), prob=1.0, per_frame=per_frame,
                                         torch=False)
        assert np.asarray(centres).shape == (N_KEYS, 2, 2) and not np.asarray(centres).any()


@pytest.mark.parametrize("p", [0.0, 0.1, 0.3, 0.75, 0.999, 1.0])
@pytest.mark.parametrize("per_frame", [True, False])
def test_mask_probability(p, per_frame):
    apply = np.asarray(draw_mask_decisions(many_keys(3), prob=p, per_frame=per_frame,
                                           torch=False)[0])
    assert apply.dtype == np.bool_ and apply.shape == (N_KEYS, 2)
    if p == 0.0:
        assert not apply.any()
        return
    if p == 1.0:
        assert apply.all()
        return
    for slot in range(2):
        k = apply[:, slot].sum()
        assert abs(k - N_KEYS * p) <= SIGMAS * np.sqrt(N_KEYS * p * (1 - p)) + 1, (slot, k)
    both = (apply[:, 0] & apply[:, 1]).sum()
    q = p * p if per_frame else p  # independent slots per frame, one draw per step
    assert abs(both - N_KEYS * q) <= SIGMAS * np.sqrt(N_KEYS * q * (1 - q)) + 1


def test_mask_decisions_keys():
    # (all draws here use one batch shape, so eager dispatch compiles once)
    kw = dict(prob=0.5, per_frame=True, torch=True)
    a1, c1 = draw_mask_decisions(many_keys(4), **kw)
    a2, c2 = draw_mask_decisions(many_keys(4), **kw)
    a3, c3 = draw_mask_decisions(many_keys(5), **kw)
    np.testing.assert_array_equal(np.asarray(a1), np.asarray(a2))
    np.testing.assert_array_equal(np.asarray(c1), np.asarray(c2))
    assert np.mean(np.asarray(a1) != np.asarray(a3)) > 0.4
    assert np.mean(np.asarray(c1) != np.asarray(c3)) > 0.9
    # env i's draw depends only on its own key, not on its place in the batch
    perm = np.random.default_rng(0).permutation(N_KEYS)
    a4, c4 = draw_mask_decisions(many_keys(4)[perm], **kw)
    np.testing.assert_array_equal(np.asarray(a4), np.asarray(a1)[perm])
    np.testing.assert_array_equal(np.asarray(c4), np.asarray(c1)[perm])


def test_mask_decisions_jit_and_vmap():
    keys = jnp.stack([many_keys(6), many_keys(8)])
    f = functools.partial(draw_mask_decisions, prob=0.4, per_frame=True, torch=True)
    eager = [f(keys[t]) for t in range(2)]
    va, vc = jax.jit(jax.vmap(f))(keys)
    np.testing.assert_array_equal(np.asarray(va), np.stack([np.asarray(e[0]) for e in eager]))
    np.testing.assert_array_equal(np.asarray(vc), np.stack([np.asarray(e[1]) for e in eager]))


def test_torch_apply_jit_and_vmap():
    frames = jnp.asarray(np.stack([sample_frames("gopher"), sample_frames("gopher")[::-1]]))
    apply, centres = draw_mask_decisions(many_keys(7), prob=0.6, per_frame=True, torch=True)
    apply, centres = apply[:8].reshape(2, 4, 2), centres[:8].reshape(2, 4, 2, 2)
    f = jax.jit(lambda fr, ap, c: apply_masks(fr, ap, centres=c))
    eager = np.stack([np.asarray(apply_masks(frames[t], apply[t], centres=centres[t]))
                      for t in range(2)])
    np.testing.assert_array_equal(np.asarray(jax.vmap(f)(frames, apply, centres)), eager)
    np.testing.assert_array_equal(np.asarray(f(frames[1], apply[1], centres[1])), eager[1])


def test_torch_mask_jit_and_vmap():
    centres = jnp.array([[[80, 105], [0, 0]], [[159, 209], [3, 200]]], jnp.int32)  # (2, 2, 2)
    out = np.asarray(jax.jit(jax.vmap(torch_mask))(centres))
    assert out.shape == (2, 2, H, W) and out.dtype == np.bool_
    for b in range(2):
        for s in range(2):
            np.testing.assert_array_equal(out[b, s], torch_reference(*np.asarray(centres[b, s])))
    np.testing.assert_array_equal(np.asarray(torch_mask(centres)), out)  # batched directly


def test_apply_masks_takes_a_static_region_or_the_torch_not_neither_or_both():
    frames, apply = jnp.zeros((1, 2, 210, 160, 3), jnp.uint8), jnp.ones((1, 2), bool)
    hidden, fill = np.zeros((210, 160), bool), np.zeros(3, np.uint8)
    centres = jnp.zeros((1, 2, 2), jnp.int32)
    for kwargs, given in ((dict(), "hidden=None, fill=None, centres=None"),
                          (dict(hidden=hidden), "hidden=..., fill=None, centres=None"),
                          (dict(hidden=hidden, fill=fill, centres=centres),
                           "hidden=..., fill=..., centres=..."),
                          (dict(fill=fill, centres=centres), "hidden=None, fill=..., centres=...")):
        with pytest.raises(ValueError, match=r"apply_masks takes either hidden= and fill= \(a "
                                             r"static region\) or centres= \(the torch\), got "
                                             + re.escape(given)):
            apply_masks(frames, apply, **kwargs)


def test_extract_labels_takes_a_game_name_or_its_spec():
    from stori_jax.functional import extract_labels

    ram = np.arange(128, dtype=np.uint8)[None]
    by_name = extract_labels("breakout", ram)
    by_spec = extract_labels(get_game("Breakout"), ram)
    assert by_name.keys() == by_spec.keys() and by_name
    for name in by_name:
        np.testing.assert_array_equal(by_name[name], by_spec[name])
    with pytest.raises(ValueError, match="NoSuchGame"):
        extract_labels("NoSuchGame", ram)


def test_a_keys_mask_draws_are_pinned():
    """A seed's masks are the same in every version: the decisions and torch centres of one
    key, written down (the draws are statistically alike under any change of key use, e.g.
    x and y taken from each other's stream, but a published run would no longer reproduce)."""
    from stori_jax.functional import env_keys

    apply, centres = draw_mask_decisions(env_keys(jax.random.PRNGKey(0), 2), prob=0.5,
                                         per_frame=True, torch=True)
    assert np.asarray(apply).tolist() == [[True, False], [False, True]]
    assert np.asarray(centres).tolist() == [[[68, 132], [139, 120]], [[112, 92], [92, 160]]]
