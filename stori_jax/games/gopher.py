"""Gopher (docs/spec.md section 7). 8 actions: NOOP, FIRE, UP, RIGHT, LEFT, UPFIRE, RIGHTFIRE,
LEFTFIRE."""

from __future__ import annotations

import numpy as np

from stori_jax.games.base import (EventOutcome, EventRule, GameSpec, NO_EVENT, RamObsMode, Region,
                                  bcd, blackout_table, byte_labels, full_width, pick)

UNDERGROUND_RAM = np.arange(0, 24)  # rows 0..5, 6..11, 12..17, 18..23 (top to bottom); 1 = tunnel
DUCK_RAM = (25, 26, 27, 28, 94)
FARMER_X = 31  # 19 left .. 83 middle .. 148 right
SCORE_HIGH, SCORE_MIDDLE, SCORE_LOW = 48, 49, 50  # BCD, two digits each
CARROTS = 52  # bit 2 left, bit 1 middle, bit 0 right
CARROT_BITS = (2, 1, 0)  # left, middle, right
SEED_Y, SEED_X = 92, 95
NO_SEED = 128
PLAY_STARTS = 238  # episode frame number from which the game is in play

BEFORE_DUG = (187, 159, 71)
AFTER_DUG = (223, 183, 85)
ATTACK_ROWS = ((146, 150, (101, 209, 174)), (151, 155, (117, 231, 194)),
               (156, 160, (132, 252, 212)))  # (y0, y1, fill) of each attack-region row
UNDERGROUND_ROWS = {"row0": (161, 168), "row1": (168, 176), "row2": (176, 182), "row3": (183, 194)}

REGIONS = {
    **{f"attack_left_{k}": Region(0, 59, y0, y1, fill)
       for k, (y0, y1, fill) in enumerate(ATTACK_ROWS)},
    **{f"attack_right_{k}": Region(100, 159, y0, y1, fill)
       for k, (y0, y1, fill) in enumerate(ATTACK_ROWS)},
    "underground_full": full_width(161, 200, BEFORE_DUG),
    "underground_full_offset": full_width(164, 200, BEFORE_DUG),
    **{name: full_width(y0, y1, BEFORE_DUG) for name, (y0, y1) in UNDERGROUND_ROWS.items()},
    **{f"{name}_dug": full_width(y0, y1, AFTER_DUG) for name, (y0, y1) in UNDERGROUND_ROWS.items()},
    "farmer_full": full_width(87, 145),
    "farmer_below_nose": full_width(104, 145),
    "duck": full_width(26, 56),
    "score": full_width(0, 25),
}

ATTACK_LEFT = ("attack_left_0", "attack_left_1", "attack_left_2")
ATTACK_RIGHT = ("attack_right_0", "attack_right_1", "attack_right_2")

BLACKOUT = blackout_table(REGIONS, {
    1: ("all: underground (before-dug), farmer, duck, score, then both attack regions",
        ("underground_full", "underground_full_offset", "row0", "row1", "row2", "row3",
         "farmer_full", "farmer_below_nose", "duck", "score") + ATTACK_LEFT + ATTACK_RIGHT),
    2: ("attack left + right", ATTACK_LEFT + ATTACK_RIGHT),
    3: ("attack left", ATTACK_LEFT),
    4: ("attack right", ATTACK_RIGHT),
    5: ("underground full, before-dug", ("underground_full",)),
    6: ("underground full offset, before-dug (holes' openings stay visible)",
        ("underground_full_offset",)),
    7: ("row0, before-dug", ("row0",)),
    8: ("row0, after-dug", ("row0_dug",)),
    9: ("row1, before-dug", ("row1",)),
    10: ("row1, after-dug", ("row1_dug",)),
    11: ("row2, before-dug", ("row2",)),
    12: ("row2, after-dug", ("row2_dug",)),
    13: ("row3, before-dug", ("row3",)),
    14: ("row3, after-dug", ("row3_dug",)),
    15: ("farmer full", ("farmer_full",)),
    16: ("farmer below nose", ("farmer_below_nose",)),
    17: ("duck flight band", ("duck",)),
    18: ("score", ("score",)),
})


