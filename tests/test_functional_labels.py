"""Type 0 labels (stori_jax.functional.extract_labels) on real RAM from ale-py."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from _env_support import new_ale

from stori_jax import get_game
from stori_jax.functional import extract_labels

# Breakout minimal action set: NOOP, FIRE, RIGHT, LEFT
FIRE, RIGHT, LEFT, NOOP = 1, 2, 3, 0
BALL_X, PADDLE_X = 99, 72


def ale_and_actions(rom_id):
    ale = new_ale(rom_id)
    return ale, ale.getMinimalActionSet()


@functools.lru_cache(maxsize=None)
def breakout_play(frames: int = 4000):
    """Play Breakout by tracking the ball from RAM; (RAM after every frame (N, 128) uint8,
    running sum of act() rewards after every frame (N,))."""
    ale, actions = ale_and_actions("breakout")
    assert [a.name for a in actions] == ["NOOP", "FIRE", "RIGHT", "LEFT"]
    rams, totals = [], []
    total, lives, launch = 0, ale.lives(), True
    for f in range(frames):
        ram = ale.getRAM().astype(np.int32)
        if ale.lives() < lives:
            lives, launch = ale.lives(), True
        if launch and f % 8 == 0:
            a, launch = FIRE, False
        else:  # move the paddle toward the ball
            target = ram[PADDLE_X] + 4
            a = RIGHT if ram[BALL_X] > target + 2 else LEFT if ram[BALL_X] < target - 2 else NOOP
        total += ale.act(actions[a])
        if ale.game_over():
            break
        rams.append(ale.getRAM().copy())
        totals.append(total)
    return np.stack(rams), np.array(totals)


def bcd(v):
    return (v >> 4) * 10 + (v & 15)


def test_breakout_score_label_equals_running_reward_on_real_ram():
    rams, totals = breakout_play()
    labels = extract_labels(get_game("Breakout"), jnp.asarray(rams))
    score = np.asarray(labels["score"])
    assert score.shape == totals.shape and score.dtype == np.int32
    np.testing.assert_array_equal(score, totals)  # on every frame
    ram = rams.astype(np.int64)
    np.testing.assert_array_equal(score, 100 * bcd(ram[:, 76]) + bcd(ram[:, 77]))
    # the play is good enough to exercise several point values and the hundreds byte
    assert len(np.unique(np.diff(totals))) >= 3, np.unique(np.diff(totals))
    assert totals[-1] >= 100, totals[-1]
    # the other labels are the RAM bytes of docs/spec.md section 5
    np.testing.assert_array_equal(np.asarray(labels["ball_x"]), rams[:, 99])
    np.testing.assert_array_equal(np.asarray(labels["ball_y"]), rams[:, 101])
    np.testing.assert_array_equal(np.asarray(labels["player_x"]), rams[:, 72])


def test_breakout_score_label_bcd_synthetic():
    ram = np.zeros((4, 128), np.uint8)
    ram[:, 76] = [0x00, 0x01, 0x09, 0x12]
    ram[:, 77] = [0x07, 0x00, 0x99, 0x34]
    score = np.asarray(extract_labels(get_game("Breakout"), jnp.asarray(ram))["score"])
    np.testing.assert_array_equal(score, [7, 100, 999, 1234])


@pytest.mark.parametrize("rom_id,frames", [("boxing", 1500), ("gopher", 1500)])
def test_score_labels_track_reward_on_real_ram(rom_id, frames):
    """Boxing: reward = change of player - enemy score; Gopher: reward = change of the score."""
    game = get_game(rom_id)
    ale, actions = ale_and_actions(rom_id)
    rng = np.random.default_rng(0)
    rams, totals, total = [], [], 0
    for _ in range(frames):
        total += ale.act(actions[rng.integers(len(actions))])
        if ale.game_over():
            break
        rams.append(ale.getRAM().copy())
        totals.append(total)
    labels = extract_labels(game, jnp.asarray(np.stack(rams)))
    if rom_id == "boxing":
        value = np.asarray(labels["player_score"]) - np.asarray(labels["enemy_score"])
    else:
        value = np.asarray(labels["score"])
    np.testing.assert_array_equal(value, np.array(totals))
    assert np.any(np.diff(totals) != 0)  # something was scored


def test_extract_labels_jit_and_vmap():
    rams, _ = breakout_play()
    game = get_game("Breakout")
    batch = jnp.asarray(rams[:64].reshape(2, 32, 128))
    out = jax.jit(jax.vmap(lambda r: extract_labels(game, r)))(batch)
    for name, value in out.items():
        assert value.shape == (2, 32) and value.dtype == jnp.int32
        np.testing.assert_array_equal(np.asarray(value).ravel(),
                                      np.asarray(extract_labels(game, rams[:64])[name]))


def test_boxing_knockout_scores_100_on_real_ram():
    """A boxer at 99 who lands a punch wins by knockout: the game writes 0xC0 to its score byte
    and ends the bout; ALE counts that as 100 (reward +1), and so must the labels (a BCD read
    gives 120). The enemy's byte decodes the same way."""
    ale, actions = ale_and_actions("boxing")
    ale.act(actions[0])
    ale.setRAM(18, 0x99)
    ale.act(actions[0])
    rng = np.random.default_rng(0)
    for _ in range(2000):
        reward = ale.act(actions[rng.integers(len(actions))])
        if ale.game_over():
            break
    assert ale.game_over() and reward == 1
    ram = ale.getRAM().copy()
    assert ram[18] == 0xC0
    enemy_knockout = ram.copy()
    enemy_knockout[18:20] = (0x37, 0xC0)
    labels = extract_labels(get_game("Boxing"), jnp.asarray(np.stack([ram, enemy_knockout])))
    assert np.asarray(labels["player_score"]).tolist() == [100, 37]
    assert np.asarray(labels["enemy_score"]).tolist() == [bcd(int(ram[19])), 100]


