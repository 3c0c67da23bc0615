"""Breakout (docs/spec.md section 5). 4 actions: NOOP, FIRE, RIGHT, LEFT."""

from __future__ import annotations

import numpy as np

from stori_jax.games.base import (EventOutcome, EventRule, GameSpec, NO_EVENT, RamObsMode, Region,
                                  bcd, blackout_table, byte_labels, changed, pick)

BLOCK_RAM = np.arange(0, 36)  # block bitmap: 6 columns of 6 bytes
BALL_X, BALL_Y, PLAYER_X = 99, 101, 72
SCORE_HUNDREDS, SCORE_TENS_UNITS = 76, 77
BALL_PADDLE_COLOUR, BLOCK_ROW_COLOURS = 62, (64, 65, 66, 67, 68, 69)  # top row first
SCORE_DIGITS = (81, 83, 85)

REGIONS = {
    "blocks": Region(8, 151, 57, 92),
    "paddle": Region(7, 152, 189, 195),
    "score": Region(2, 158, 3, 16),
    "ball_band_top": Region(8, 151, 105, 130),
    "ball_band_middle": Region(8, 151, 131, 156),
    "ball_band_bottom": Region(8, 151, 157, 182),
}

BLACKOUT = blackout_table(REGIONS, {
    1: ("all six regions", ("blocks", "paddle", "score", "ball_band_top", "ball_band_middle",
                            "ball_band_bottom")),
    2: ("blocks", ("blocks",)),
    3: ("paddle", ("paddle",)),
    4: ("score", ("score",)),
    5: ("ball-band top", ("ball_band_top",)),
    6: ("ball-band middle", ("ball_band_middle",)),
    7: ("ball-band bottom", ("ball_band_bottom",)),
    8: ("blocks + paddle", ("blocks", "paddle")),
    9: ("blocks + score", ("blocks", "score")),
    10: ("ball-band top + bottom (ball visible only in the middle band)",
         ("ball_band_top", "ball_band_bottom")),
    11: ("all three ball bands", ("ball_band_top", "ball_band_middle", "ball_band_bottom")),
})

NUS_PATTERN = {0: 62, 1: 61, 2: 60, 3: 62, 5: 60, 6: 240, 7: 127, 8: 120, 9: 112, 10: 119,
               11: 120, 12: 0, 13: 240, 14: 240, 15: 240, 16: 240, 17: 240, 18: 57, 19: 218,
               20: 219, 21: 219, 22: 219, 23: 219, 24: 239, 25: 239, 26: 238, 27: 237, 28: 235,
               29: 231}

RAM_OBS = {
    1: RamObsMode("'NUS pattern' written into the block RAM (marked buggy by the authors)",
                  lambda ram: dict(NUS_PATTERN)),
    2: RamObsMode("ball hidden", lambda ram: {BALL_X: 0, BALL_Y: 0}),
}


def _block_hit_cancel(zero_reward: bool):
    def post_frame(prev_ram, ram, start_ram, state, u, u_choice, p, episode_frame):
        if not np.any(ram[BLOCK_RAM] != start_ram[BLOCK_RAM]):
            return NO_EVENT
        hit = changed(prev_ram, ram, BLOCK_RAM)
        if hit.size == 0 or not u < p:
            return NO_EVENT
        return EventOutcome(writes={int(i): int(prev_ram[i]) for i in hit}, fired=True,
                            zero_reward=zero_reward)
    return post_frame


def _regenerate_block(prev_ram, ram, start_ram, state, u, u_choice, p, episode_frame):
    hit = changed(start_ram, ram, BLOCK_RAM)
    if hit.size == 0 or not u < p:
        return NO_EVENT
    i = int(pick(hit, u_choice))
    return EventOutcome(writes={i: int(start_ram[i])}, fired=True)


EVENTS = {
    1: EventRule("block-hit cancel, reward kept", post_frame=_block_hit_cancel(False)),
    2: EventRule("block-hit cancel, reward set to 0", post_frame=_block_hit_cancel(True)),
    3: EventRule("regenerate a hit block", post_frame=_regenerate_block),
}

LABELS = {
    "ball_x": lambda ram: ram[..., BALL_X],
    "ball_y": lambda ram: ram[..., BALL_Y],
    "player_x": lambda ram: ram[..., PLAYER_X],
    "score": lambda ram: 100 * bcd(ram[..., SCORE_HUNDREDS]) + bcd(ram[..., SCORE_TENS_UNITS]),
    **byte_labels([f"block_bitmap_{a}" for a in BLOCK_RAM], BLOCK_RAM),
    "ball_paddle_colour": lambda ram: ram[..., BALL_PADDLE_COLOUR],
    **byte_labels([f"block_row_colour_{k}" for k in range(6)], BLOCK_ROW_COLOURS),
    **byte_labels([f"score_digit_{k}" for k in range(3)], SCORE_DIGITS),
}

GAME = GameSpec(name="Breakout", rom_id="breakout", num_actions=4, start_lives=5,
                regions=REGIONS, blackout_modes=BLACKOUT, ram_obs_modes=RAM_OBS, event_modes=EVENTS,
                labels=LABELS)