def _hide_carrot(bit: int):
    return lambda ram: {CARROTS: int(ram[CARROTS]) & ~(1 << bit) & 0xFF}


RAM_OBS = {
    1: RamObsMode("hide left carrot", _hide_carrot(2)),
    2: RamObsMode("hide middle carrot", _hide_carrot(1)),
    3: RamObsMode("hide right carrot", _hide_carrot(0)),
    4: RamObsMode("hide all carrots", lambda ram: {CARROTS: 0}),
    5: RamObsMode("hide seed (skipped when there is none)",
                  lambda ram: None if int(ram[SEED_Y]) == NO_SEED else {SEED_Y: NO_SEED}),
}


def score(ram):
    """The score in RAM 48..50 (BCD), of int RAM arrays (numpy or jax, any leading shape)."""
    return (10000 * bcd(ram[..., SCORE_HIGH]) + 100 * bcd(ram[..., SCORE_MIDDLE])
            + bcd(ram[..., SCORE_LOW]))


def _hole_stays_open(zero_reward: bool):
    def post_frame(prev_ram, ram, start_ram, state, u, u_choice, p, episode_frame):
        # A fill is a bit this frame clears (1 before, 0 now) while scoring: the farmer's fill
        # earns 20 points on the frame that clears it.  Digging (setting bits) is left alone,
        # and so is the game's own refilling of the whole underground when a new round starts
        # after a carrot is eaten (17-68 bits at once, no points; docs/spec.md sections 7
        # and 12).
        fills = prev_ram[UNDERGROUND_RAM] & ~ram[UNDERGROUND_RAM]
        if not np.any(fills) or not u < p:
            return NO_EVENT
        if score(ram.astype(np.int32)) == score(prev_ram.astype(np.int32)):  # not the farmer
            return NO_EVENT
        return EventOutcome(writes={int(i): int(ram[i] | f)
                                    for i, f in zip(UNDERGROUND_RAM, fills) if f},
                            fired=True, zero_reward=zero_reward)
    return post_frame


def _carrot_dies(prev_ram, ram, start_ram, state, u, u_choice, p, episode_frame):
    if state["carrot_died"] or episode_frame < PLAY_STARTS:
        return NO_EVENT
    visible = [b for b in CARROT_BITS if int(ram[CARROTS]) >> b & 1]
    if not visible or not u < p:
        return NO_EVENT
    bit = pick(visible, u_choice)
    state["carrot_died"] = True
    return EventOutcome(writes={CARROTS: int(ram[CARROTS]) & ~(1 << bit) & 0xFF}, fired=True)


EVENTS = {
    1: EventRule("hole stays open (a fill is undone), reward kept",
                 post_frame=_hole_stays_open(False)),
    2: EventRule("hole stays open (a fill is undone), reward set to 0",
                 post_frame=_hole_stays_open(True)),
    3: EventRule("a carrot dies (once per episode)", post_frame=_carrot_dies,
                 new_state=lambda: {"carrot_died": False}),
}

LABELS = {
    "farmer_x": lambda ram: ram[..., FARMER_X],
    "score": score,
    "carrots": lambda ram: ram[..., CARROTS] & 7,
    "seed_x": lambda ram: ram[..., SEED_X],
    "seed_y": lambda ram: ram[..., SEED_Y],
    **byte_labels([f"underground_row{a // 6}_{a % 6}" for a in UNDERGROUND_RAM], UNDERGROUND_RAM),
    **byte_labels([f"duck_{a}" for a in DUCK_RAM], DUCK_RAM),
}

GAME = GameSpec(name="Gopher", rom_id="gopher", num_actions=8, start_lives=3,
                regions=REGIONS, blackout_modes=BLACKOUT, ram_obs_modes=RAM_OBS, event_modes=EVENTS,
                labels=LABELS)