@pytest.mark.parametrize("ram, error", [
    (np.zeros((1, 10), np.uint8), r"shape \(\.\.\., 128\) .* got shape \(1, 10\)"),
    (np.zeros((128, 3), np.uint8), r"got shape \(128, 3\)"),   # a batch transposed
    (np.uint8(7), r"got shape \(\)"),
    (np.zeros((2, 128), np.int8), "as uint8 .* got dtype int8"),
    (np.zeros((2, 128), np.float32), "got dtype float32"),
    (np.zeros((2, 128), bool), "got dtype bool"),
])
def test_extract_labels_refuses_what_is_not_ram(ram, error):
    """RAM of the wrong length read clamped addresses (a 10-byte row gave BankHeist's robber_x
    from byte 9), a transposed batch gave 128 rows of labels, and int8 RAM decoded scores as
    negative numbers: each is now a ValueError naming the shape or dtype."""
    with pytest.raises(ValueError, match=error):
        extract_labels("BankHeist", ram)
    for ok in (np.zeros((2, 128), np.uint8), np.zeros((3, 2, 128), np.int32),
               np.zeros(128, np.uint16)):
        assert extract_labels("BankHeist", ok)["robber_x"].shape == ok.shape[:-1]


@pytest.mark.parametrize("bad", [256, -1])
def test_extract_labels_refuses_a_value_just_outside_a_byte(bad):
    """A wide integer type must hold bytes: 256 or -1 anywhere is a ValueError naming the
    range (the check is exactly [0, 255], no value off by one slips through), while 0 and 255,
    the range's own ends, are accepted."""
    ram = np.zeros((1, 128), np.int32)
    ram[0, 99] = bad
    with pytest.raises(ValueError, match=r"values in \[0, 255\]"):
        extract_labels("Breakout", ram)
    with pytest.raises(ValueError, match=r"values in \[0, 255\]"):
        extract_labels("Breakout", np.full((1, 128), bad, np.int32))
    for edge in (0, 255):
        ram[0, 99] = edge
        assert np.asarray(extract_labels("Breakout", ram)["ball_x"]).tolist() == [edge]
        full = np.full((1, 128), edge, np.int32)
        assert np.asarray(extract_labels("Breakout", full)["ball_x"]).tolist() == [edge]
