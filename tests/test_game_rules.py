"""The STORI game facts as pure functions: regions, mode tables, RAM-obs modes, event rules, labels.

Everything runs on synthetic RAM arrays (no emulator), except one sanity test that drives each
game's rules on real RAM read from ``ale_py.ALEInterface``.
"""

from __future__ import annotations

import numpy as np
import pytest

from stori_jax.games import bankheist, boxing, breakout, gopher
from stori_jax.games.base import (BLACK, NO_EVENT, SCREEN_HEIGHT, SCREEN_WIDTH, EventOutcome,
                                  Region)

GAMES = {"Breakout": breakout, "Boxing": boxing, "Gopher": gopher, "BankHeist": bankheist}
P = 0.5
BELOW = float(np.nextafter(P, 0.0))  # u just below p: fires
AT = P  # u == p: does not fire


def make_ram(values=None):
    ram = np.zeros(128, np.uint8)
    for address, value in (values or {}).items():
        ram[address] = value
    return ram


def post(rule, prev, ram, start=None, state=None, u=0.0, u_choice=0.0, p=P, episode_frame=1000):
    start = make_ram() if start is None else start
    state = rule.new_state() if state is None else state
    out = rule.post_frame(prev, ram, start, state, u, u_choice, p, episode_frame)
    assert isinstance(out, EventOutcome)
    assert_python_writes(out.writes)
    if not out.fired:
        assert out == NO_EVENT
    return out


def pre(rule, start, state, u=0.0, p=P, decide=True):
    writes, fired = rule.pre_frame(start, state, u, p, decide)
    assert_python_writes(writes)
    assert isinstance(fired, bool)
    return writes, fired


def assert_python_writes(writes):
    assert isinstance(writes, dict)
    for address, value in writes.items():
        assert type(address) is int and type(value) is int, (address, value)
        assert 0 <= address < 128 and 0 <= value <= 255, (address, value)


# ---------------------------------------------------------------------------------------------
# Spec tables: mode numbers, regions, fills
# ---------------------------------------------------------------------------------------------

SPEC_MODES = {  # game: (blackout modes, RAM modes, event modes); 0 ("none") is never in a table
    "Breakout": (range(1, 12), range(1, 3), range(1, 4)),
    "Boxing": (range(1, 10), range(1, 4), range(1, 4)),
    "Gopher": (range(1, 19), range(1, 6), range(1, 4)),
    "BankHeist": (range(1, 11), range(1, 7), range(1, 5)),
}

SPEC_GAME = {  # name: (rom_id, num_actions)
    "Breakout": ("breakout", 4), "Boxing": ("boxing", 18), "Gopher": ("gopher", 8),
    "BankHeist": ("bank_heist", 18),
}


@pytest.mark.parametrize("name", GAMES)
def test_mode_numbers_match_spec(name):
    module = GAMES[name]
    blackout, ram_modes, events = SPEC_MODES[name]
    game = module.GAME
    assert sorted(game.blackout_modes) == list(blackout)
    assert sorted(game.ram_obs_modes) == list(ram_modes)
    assert sorted(game.event_modes) == list(events)
    assert game.blackout_modes is module.BLACKOUT or game.blackout_modes == module.BLACKOUT
    assert game.ram_obs_modes == module.RAM_OBS and game.event_modes == module.EVENTS
    assert game.regions == module.REGIONS and game.labels == module.LABELS
    assert (game.name, game.rom_id, game.num_actions) == (name, *SPEC_GAME[name])


@pytest.mark.parametrize("name", GAMES)
def test_every_blackout_region_is_on_screen(name):
    game = GAMES[name].GAME
    for mode, bm in game.blackout_modes.items():
        assert bm.regions, (name, mode)
        for r in bm.regions:
            assert isinstance(r, Region)
            assert 0 <= r.x0 <= r.x1 < SCREEN_WIDTH, (name, mode, r)
            assert 0 <= r.y0 <= r.y1 < SCREEN_HEIGHT, (name, mode, r)
            assert len(r.fill) == 3 and all(0 <= c <= 255 for c in r.fill)
            assert r in game.regions.values()
    with pytest.raises(ValueError):
        Region(0, SCREEN_WIDTH, 0, 10)


