"""Type 1 action corruption, the type 2.2 drift schedule, keys and event uniforms
(stori_jax.functional): rates within binomial bounds, exact semantics, keys, jit and vmap."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from stori_jax import ActionNoise, get_game
from stori_jax.functional import (Purpose, concept2_probability, concept_of, corrupt_actions,
                                  env_keys, event_uniforms, purpose_keys)

SIGMAS = 5.0
B = 20000  # envs per batch (every call in this file uses this one batch shape)
SLOTS = 4


@functools.lru_cache(maxsize=None)
def keys_of(seed: int):
    return jax.random.split(jax.random.PRNGKey(seed), B)


def within_binomial(k, n, p):
    return abs(k - n * p) <= SIGMAS * np.sqrt(n * p * (1 - p)) + 1


def chi2_upper(df: int, z: float = SIGMAS) -> float:
    """Wilson-Hilferty upper quantile of chi-square(df) at a z-sigma tail."""
    return df * (1 - 2 / (9 * df) + z * np.sqrt(2 / (9 * df))) ** 3


def corrupt(seed, actions, prev, **kw):
    kw.setdefault("num_slots", SLOTS)
    executed, fired = corrupt_actions(keys_of(seed), jnp.asarray(actions, jnp.int32),
                                      jnp.asarray(prev, jnp.int32), **kw)
    executed, fired = np.asarray(executed), np.asarray(fired)
    assert executed.shape == (B, kw["num_slots"]) and executed.dtype == np.int32
    assert fired.shape == (B, kw["num_slots"]) and fired.dtype == np.bool_
    return executed, fired


# ---------------------------------------------------------------------------------------------
# Uniform replacement
# ---------------------------------------------------------------------------------------------

def test_replacement_sets_of_the_games():
    noise = ActionNoise(0.3)
    assert get_game("Breakout").replacement_actions(noise) == (0, 1, 2, 3)
    assert get_game("Gopher").replacement_actions(noise) == tuple(range(8))
    assert get_game("Boxing").replacement_actions(noise) == tuple(range(18))
    assert get_game("BankHeist").replacement_actions(noise) == tuple(range(10))
    assert get_game("BankHeist").replacement_actions(ActionNoise(0.3, (4, 5))) == (4, 5)


@pytest.mark.parametrize("game_name,p", [("Breakout", 0.3), ("Boxing", 0.05), ("Gopher", 0.5),
                                         ("BankHeist", 0.3)])
def test_uniform_replacement_rate_and_distribution(game_name, p):
    game = get_game(game_name)
    table = game.replacement_actions(ActionNoise(p))
    rng = np.random.default_rng(0)
    intended = rng.integers(0, game.num_actions, B)
    if game_name == "BankHeist":
        intended[: B // 2] = 17  # an intended FIRE action that a replacement must never produce
    executed, fired = corrupt(0, intended, np.zeros(B), prob=p, replacement=table)
    # not fired: the intended action, exactly
    np.testing.assert_array_equal(executed[~fired], np.broadcast_to(intended[:, None],
                                                                     fired.shape)[~fired])
    # the channel fires per slot independently with probability p
    n = fired.size
    assert within_binomial(fired.sum(), n, p)
    for slot in range(SLOTS):
        assert within_binomial(fired[:, slot].sum(), B, p), slot
    assert within_binomial((fired[:, 0] & fired[:, 1]).sum(), B, p * p)
    # fired: uniform over the replacement set (it may equal the intended action)
    replaced = executed[fired]
    assert set(np.unique(replaced)) == set(table)
    counts = np.bincount(replaced, minlength=max(table) + 1)[list(table)]
    expected = replaced.size / len(table)
    chi2 = ((counts - expected) ** 2 / expected).sum()
    assert chi2 < chi2_upper(len(table) - 1)
    same = (replaced == np.broadcast_to(intended[:, None], fired.shape)[fired]).mean()
    if game_name != "BankHeist":
        assert abs(same - 1 / len(table)) < SIGMAS * np.sqrt(1 / len(table) / replaced.size) + 1e-3
    else:
        assert replaced.max() <= 9  # never a FIRE action (>= 10)
        assert not (executed[: B // 2][fired[: B // 2]] >= 10).any()


def test_custom_replacement_set():
    executed, fired = corrupt(1, np.full(B, 2), np.zeros(B), prob=1.0, replacement=(5, 7))
    assert fired.all()
    assert set(np.unique(executed)) == {5, 7}
    assert within_binomial((executed == 5).sum(), executed.size, 0.5)


@pytest.mark.parametrize("sticky", [False, True])
def test_probability_zero_and_one(sticky):
    intended = np.arange(B) % 18
    prev = (np.arange(B) + 5) % 18
    table = None if sticky else tuple(range(18))
    executed, fired = corrupt(2, intended, prev, prob=0.0, replacement=table, sticky=sticky)
    assert not fired.any()
    np.testing.assert_array_equal(executed, np.repeat(intended[:, None], SLOTS, 1))
    executed, fired = corrupt(2, intended, prev, prob=1.0, replacement=table, sticky=sticky)
    assert fired.all()
    if sticky:
        np.testing.assert_array_equal(executed, np.repeat(prev[:, None], SLOTS, 1))
    else:
        assert within_binomial((executed == intended[:, None]).sum(), executed.size, 1 / 18)


# ---------------------------------------------------------------------------------------------
# Sticky actions
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("p", [0.25, 0.75])
def test_sticky_semantics(p):
    rng = np.random.default_rng(1)
    intended = rng.integers(0, 18, B)
    prev = (intended + 1 + rng.integers(0, 17, B)) % 18  # always different from intended
    executed, fired = corrupt(3, intended, prev, prob=p, sticky=True)
    assert within_binomial(fired.sum(), fired.size, p)
    for slot in range(SLOTS):
        assert within_binomial(fired[:, slot].sum(), B, p)
    # executed[f] = executed[f - 1] if fired[f] else intended, with executed[-1] = prev
    expected = np.empty_like(executed)
    last = prev.copy()
    for f in range(SLOTS):
        last = np.where(fired[:, f], last, intended)
        expected[:, f] = last
    np.testing.assert_array_equal(executed, expected)
    # equivalently: prev while every slot so far fired, otherwise intended
    all_fired = np.cumprod(fired, axis=1).astype(bool)
    np.testing.assert_array_equal(executed, np.where(all_fired, prev[:, None],
                                                     intended[:, None]))
    assert set(np.unique(executed)) <= set(range(18))
    # the probability that slot f still repeats prev is p^(f+1)
    for f in range(SLOTS):
        assert within_binomial((executed[:, f] == prev).sum(), B, p ** (f + 1)), f


def test_step_granularity_one_slot():
    executed, fired = corrupt(4, np.full(B, 3), np.full(B, 1), prob=0.3, num_slots=1,
                              replacement=(0, 1, 2, 3))
    assert within_binomial(fired.sum(), B, 0.3)
    executed, fired = corrupt(4, np.full(B, 3), np.full(B, 1), prob=0.3, num_slots=1,
                              sticky=True)
    np.testing.assert_array_equal(executed[:, 0], np.where(fired[:, 0], 1, 3))


@pytest.mark.parametrize("sticky", [False, True])
def test_active_mask_switches_corruption_off_per_env(sticky):
    rng = np.random.default_rng(2)
    intended = rng.integers(0, 18, B)
    prev = (intended + 3) % 18
    active = rng.random(B) < 0.5
    kw = dict(prob=0.6, replacement=None if sticky else tuple(range(18)), sticky=sticky)
    executed, fired = corrupt(5, intended, prev, **kw)
    ex_a, fi_a = corrupt(5, intended, prev, active=jnp.asarray(active), **kw)
    # inactive envs: intended action on every slot, nothing fired
    np.testing.assert_array_equal(ex_a[~active], np.repeat(intended[~active, None], SLOTS, 1))
    assert not fi_a[~active].any()
    # active envs: exactly what the unmasked call gives with the same keys
    np.testing.assert_array_equal(ex_a[active], executed[active])
    np.testing.assert_array_equal(fi_a[active], fired[active])
    assert fired[active].any() and fired[~active].any()  # the mask really changed something
    all_on, _ = corrupt(5, intended, prev, active=jnp.ones(B, bool), **kw)
    np.testing.assert_array_equal(all_on, executed)


@pytest.mark.parametrize("sticky", [False, True])
def test_corrupt_actions_keys(sticky):
    intended, prev = np.arange(B) % 4, (np.arange(B) + 1) % 4
    kw = dict(prob=0.5, replacement=None if sticky else (0, 1, 2, 3), sticky=sticky)
    e1, f1 = corrupt(6, intended, prev, **kw)
    e2, f2 = corrupt(6, intended, prev, **kw)
    e3, f3 = corrupt(7, intended, prev, **kw)
    np.testing.assert_array_equal(e1, e2)
    np.testing.assert_array_equal(f1, f2)
    assert (f1 != f3).mean() > 0.4 and (e1 != e3).mean() > 0.2
    # env i depends only on its own key
    perm = np.random.default_rng(0).permutation(B)
    executed, fired = corrupt_actions(keys_of(6)[perm], jnp.asarray(intended[perm]),
                                      jnp.asarray(prev[perm]), num_slots=SLOTS, **kw)
    np.testing.assert_array_equal(np.asarray(executed), e1[perm])
    np.testing.assert_array_equal(np.asarray(fired), f1[perm])


@pytest.mark.parametrize("sticky", [False, True])
def test_corrupt_actions_jit_and_vmap(sticky):
    keys = jnp.stack([keys_of(8), keys_of(9)])
    intended = jnp.asarray(np.arange(2 * B).reshape(2, B) % 18, jnp.int32)
    prev = (intended + 7) % 18
    active = jnp.asarray(np.arange(2 * B).reshape(2, B) % 3 != 0)
    f = functools.partial(corrupt_actions, prob=0.4, num_slots=SLOTS, sticky=sticky,
                          replacement=None if sticky else tuple(range(18)))
    eager = [f(keys[t], intended[t], prev[t], active=active[t]) for t in range(2)]
    ve, vf = jax.jit(jax.vmap(lambda k, a, p, on: f(k, a, p, active=on)))(keys, intended, prev,
                                                                         active)
    np.testing.assert_array_equal(np.asarray(ve), np.stack([np.asarray(e[0]) for e in eager]))
    np.testing.assert_array_equal(np.asarray(vf), np.stack([np.asarray(e[1]) for e in eager]))


# ---------------------------------------------------------------------------------------------
# Concept drift schedule
# ---------------------------------------------------------------------------------------------

PERIODS = [1, 2, 3, 300, 600]


@pytest.mark.parametrize("T", PERIODS)
def test_sudden_boundaries(T):
    steps = np.array([0, max(T - 2, 0), T - 1, T, T + 1, 2 * T, 10 * T])
    expected = (steps >= T).astype(np.int32)
    p = np.asarray(concept2_probability(jnp.asarray(steps), "sudden", T))
    np.testing.assert_array_equal(p, expected.astype(np.float32))
    c = np.asarray(concept_of(keys_of(10)[: steps.size], jnp.asarray(steps), "sudden", T))
    np.testing.assert_array_equal(c, expected)
    assert c[list(steps).index(T - 1)] == 0 and c[list(steps).index(T)] == 1


@pytest.mark.parametrize("T", PERIODS)
def test_cyclic_boundaries(T):
    steps = np.array([0, T - 1, T, 2 * T - 1, 2 * T, 3 * T - 1, 3 * T, 4 * T, 7 * T + T // 2])
    expected = (steps // T) % 2
    np.testing.assert_array_equal(expected[1:7], [0, 1, 1, 0, 0, 1])
    p = np.asarray(concept2_probability(jnp.asarray(steps), "cyclic", T))
    np.testing.assert_array_equal(p, expected.astype(np.float32))
    c = np.asarray(concept_of(keys_of(10)[: steps.size], jnp.asarray(steps), "cyclic", T))
    np.testing.assert_array_equal(c, expected)
    assert c.dtype == np.int32


@pytest.mark.parametrize("T", [2, 300, 600])
def test_gradual_probability_exact(T):
    steps = np.array([0, T - 1, T, T + T // 4, T + T // 2, 2 * T - 1, 2 * T, 2 * T + 1, 10 * T])
    p = np.asarray(concept2_probability(jnp.asarray(steps), "gradual", T))
    expected = np.clip((steps - T) / T, 0, 1).astype(np.float32)
    np.testing.assert_array_equal(p, expected)
    assert p[2] == 0.0 and p[4] == 0.5 and p[6] == 1.0  # k = T, 1.5 T, 2 T


def test_gradual_empirical_rate():
    T = 300
    for k, q in ((T, 0.0), (T + 75, 0.25), (T + 150, 0.5), (T + 270, 0.9), (2 * T, 1.0)):
        c = np.asarray(concept_of(keys_of(11), jnp.full(B, k), "gradual", T))
        assert c.shape == (B,) and c.dtype == np.int32
        if q in (0.0, 1.0):
            assert (c == int(q)).all(), k
        else:
            assert within_binomial(c.sum(), B, q), (k, c.mean())
    # per-env steps: each env gets its own probability
    steps = np.where(np.arange(B) % 2 == 0, T + 150, 2 * T)
    c = np.asarray(concept_of(keys_of(12), jnp.asarray(steps), "gradual", T))
    assert c[1::2].all() and within_binomial(c[::2].sum(), B // 2, 0.5)


def test_gradual_keys():
    steps = jnp.full(B, 450)
    c1 = np.asarray(concept_of(keys_of(13), steps, "gradual", 300))
    c2 = np.asarray(concept_of(keys_of(13), steps, "gradual", 300))
    c3 = np.asarray(concept_of(keys_of(14), steps, "gradual", 300))
    np.testing.assert_array_equal(c1, c2)
    assert (c1 != c3).mean() > 0.4


@pytest.mark.parametrize("schedule", ["sudden", "cyclic", "gradual"])
def test_drift_jit_and_vmap(schedule):
    T = 300
    keys = jnp.stack([keys_of(15), keys_of(16)])
    steps = jnp.asarray(np.arange(2 * B).reshape(2, B) % (4 * T), jnp.int32)
    f = jax.jit(jax.vmap(lambda k, s: concept_of(k, s, schedule, T)))
    out = np.asarray(f(keys, steps))
    eager = np.stack([np.asarray(concept_of(keys[t], steps[t], schedule, T)) for t in range(2)])
    np.testing.assert_array_equal(out, eager)
    g = jax.jit(lambda s: concept2_probability(s, schedule, T))
    np.testing.assert_array_equal(np.asarray(g(steps[0])),
                                  np.asarray(concept2_probability(steps[0], schedule, T)))


def test_unknown_schedule():
    with pytest.raises(ValueError, match=r"schedule must be one of \['sudden', 'cyclic', "
                                         r"'gradual'\], got 'linear'"):
        concept2_probability(jnp.zeros(3, jnp.int32), "linear", 10)


def test_the_pure_functions_refuse_bad_parameters_and_take_traced_ones():
    """corrupt_actions(prob=1.5) corrupted every action and concept_of(..., 'cyclic', 0) gave
    concepts without a word; inside jit or vmap a parameter has no number yet and is taken as
    it is (a sweep over probabilities)."""
    from stori_jax.functional import draw_mask_decisions

    keys, zeros = keys_of(0)[:4], jnp.zeros(4, jnp.int32)
    for call, match in (
            (lambda: corrupt_actions(keys, zeros, zeros, prob=1.5, num_slots=1,
                                     replacement=[0, 1]), r"prob must be in \[0, 1\], got 1.5"),
            (lambda: corrupt_actions(keys, zeros, zeros, prob=0.5, num_slots=0, sticky=True),
             "num_slots must be >= 1, got 0"),
            (lambda: draw_mask_decisions(keys, prob=-0.1, per_frame=True, torch=False),
             r"prob must be in \[0, 1\], got -0.1"),
            (lambda: concept_of(keys, jnp.arange(4), "cyclic", 0),
             r"period must be in \[1, 2147483647\], got 0")):
        with pytest.raises(ValueError, match=match):
            call()
    probs = jnp.array([0.0, 1.0])
    masked = jax.vmap(lambda p: draw_mask_decisions(keys, prob=p, per_frame=True,
                                                    torch=False)[0].sum())(probs)
    assert masked.tolist() == [0, 8]
    assert jax.jit(lambda t: concept_of(keys, jnp.arange(4), "cyclic", t))(2).tolist() == [
        0, 0, 1, 1]


def test_the_pure_functions_refuse_bad_static_arguments():
    """Static arguments (counts, flags, action tables, purposes, shapes) are checked when
    traced: each was a JAX, numpy or Python error from deep inside, or was silently taken (a
    string flag as True, a float count or purpose truncated, a negative action executed)."""
    from stori_jax.functional import (apply_masks, atari84_frame, draw_mask_decisions,
                                      event_uniforms, extract_labels, max_pool, purpose_keys,
                                      region_mask)
    from stori_jax.functional.masks import CROP_REGIONS
    from stori_jax.functional.preprocess import area_resize

    keys, zeros = keys_of(0)[:4], jnp.zeros(4, jnp.int32)
    hidden, fill = region_mask(CROP_REGIONS[1])
    frames = jnp.zeros((4, 2, 210, 160, 3), jnp.uint8)
    purpose = r"purpose must be a stori_jax\.functional\.Purpose \(ACTIONS = 1, .*NOOPS = 5\)"
    table = r"replacement must be a non-empty sequence of action indices >= 0 when sticky=False"
    for call, match in (
            (lambda: env_keys(jax.random.PRNGKey(0), 2.5), r"num_envs must be an int >= 1"),
            (lambda: env_keys(jax.random.PRNGKey(0), -1), r"num_envs must be >= 1, got -1"),
            (lambda: purpose_keys(keys, 99), purpose + ", got 99"),
            (lambda: purpose_keys(keys, 1.0), purpose + ", got 1.0"),
            (lambda: purpose_keys(keys, "ACTIONS"), purpose),
            (lambda: event_uniforms(keys, 0), r"num_slots must be >= 1, got 0"),
            (lambda: corrupt_actions(keys, zeros, zeros, prob=0.5, num_slots=1,
                                     replacement=(-3,)), table + r", got \(-3,\)"),
            (lambda: corrupt_actions(keys, zeros, zeros, prob=0.5, num_slots=1,
                                     replacement=(0.5, 1.5)), table),
            (lambda: corrupt_actions(keys, zeros, zeros, prob=0.5, num_slots=1, replacement=3),
             table + ", got 3"),
            (lambda: corrupt_actions(keys, zeros, zeros, prob=0.5, num_slots=1, sticky="no"),
             r"sticky must be True or False, got 'no'"),
            (lambda: corrupt_actions(keys, zeros, zeros, prob=0.5, num_slots=1, sticky=True,
                                     replacement=(0, 1)), r"replacement must be None when sticky"),
            (lambda: draw_mask_decisions(keys, prob=0.5, per_frame="no", torch=False),
             r"per_frame must be True or False, got 'no'"),
            (lambda: extract_labels(None, jnp.zeros((1, 128), jnp.uint8)),
             r"game must be a game's name or its GameSpec"),
            (lambda: region_mask([1, 2]), r"region_mask takes Regions"),
            (lambda: apply_masks(frames, jnp.zeros(4, bool), hidden=hidden, fill=fill),
             r"apply must have shape \(4, 2\), got \(4,\)"),
            (lambda: apply_masks(frames[:, 0], jnp.zeros((4, 2), bool), hidden=hidden, fill=fill),
             r"frames must have shape \(B, S, 210, 160, 3\), got \(4, 210, 160, 3\)"),
            (lambda: max_pool(jnp.zeros(5)), r"frames must have shape \(B, 2, \.\.\.\)"),
            (lambda: atari84_frame(jnp.zeros((2, 210, 160), jnp.uint8)),
             r"screen must have shape \(B, height, width, 3\)"),
            (lambda: area_resize(jnp.zeros((2, 210, 160), jnp.uint8), 0, 5, y_axis=1, x_axis=2),
             r"height must be >= 1, got 0"),
            (lambda: area_resize(jnp.zeros((2, 210, 160), jnp.uint8), 5, 5, y_axis=1, x_axis=1),
             r"y_axis and x_axis must be two different axes")):
        with pytest.raises(ValueError, match=match):
            call()
    # inside jit too, when the function is traced (the static arguments have their values)
    with pytest.raises(ValueError, match=purpose + ", got 99"):
        jax.jit(lambda k: purpose_keys(k, 99))(keys)
    with pytest.raises(ValueError, match=r"sticky must be True or False, got 'no'"):
        jax.jit(lambda p: corrupt_actions(keys, zeros, zeros, prob=p, num_slots=1,
                                          sticky="no"))(0.5)
    with pytest.raises(ValueError, match=r"apply must have shape \(4, 2\), got \(4,\)"):
        jax.jit(lambda f: apply_masks(f, jnp.zeros(4, bool), hidden=hidden, fill=fill))(frames)
    # what they take: numpy ints and bools, an array as the action table, a one-screen batch
    assert purpose_keys(keys, np.int64(1)).shape == purpose_keys(keys, Purpose.ACTIONS).shape
    executed, _ = corrupt_actions(keys, zeros, zeros, prob=1.0, num_slots=2,
                                  replacement=np.array([3]))
    assert executed.tolist() == [[3, 3]] * 4
    assert draw_mask_decisions(keys, prob=1.0, per_frame=np.True_, torch=False)[0].all()
    assert apply_masks(frames[:, :1], jnp.ones((4, 1), bool), hidden=hidden,
                       fill=fill).shape == (4, 1, 210, 160, 3)


def test_the_pure_functions_refuse_arrays_of_the_wrong_dtype_and_values():
    """Each was coerced without a word: float actions truncated (1.7 played 1), an int
    ``apply`` combined bit by bit with the mask (255 masked, 254 not, 2 nothing), a float screen
    cast to uint16 (0.9 became black), RAM of 300 read as a score, a 3000 x 3000 image's int32
    sums wrapped around (255 resized to 34); and concept_of gave () for a scalar step under
    sudden and cyclic, (B,) under gradual."""
    from stori_jax.functional import (apply_masks, atari84_frame, dreamer64, extract_labels,
                                      max_pool, push_frame, region_mask, reset_stack, to_gray,
                                      torch_mask)
    from stori_jax.functional.masks import CROP_REGIONS
    from stori_jax.functional.preprocess import area_resize

    keys, zeros = keys_of(0)[:4], jnp.zeros(4, jnp.int32)
    hidden, fill = region_mask(CROP_REGIONS[1])
    frames = jnp.full((4, 2, 210, 160, 3), 255, jnp.uint8)
    gray, no = jnp.zeros((3, 84, 84), jnp.uint8), jnp.zeros(3, bool)
    stack = jnp.zeros((3, 84, 84, 4), jnp.uint8)
    for call, match in (
            (lambda: corrupt_actions(keys, jnp.array([1.7, 2.9, 3.5, 0.0]), zeros, prob=0,
                                     num_slots=1, replacement=(0, 1)),
             r"actions must be an array of action indices .*got dtype float32"),
            (lambda: corrupt_actions(keys, zeros, zeros.astype(bool), prob=0, num_slots=1,
                                     sticky=True), r"prev_executed must be .*got dtype bool"),
            (lambda: corrupt_actions(keys, zeros, zeros, prob=0, num_slots=1, sticky=True,
                                     active=zeros), r"active must be an array of bools"),
            (lambda: apply_masks(frames, jnp.full((4, 2), 2), hidden=hidden, fill=fill),
             r"apply must be an array of bools \(4, 2\) .*got dtype int32"),
            (lambda: apply_masks(frames.astype(jnp.float32), jnp.ones((4, 2), bool),
                                 hidden=hidden, fill=fill), r"frames must be an array of uint8"),
            (lambda: apply_masks(frames, jnp.ones((4, 2), bool), hidden=hidden.astype(int),
                                 fill=fill), r"hidden must be an array of bools"),
            (lambda: torch_mask(jnp.zeros((4, 2), jnp.float32)), r"centres must be .*integer"),
            (lambda: torch_mask(jnp.zeros((4, 3), jnp.int32)), r"centres must have shape"),
            (lambda: atari84_frame(jnp.full((1, 210, 160, 3), 0.9)), r"screen must be .*uint8"),
            (lambda: dreamer64(jnp.zeros((1, 210, 160, 3), jnp.int32)), r"screen must be .*uint8"),
            (lambda: to_gray(jnp.zeros((2, 3), jnp.float32)), r"rgb must be .*uint8"),
            (lambda: max_pool(jnp.zeros((1, 2, 4, 3), jnp.int32)), r"frames must be .*uint8"),
            (lambda: reset_stack(jnp.zeros((3, 84, 84), jnp.float32)), r"frame must be .*uint8"),
            (lambda: reset_stack(jnp.zeros((84, 84), jnp.uint8)), r"frame must have shape"),
            (lambda: push_frame(stack, jnp.full((3, 84, 84), 0.7), no),
             r"frame must be an array of uint8"),
            (lambda: push_frame(stack.astype(jnp.int32), gray, no), r"stack must be .*uint8"),
            (lambda: push_frame(stack[:2], gray, no), r"stack must have shape \(3, 84, 84, 4\)"),
            (lambda: push_frame(stack, gray, jnp.array([0, 1, 2])),
             r"new_episode must be an array of bools"),
            (lambda: push_frame(stack, gray, no[:2]), r"new_episode must have shape \(3,\)"),
            (lambda: area_resize(jnp.full((1, 2900, 2900), 255, jnp.uint8), 1, 1, y_axis=1,
                                 x_axis=2), r"image is too large for area_resize's int32 sums"),
            (lambda: extract_labels("Breakout", jnp.full((1, 128), 300, jnp.int32)),
             r"ram must hold bytes \(values in \[0, 255\]\), got values 300\.\.300"),
            (lambda: concept_of(keys, 1.5, "cyclic", 1),
             r"episode_step must be an array of agent steps \(an integer dtype\)"),
            (lambda: concept_of(keys, jnp.arange(5), "sudden", 1),
             r"concept_of takes keys \(B,\) .*got keys \(4, 2\) and episode_step \(5,\)"),
            (lambda: concept_of(jnp.zeros((2, 2, 2), jnp.uint32), 1, "sudden", 1),
             r"got keys \(2, 2, 2\)"),
            # raw key data must end in a key's words: (4,) is no batch of keys, () no key
            (lambda: concept_of(jnp.zeros(4, jnp.uint32), 1, "sudden", 1),
             r"got keys of shape \(4,\) and dtype uint32"),
            (lambda: concept_of(jnp.zeros((), jnp.uint32), 1, "gradual", 1),
             r"got keys of shape \(\) and dtype uint32")):
        with pytest.raises(ValueError, match=match):
            call()
    with pytest.raises(ValueError, match=r"apply must be an array of bools"):  # inside jit too
        jax.jit(lambda a: apply_masks(frames, a, hidden=hidden, fill=fill))(jnp.ones((4, 2), int))
    # what they take: int lists, any int width, the largest image the sums hold
    assert corrupt_actions(keys, [1, 2, 3, 0], np.zeros(4, np.int64), prob=0, num_slots=1,
                           replacement=(0, 1))[0].ravel().tolist() == [1, 2, 3, 0]
    assert area_resize(jnp.full((1, 2898, 2898), 255, jnp.uint8), 1, 1, y_axis=1,
                       x_axis=2).tolist() == [[[255]]]  # 2900 x 2900's rounding wrapped to 0
    assert extract_labels("Breakout", jnp.full((1, 128), 3, jnp.int32))["score"].shape == (1,)
    # one shape, (B,), whatever the schedule, for a scalar step as for a (B,) one
    # (one concept per env for raw or typed keys, and per key when vmapped over single envs,
    # as a gymnax-style env written for one env is)
    typed = jax.random.split(jax.random.key(0), 4)
    for schedule in ("sudden", "cyclic", "gradual"):
        for batch in (keys, typed):
            assert concept_of(batch, 7, schedule, 3).shape == (4,), schedule
            assert concept_of(batch, jnp.arange(4), schedule, 3).shape == (4,), schedule
            one_by_one = jax.vmap(lambda k, s: concept_of(k, s, schedule, 3))(batch, jnp.arange(4))
            np.testing.assert_array_equal(one_by_one, concept_of(batch, jnp.arange(4), schedule, 3))
            assert concept_of(batch[0], 5, schedule, 3).shape == ()
    assert concept_of(keys, 3, "sudden", 3).tolist() == [1] * 4


def test_the_checks_take_bfloat16_and_0d_bool_arrays():
    """A bfloat16 probability was refused called directly ("must be a number") but taken under
    jit; Config.ram_observation refused np.True_, and check_bool a 0-d bool array, which every
    other flag took."""
    from stori_jax import Config, ObservationMask
    from stori_jax.checks import check_bool, check_int
    from stori_jax.functional import draw_mask_decisions

    half = jnp.array(0.5, jnp.bfloat16)
    assert ActionNoise(prob=half).prob == 0.5 and ObservationMask("crop", 1, half).prob == 0.5
    direct = draw_mask_decisions(keys_of(0)[:64], prob=half, per_frame=True, torch=False)[0]
    jitted = jax.jit(lambda p: draw_mask_decisions(keys_of(0)[:64], prob=p, per_frame=True,
                                                   torch=False)[0])(half)
    assert (direct == jitted).all()
    assert Config(ram_observation=np.True_).ram_observation is True
    assert check_bool("x", jnp.array(True)) is True and check_bool("x", np.array(False)) is False
    with pytest.raises(ValueError, match="x must be True or False, got 1"):
        check_bool("x", jnp.array(1))
    with pytest.raises(ValueError, match="n must be an int, got True"):
        check_int("n", jnp.array(True))


# ---------------------------------------------------------------------------------------------
# Keys and event uniforms
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("partitionable", [True, False])
def test_env_keys_independent_of_batch_size(partitionable):
    """Env i's key is a function of (step key, i) alone, under either threefry setting (a
    split of the step key into B keys is not: its first k keys change with B when
    jax_threefry_partitionable is off)."""
    step_key = jax.random.PRNGKey(3)
    with jax.threefry_partitionable(partitionable):
        big, small = np.asarray(env_keys(step_key, 8)), np.asarray(env_keys(step_key, 3))
    np.testing.assert_array_equal(big[:3], small)
    assert len({tuple(k) for k in big}) == 8
    a = np.asarray(purpose_keys(env_keys(step_key, 8), Purpose.ACTIONS))
    b = np.asarray(purpose_keys(env_keys(step_key, 8), Purpose.OBSERVATION))
    assert len({tuple(k) for k in np.concatenate([a, b, big])}) == 24
    assert len(set(int(p) for p in Purpose)) == len(Purpose)


def test_event_uniforms():
    u = np.asarray(event_uniforms(keys_of(17), SLOTS))
    assert u.shape == (B, SLOTS, 2) and u.dtype == np.float32
    assert u.min() >= 0.0 and u.max() < 1.0
    for p in (0.001, 0.3):
        assert within_binomial((u[..., 0] < p).sum(), B * SLOTS, p)
    assert abs(np.corrcoef(u[..., 0].ravel(), u[..., 1].ravel())[0, 1]) < SIGMAS / np.sqrt(u.size)
    np.testing.assert_array_equal(u, np.asarray(event_uniforms(keys_of(17), SLOTS)))
    assert (u != np.asarray(event_uniforms(keys_of(18), SLOTS))).mean() > 0.99
    vu = np.asarray(jax.jit(jax.vmap(lambda k: event_uniforms(k, SLOTS)))(
        jnp.stack([keys_of(17), keys_of(18)])))
    np.testing.assert_array_equal(vu[0], u)


def test_keys_functions_keys_jit_and_vmap():
    k1, k2 = jax.random.PRNGKey(1), jax.random.PRNGKey(2)
    a = np.asarray(env_keys(k1, 8))
    np.testing.assert_array_equal(a, np.asarray(env_keys(k1, 8)))  # same key, same keys
    assert not (a == np.asarray(env_keys(k2, 8))).all(axis=1).any()  # other key, other keys
    jitted = jax.jit(env_keys, static_argnums=1)
    np.testing.assert_array_equal(np.asarray(jitted(k1, 8)), a)
    both = np.asarray(jax.vmap(lambda k: env_keys(k, 8))(jnp.stack([k1, k2])))
    np.testing.assert_array_equal(both[0], a)
    np.testing.assert_array_equal(both[1], np.asarray(env_keys(k2, 8)))
    p = np.asarray(purpose_keys(jnp.asarray(a), Purpose.DRIFT))
    np.testing.assert_array_equal(
        np.asarray(jax.jit(purpose_keys, static_argnums=1)(jnp.asarray(a), Purpose.DRIFT)), p)
    vp = jax.vmap(lambda k: purpose_keys(k, Purpose.DRIFT))(jnp.asarray(both))
    np.testing.assert_array_equal(np.asarray(vp)[0], p)


def test_concept2_probability_vmap():
    steps = jnp.asarray(np.arange(40).reshape(2, 20), jnp.int32)
    for schedule in ("sudden", "cyclic", "gradual"):
        out = jax.vmap(lambda s: concept2_probability(s, schedule, 7))(steps)
        np.testing.assert_array_equal(np.asarray(out).ravel(), np.asarray(
            concept2_probability(steps.ravel(), schedule, 7)))