def names_of(module, mode):
    by_region = {}
    for name, region in module.REGIONS.items():
        by_region.setdefault(region, name)
    return tuple(by_region[r] for r in module.BLACKOUT[mode].regions)


def test_breakout_regions_and_modes():
    R = breakout.REGIONS
    assert R["blocks"] == Region(8, 151, 57, 92)
    assert R["paddle"] == Region(7, 152, 189, 195)
    assert R["score"] == Region(2, 158, 3, 16)
    assert R["ball_band_top"] == Region(8, 151, 105, 130)
    assert R["ball_band_middle"] == Region(8, 151, 131, 156)
    assert R["ball_band_bottom"] == Region(8, 151, 157, 182)
    assert all(r.fill == BLACK for r in R.values())
    bands = ("ball_band_top", "ball_band_middle", "ball_band_bottom")
    expected = {1: ("blocks", "paddle", "score") + bands, 2: ("blocks",), 3: ("paddle",),
                4: ("score",), 5: bands[:1], 6: bands[1:2], 7: bands[2:],
                8: ("blocks", "paddle"), 9: ("blocks", "score"), 10: (bands[0], bands[2]),
                11: bands}
    for mode, names in expected.items():
        assert set(names_of(breakout, mode)) == set(names), mode


def test_boxing_regions_and_modes():
    ring = (110, 156, 66)
    R = boxing.REGIONS
    assert R["full_ring"] == Region(32, 127, 36, 176, ring)
    assert R["left_ring"] == Region(32, 80, 36, 176, ring)
    assert R["right_ring"] == Region(81, 127, 36, 176, ring)
    assert R["enemy_score"] == Region(87, 134, 1, 16, ring)
    assert R["player_score"] == Region(33, 69, 1, 16, ring)
    assert R["clock"] == Region(57, 97, 14, 27, ring)
    expected = {1: set(R), 2: {"left_ring"}, 3: {"right_ring"}, 4: {"full_ring"},
                5: {"enemy_score"}, 6: {"player_score"}, 7: {"enemy_score", "player_score"},
                8: {"clock"}, 9: {"enemy_score", "player_score", "clock"}}
    for mode, names in expected.items():
        assert set(names_of(boxing, mode)) == names, mode


GOPHER_ATTACK_ROWS = [((146, 150), (101, 209, 174)), ((151, 155), (117, 231, 194)),
                      ((156, 160), (132, 252, 212))]
BEFORE_DUG, AFTER_DUG = (187, 159, 71), (223, 183, 85)
GOPHER_ROWS = {"row0": (161, 168), "row1": (168, 176), "row2": (176, 182), "row3": (183, 194)}


def attack(x0, x1):
    return [Region(x0, x1, y0, y1, fill) for (y0, y1), fill in GOPHER_ATTACK_ROWS]


def test_gopher_regions_and_modes():
    B = gopher.BLACKOUT
    left, right = attack(0, 59), attack(100, 159)
    underground_full = Region(0, 159, 161, 200, BEFORE_DUG)
    underground_offset = Region(0, 159, 164, 200, BEFORE_DUG)
    rows = {k: Region(0, 159, y0, y1, BEFORE_DUG) for k, (y0, y1) in GOPHER_ROWS.items()}
    rows_dug = {k: r.with_fill(AFTER_DUG) for k, r in rows.items()}
    farmer_full, farmer_nose = Region(0, 159, 87, 145), Region(0, 159, 104, 145)
    duck, score = Region(0, 159, 26, 56), Region(0, 159, 0, 25)
    # mode 1: paint order matters (later regions overwrite earlier ones)
    assert B[1].regions == (underground_full, underground_offset, *rows.values(), farmer_full,
                            farmer_nose, duck, score, *left, *right)
    assert B[2].regions == (*left, *right)
    assert B[3].regions == tuple(left)
    assert B[4].regions == tuple(right)
    assert B[5].regions == (underground_full,)
    assert B[6].regions == (underground_offset,)
    for k, row in enumerate(GOPHER_ROWS):
        assert B[7 + 2 * k].regions == (rows[row],)
        assert B[8 + 2 * k].regions == (rows_dug[row],)
    assert B[15].regions == (farmer_full,)
    assert B[16].regions == (farmer_nose,)
    assert B[17].regions == (duck,)
    assert B[18].regions == (score,)


def test_gopher_mode1_paint_order_on_a_screen():
    """Painting mode 1 in order gives every band its own colour (attack rows in their row
    colours, the rest of rows 146..160 untouched, underground before-dug, the rest black)."""
    screen = np.full((SCREEN_HEIGHT, SCREEN_WIDTH, 3), 255, np.uint8)
    for r in gopher.BLACKOUT[1].regions:
        screen[r.y0:r.y1 + 1, r.x0:r.x1 + 1] = r.fill
    assert tuple(screen[148, 10]) == (101, 209, 174)
    assert tuple(screen[158, 120]) == (132, 252, 212)
    assert tuple(screen[150, 80]) == (255, 255, 255)  # between the attack regions: untouched
    assert tuple(screen[190, 80]) == BEFORE_DUG
    assert tuple(screen[100, 80]) == BLACK and tuple(screen[10, 0]) == BLACK


def test_bankheist_regions_and_modes():
    R = bankheist.REGIONS
    blue, brown = (0, 0, 148), (162, 98, 33)
    assert R["top_wall"] == Region(12, 147, 37, 44)
    assert R["left_wall"] == Region(12, 15, 37, 177)
    assert R["bottom_wall"] == Region(12, 147, 173, 177)
    assert R["right_wall"] == Region(144, 147, 37, 177)
    assert R["fuel"] == Region(12, 73, 11, 36, blue)
    assert R["lives"] == Region(78, 147, 11, 36, blue)
    assert R["score"] == Region(12, 147, 178, 186, brown)
    walls = {"top_wall", "left_wall", "bottom_wall", "right_wall"}
    expected = {1: walls | {"fuel", "lives", "score"}, 2: walls, 3: {"top_wall"},
                4: {"left_wall"}, 5: {"bottom_wall"}, 6: {"right_wall"},
                7: {"left_wall", "right_wall"}, 8: {"fuel"}, 9: {"lives"}, 10: {"score"}}
    for mode, names in expected.items():
        assert set(names_of(bankheist, mode)) == names, mode


def test_replacement_actions_defaults():
    assert bankheist.GAME.default_replacement_actions == tuple(range(10))
    for module in (breakout, boxing, gopher):
        assert module.GAME.default_replacement_actions is None


# ---------------------------------------------------------------------------------------------
# RAM observation modes
# ---------------------------------------------------------------------------------------------

def test_breakout_ram_obs():
    w = breakout.RAM_OBS[1].writes(make_ram())
    assert w == breakout.NUS_PATTERN and 4 not in w and len(w) == 29
    assert breakout.RAM_OBS[2].writes(make_ram({99: 50, 101: 60})) == {99: 0, 101: 0}


def test_breakout_nus_pattern_has_the_spec_values():
    """docs/spec.md section 5, RAM mode 1, typed in from it (not the library's copy): these
    29 block bytes and no others, whatever the current RAM."""
    spec = {0: 62, 1: 61, 2: 60, 3: 62, 5: 60, 6: 240, 7: 127, 8: 120, 9: 112, 10: 119, 11: 120,
            12: 0, 13: 240, 14: 240, 15: 240, 16: 240, 17: 240, 18: 57, 19: 218, 20: 219,
            21: 219, 22: 219, 23: 219, 24: 239, 25: 239, 26: 238, 27: 237, 28: 235, 29: 231}
    rng = np.random.default_rng(0)
    for ram in (make_ram(), rng.integers(0, 256, 128, dtype=np.uint8)):
        assert breakout.RAM_OBS[1].writes(ram) == spec


def test_boxing_ram_obs():
    ram = make_ram({1: 10, 2: 20, 3: 30})
    assert boxing.RAM_OBS[1].writes(ram) == {3: 214}
    assert boxing.RAM_OBS[2].writes(ram) == {2: 214}
    assert boxing.RAM_OBS[3].writes(ram) == {1: 214}


def test_gopher_ram_obs():
    ram = make_ram({52: 0b11110111, 92: 40})
    assert gopher.RAM_OBS[1].writes(ram) == {52: 0b11110011}
    assert gopher.RAM_OBS[2].writes(ram) == {52: 0b11110101}
    assert gopher.RAM_OBS[3].writes(ram) == {52: 0b11110110}
    assert gopher.RAM_OBS[4].writes(ram) == {52: 0}
    assert gopher.RAM_OBS[5].writes(ram) == {92: 128}
    assert gopher.RAM_OBS[5].writes(make_ram({92: 128})) is None
    for mode in gopher.RAM_OBS:
        w = gopher.RAM_OBS[mode].writes(ram)
        assert_python_writes(w)


def test_bankheist_ram_obs():
    ram = make_ram({0: 6, 8: 80, 28: 70, 86: 9, 66: 3, 68: 4, 24: 253, 25: 254, 26: 253})
    assert bankheist.RAM_OBS[1].writes(ram) == {8: 155, 28: 12}
    assert bankheist.RAM_OBS[2].writes(ram) == {86: 0}
    assert bankheist.RAM_OBS[3].writes(ram) == {66: 0, 68: 0}
    for city, colour in [(0, 30), (1, 190), (2, 46), (3, 126), (4, 30), (6, 46), (11, 126)]:
        assert bankheist.RAM_OBS[4].writes(make_ram({0: city})) == {69: colour}
    assert bankheist.RAM_OBS[5].writes(ram) == {24: 255, 26: 255}
    assert bankheist.RAM_OBS[6].writes(ram) == {25: 255}
    none = make_ram({24: 255, 25: 255, 26: 255})
    assert bankheist.RAM_OBS[5].writes(none) is None
    assert bankheist.RAM_OBS[6].writes(none) is None
    assert bankheist.RAM_OBS[5].writes(make_ram({24: 254})) is None
    assert bankheist.RAM_OBS[6].writes(make_ram({26: 254})) == {26: 255}
    for mode in bankheist.RAM_OBS:
        assert_python_writes(bankheist.RAM_OBS[mode].writes(ram))


# ---------------------------------------------------------------------------------------------
# Breakout events
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("mode", [1, 2])
def test_breakout_block_hit_cancel(mode):
    rule = breakout.EVENTS[mode]
    start = make_ram({i: 255 for i in range(36)})
    prev = start.copy()
    prev[7] = 0  # an older hit: differs from start, not from prev
    prev[11] = 0b1111_1110  # a block of byte 11 was hit earlier (not cancelled)
    ram = prev.copy()
    ram[3] = 127
    ram[20] = 0
    ram[11] = 0b1111_1100  # another block of byte 11 is hit now
    ram[40] = 9  # outside the block RAM: ignored
    out = post(rule, prev, ram, start, u=BELOW)
    # the previous values come back: byte 11's older hit stays (its start value would respawn it)
    assert out.fired and out.writes == {3: 255, 20: 255, 11: 0b1111_1110}
    assert out.zero_reward == (mode == 2) and not out.cancel_next_reward
    assert post(rule, prev, ram, start, u=AT) == NO_EVENT
    assert post(rule, prev, ram, start, u=0.0, p=0.0) == NO_EVENT
    # no block differs from the start: nothing to cancel
    assert post(rule, start, start.copy(), start, u=0.0) == NO_EVENT
    # differs from start but nothing hit this frame
    assert post(rule, prev, prev.copy(), start, u=0.0) == NO_EVENT
    # blocks changed this frame, but the wall is back at its start (a new wall after a cleared
    # one): nothing is a hit to cancel
    assert post(rule, prev, start.copy(), start, u=0.0) == NO_EVENT


def test_breakout_regenerate_block():
    rule = breakout.EVENTS[3]
    start = make_ram({i: 255 for i in range(36)})
    ram = start.copy()
    ram[[4, 10, 30]] = [1, 2, 3]
    assert post(rule, ram, ram, start, u=BELOW, u_choice=0.0).writes == {4: 255}
    assert post(rule, ram, ram, start, u=BELOW, u_choice=0.5).writes == {10: 255}
    assert post(rule, ram, ram, start, u=BELOW, u_choice=0.999).writes == {30: 255}
    assert post(rule, ram, ram, start, u=AT) == NO_EVENT
    assert post(rule, start, start.copy(), start, u=0.0) == NO_EVENT


def test_breakout_labels():
    ram = make_ram({99: 11, 101: 22, 72: 33, 76: 0x01, 77: 0x23}).astype(np.int32)
    L = breakout.LABELS
    assert (L["ball_x"](ram), L["ball_y"](ram), L["player_x"](ram), L["score"](ram)) == (
        11, 22, 33, 123)
    bitmap = make_ram({a: 100 + a for a in range(36)}).astype(np.int32)
    assert [int(L[f"block_bitmap_{a}"](bitmap)) for a in range(36)] == list(range(100, 136))
    assert sum(name.startswith("block_bitmap_") for name in L) == 36
    colours = make_ram({62: 200, 64: 1, 65: 2, 66: 3, 67: 4, 68: 5, 69: 6, 81: 7, 83: 8, 85: 9})
    colours = colours.astype(np.int32)
    assert int(L["ball_paddle_colour"](colours)) == 200
    assert [int(L[f"block_row_colour_{k}"](colours)) for k in range(6)] == [1, 2, 3, 4, 5, 6]
    assert [int(L[f"score_digit_{k}"](colours)) for k in range(3)] == [7, 8, 9]


# ---------------------------------------------------------------------------------------------
# Boxing events
# ---------------------------------------------------------------------------------------------

def test_boxing_colour_flip_toggles_and_reapplies():
    rule = boxing.EVENTS[1]
    start = make_ram({1: 10, 2: 20})
    state = rule.new_state()
    assert state == {"flipped": False}
    normal, swapped = {1: 10, 2: 20}, {1: 20, 2: 10}
    assert pre(rule, start, state, u=AT) == (normal, False)  # u == p: no toggle, still writes
    assert pre(rule, start, state, u=BELOW) == (swapped, True)
    assert state["flipped"] is True
    # later frames of the same step: no decision, even with u < p; the colours are re-applied
    for _ in range(3):
        assert pre(rule, start, state, u=0.0, decide=False) == (swapped, False)
    assert state["flipped"] is True
    assert pre(rule, start, state, u=0.9) == (swapped, False)
    assert pre(rule, start, state, u=0.1) == (normal, True)  # toggles back
    assert state["flipped"] is False
    assert pre(rule, start, state, u=0.0, decide=False) == (normal, False)
    assert rule.new_state() == {"flipped": False}  # a fresh state per episode


def test_boxing_hit_cancel():
    rule = boxing.EVENTS[2]
    prev = make_ram({18: 0x09, 19: 0x05})
    ram = prev.copy()
    ram[18] = 0x10
    out = post(rule, prev, ram, u=BELOW)
    assert out.fired and out.writes == {18: 0x09}
    assert out.zero_reward and out.cancel_next_reward
    enemy = prev.copy()
    enemy[19] = 0x07
    assert post(rule, prev, enemy, u=0.0).writes == {19: 0x05}
    assert post(rule, prev, ram, u=AT) == NO_EVENT
    both = ram.copy()
    both[19] = 0x06
    assert post(rule, prev, both, u=0.0) == NO_EVENT  # both changed: not exactly one
    other = prev.copy()
    other[32] = 77
    assert post(rule, prev, other, u=0.0) == NO_EVENT  # no score changed


def test_boxing_displace_to_corners():
    rule = boxing.EVENTS[3]
    start = make_ram({32: 30, 34: 4, 33: 109, 35: 87})
    state = rule.new_state()
    writes, fired = pre(rule, start, state, u=BELOW)
    assert fired and writes == {32: 109, 34: 87, 33: 30, 35: 4}
    assert pre(rule, start, state, u=AT) == ({}, False)
    assert pre(rule, start, state, u=0.0, decide=False) == ({}, False)


def test_boxing_labels():
    ram = make_ram({32: 1, 34: 2, 33: 3, 35: 4, 18: 0x42, 19: 0x17, 16: 0x1B, 17: 0x59,
                    1: 14, 2: 0, 3: 214, 4: 208})
    L = boxing.LABELS
    got = {k: int(f(ram.astype(np.int32))) for k, f in L.items()}
    assert got == {"player_x": 1, "player_y": 2, "enemy_x": 3, "enemy_y": 4, "player_score": 42,
                   "enemy_score": 17, "clock_minutes": 1, "clock_seconds": 59,
                   "player_colour": 14, "enemy_colour": 0, "ring_colour": 214, "clock_colour": 208}


# ---------------------------------------------------------------------------------------------
# Gopher events
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("mode", [1, 2])
def test_gopher_fill_undone_dig_kept(mode):
    rule = gopher.EVENTS[mode]
    prev = make_ram({0: 0b0101, 7: 0b1111_0000, 23: 0b1000_0001, 40: 255, 49: 0x09, 50: 0x90})
    ram = prev.copy()
    ram[0] = 0b0110  # bit 0 filled, bit 1 dug
    ram[7] = 0b1011_0000  # bit 6 filled
    ram[23] = 0b1000_0011  # only dug
    ram[40] = 0  # outside the underground: ignored
    ram[49], ram[50] = 0x10, 0x10  # the fill's 20 points: score 990 -> 1010 (BCD)
    out = post(rule, prev, ram, u=BELOW)
    assert out.fired and out.writes == {0: 0b0111, 7: 0b1111_0000}
    assert out.zero_reward == (mode == 2) and not out.cancel_next_reward
    assert post(rule, prev, ram, u=AT) == NO_EVENT
    # the same clearing without points is the game refilling the underground for a new round
    unscored = ram.copy()
    unscored[49], unscored[50] = prev[49], prev[50]
    assert post(rule, prev, unscored, u=0.0) == NO_EVENT
    # digging alone (bits set) is never undone
    dig = prev.copy()
    dig[5] = 0b11
    dig[23] = 0b1100_0001
    assert post(rule, prev, dig, u=0.0) == NO_EVENT
    assert post(rule, prev, prev.copy(), u=0.0) == NO_EVENT


def test_gopher_fill_writes_never_clear_a_bit():
    rng = np.random.default_rng(0)
    rule = gopher.EVENTS[1]
    for _ in range(200):
        prev = rng.integers(0, 256, 128, dtype=np.uint8)
        ram = rng.integers(0, 256, 128, dtype=np.uint8)
        out = post(rule, prev, ram, u=0.0)
        fills = prev[:24] & ~ram[:24]
        scored = gopher.score(prev.astype(int)) != gopher.score(ram.astype(int))
        assert out.fired == bool(fills.any() and scored)
        if not out.fired:
            continue
        for i, v in out.writes.items():
            assert i < 24
            assert v & ram[i] == ram[i]  # nothing dug (set now) is cleared
            assert v == ram[i] | fills[i]
        assert set(out.writes) == {i for i in range(24) if fills[i]}


def test_gopher_carrot_dies_once():
    rule = gopher.EVENTS[3]
    state = rule.new_state()
    assert state == {"carrot_died": False}
    ram = make_ram({52: 0b1000_0111})
    assert post(rule, ram, ram, state=state, u=0.0, episode_frame=237) == NO_EVENT
    assert post(rule, ram, ram, state=state, u=AT, episode_frame=238) == NO_EVENT
    assert state["carrot_died"] is False
    out = post(rule, ram, ram, state=state, u=BELOW, u_choice=0.0, episode_frame=238)
    assert out.fired and out.writes == {52: 0b1000_0011}  # left carrot (bit 2); bit 7 kept
    assert state["carrot_died"] is True
    assert post(rule, ram, ram, state=state, u=0.0, episode_frame=5000) == NO_EVENT  # once


@pytest.mark.parametrize("visible,u_choice,cleared", [
    (0b111, 0.0, 2), (0b111, 0.4, 1), (0b111, 0.99, 0), (0b010, 0.99, 1), (0b101, 0.2, 2),
    (0b101, 0.7, 0), (0b001, 0.0, 0)])
def test_gopher_carrot_choice(visible, u_choice, cleared):
    rule = gopher.EVENTS[3]
    ram = make_ram({52: visible})
    out = post(rule, ram, ram, u=0.0, u_choice=u_choice)
    assert out.writes == {52: visible & ~(1 << cleared)}


def test_gopher_no_carrot_visible():
    rule = gopher.EVENTS[3]
    state = rule.new_state()
    ram = make_ram({52: 0b1111_1000})
    assert post(rule, ram, ram, state=state, u=0.0) == NO_EVENT
    assert state["carrot_died"] is False


def test_gopher_labels():
    ram = make_ram({31: 83, 48: 0x01, 49: 0x23, 50: 0x45, 52: 0b1101, 92: 128, 95: 60})
    L = gopher.LABELS
    got = {k: int(f(ram.astype(np.int32))) for k, f in L.items()}
    named = {k: v for k, v in got.items()
             if not k.startswith(("underground_row", "duck_"))}
    assert named == {"farmer_x": 83, "score": 12345, "carrots": 0b101, "seed_x": 60, "seed_y": 128}
    # the underground rows (top to bottom: RAM 0..5, 6..11, 12..17, 18..23) and the duck's bytes
    bytes_ = make_ram({**{a: 100 + a for a in range(24)},
                       **{a: 200 + a % 50 for a in (25, 26, 27, 28, 94)}}).astype(np.int32)
    got = {k: int(f(bytes_)) for k, f in L.items()}
    assert [got[f"underground_row{r}_{k}"] for r in range(4) for k in range(6)] == list(
        range(100, 124))
    assert [got[f"duck_{a}"] for a in (25, 26, 27, 28, 94)] == [225, 226, 227, 228, 244]
    assert len(got) == 5 + 24 + 5


# ---------------------------------------------------------------------------------------------
# BankHeist events
# ---------------------------------------------------------------------------------------------

def test_bankheist_dud_bomb():
    rule = bankheist.EVENTS[1]
    start = make_ram({12: 0})
    prev = make_ram({12: 3})
    ram = make_ram({12: 4})
    out = post(rule, prev, ram, start, u=BELOW)
    assert out.fired and out.writes == {12: 3} and not out.zero_reward
    assert post(rule, prev, ram, start, u=AT) == NO_EVENT
    assert post(rule, prev, make_ram({12: 0}), start, u=0.0) == NO_EVENT  # equals start
    assert post(rule, prev, prev.copy(), start, u=0.0) == NO_EVENT  # unchanged


def test_bankheist_fuel_leak_once_per_city():
    rule = bankheist.EVENTS[2]
    state = rule.new_state()
    assert state == {"leaked": set()}
    full = make_ram({0: 5, 86: 3})  # city 1, fuller than half
    assert post(rule, full, full, state=state, u=AT) == NO_EVENT
    assert state["leaked"] == set()  # not marked when u >= p
    half = make_ram({0: 5, 86: 12})
    assert post(rule, half, half, state=state, u=0.0) == NO_EVENT
    assert state["leaked"] == set()  # not marked when nothing is written (reference defect)
    out = post(rule, full, full, state=state, u=BELOW)
    assert out.fired and out.writes == {86: 12}
    assert state["leaked"] == {1}
    assert post(rule, full, full, state=state, u=0.0) == NO_EVENT  # city 1 already leaked
    assert post(rule, full, make_ram({0: 9, 86: 0}), state=state, u=0.0) == NO_EVENT  # 9%4 == 1
    out = post(rule, full, make_ram({0: 6, 86: 11}), state=state, u=0.0)
    assert out.writes == {86: 12} and state["leaked"] == {1, 2}
    assert rule.new_state() == {"leaked": set()}


def test_bankheist_city_switch_keeps_level():
    rule = bankheist.EVENTS[3]
    for city in range(0, 44):
        ram = make_ram({0: city})
        seen = set()
        for u_choice in np.linspace(0.0, 0.9999, 61):
            out = post(rule, ram, ram, u=BELOW, u_choice=float(u_choice))
            assert out.fired and set(out.writes) == {0}
            new = out.writes[0]
            assert new // 4 == city // 4  # level kept
            assert new % 4 != city % 4  # never the current maze
            seen.add(new % 4)
        assert seen == set(range(4)) - {city % 4}  # all three others reachable
        assert post(rule, ram, ram, u=AT) == NO_EVENT
    # uniform: each third of [0, 1) picks one maze
    picks = [post(rule, make_ram({0: 8}), make_ram({0: 8}), u=0.0, u_choice=c).writes[0]
             for c in (0.0, 0.33, 0.34, 0.66, 0.67, 0.999)]
    assert picks == [9, 9, 10, 10, 11, 11]


def test_bankheist_bank_was_empty():
    rule = bankheist.EVENTS[4]
    prev = make_ram({24: 254, 25: 253, 26: 255})
    robbed = make_ram({24: 254, 25: 255, 26: 255})
    out = post(rule, prev, robbed, u=BELOW)
    assert out.fired and out.zero_reward and out.writes == {} and not out.cancel_next_reward
    assert post(rule, prev, robbed, u=AT) == NO_EVENT
    assert post(rule, prev, prev.copy(), u=0.0) == NO_EVENT  # bank still there
    police_gone = make_ram({24: 255, 25: 253, 26: 255})
    assert post(rule, prev, police_gone, u=0.0) == NO_EVENT  # a police slot changed, not a bank
    appeared = make_ram({24: 254, 25: 253, 26: 253})
    assert post(rule, prev, appeared, u=0.0) == NO_EVENT


def test_bankheist_labels():
    """Every label reads its address in docs/spec.md section 8: each byte holds a value of its own
    (address + 101), so a label that reads a neighbour's byte shows (direction read 16, the
    background colour 66, and the test did not see it)."""
    ram = (np.arange(128) + 101).astype(np.int32)
    got = {k: int(f(ram)) for k, f in bankheist.LABELS.items()}
    spec = {"city_count": 0, "robber_y": 8, "robber_x": 28, "bomb": 12, "direction": 15,
            "orientation": 51, "slot_0": 24, "slot_1": 25, "slot_2": 26,
            "police_orientation_0": 52, "police_orientation_1": 53, "police_orientation_2": 54,
            "lives": 85, "fuel": 86, "background_colour": 69, "city_blocks_66": 66,
            "city_blocks_68": 68}
    assert got == {"city": 101 % 4, **{k: address + 101 for k, address in spec.items()}}


# ---------------------------------------------------------------------------------------------
# Labels work on batched numpy and jax arrays alike
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", GAMES)
def test_labels_batched_numpy_and_jax(name):
    import jax.numpy as jnp

    rng = np.random.default_rng(1)
    ram = rng.integers(0, 256, (3, 5, 128)).astype(np.int32)
    for label, f in GAMES[name].LABELS.items():
        a = np.asarray(f(ram))
        b = np.asarray(f(jnp.asarray(ram)))
        assert a.shape == (3, 5), label
        np.testing.assert_array_equal(a, b, err_msg=label)
        single = f(ram[1, 2])
        assert int(single) == a[1, 2]


# ---------------------------------------------------------------------------------------------
# Sanity: the rules run on real RAM from the emulator
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", GAMES)
def test_rules_run_on_real_ram(name):
    from ale_py import ALEInterface, LoggerMode, roms

    game = GAMES[name].GAME
    ALEInterface.setLoggerMode(LoggerMode.Error)
    ale = ALEInterface()
    ale.setInt("random_seed", 0)
    ale.setFloat("repeat_action_probability", 0.0)
    ale.loadROM(roms.get_rom_path(game.rom_id))
    actions = ale.getMinimalActionSet()
    assert len(actions) == game.num_actions
    rng = np.random.default_rng(0)
    for mode, rule in game.event_modes.items():
        ale.reset_game()
        start = ale.getRAM().copy()
        state = rule.new_state()
        fired = 0
        for frame in range(400):
            u, u_choice = float(rng.random()), float(rng.random())
            if rule.pre_frame is not None:
                writes, f = rule.pre_frame(start, state, u, 0.2, True)
                assert_python_writes(writes)
                for i, v in writes.items():
                    ale.setRAM(i, v)
                fired += f
            prev = ale.getRAM().copy()
            ale.act(actions[rng.integers(len(actions))])
            if rule.post_frame is not None:
                out = rule.post_frame(prev, ale.getRAM().copy(), start, state, u, u_choice, 0.2,
                                      ale.getEpisodeFrameNumber())
                assert_python_writes(out.writes)
                for i, v in out.writes.items():
                    ale.setRAM(i, v)
                fired += out.fired
            if ale.game_over():
                ale.reset_game()
                start = ale.getRAM().copy()
                state = rule.new_state()
        if name == "Boxing" and mode != 2 or name == "BankHeist" and mode == 3:
            assert fired > 0, (name, mode)  # these fire unconditionally with p = 0.2
    ram = ale.getRAM()
    for mode, ram_mode in game.ram_obs_modes.items():
        w = ram_mode.writes(ram)
        if w is not None:
            assert w and isinstance(w, dict)
            assert_python_writes(w)
    for f in game.labels.values():
        np.asarray(f(ram.astype(np.int32)))
