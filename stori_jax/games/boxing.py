"""Boxing (docs/spec.md section 6). 18 actions (the full set is also the minimal set)."""

from __future__ import annotations

from stori_jax.games.base import (EventOutcome, EventRule, GameSpec, NO_EVENT, RamObsMode, Region,
                                  bcd, blackout_table, byte_labels, changed)

PLAYER_X, ENEMY_X, PLAYER_Y, ENEMY_Y = 32, 33, 34, 35
PLAYER_SCORE, ENEMY_SCORE = 18, 19  # BCD (ALE reads them as decimal scores)
KNOCKOUT = 0xC0  # the score byte of a boxer who scored 100 (a knockout): ALE counts it as 100
CLOCK_MINUTES, CLOCK_SECONDS = 16, 17  # minutes in the high nibble (the low one is 0xB), seconds in BCD
PLAYER_COLOUR, ENEMY_COLOUR, RING_COLOUR, CLOCK_COLOUR = 1, 2, 3, 4
INVISIBLE = 214  # colour value that makes a sprite the ring background colour
SCORES = (PLAYER_SCORE, ENEMY_SCORE)

RING = (110, 156, 66)  # ring background colour, the fill of every Boxing region

REGIONS = {
    "full_ring": Region(32, 127, 36, 176, RING),
    "left_ring": Region(32, 80, 36, 176, RING),
    "right_ring": Region(81, 127, 36, 176, RING),
    "enemy_score": Region(87, 134, 1, 16, RING),
    "player_score": Region(33, 69, 1, 16, RING),
    "clock": Region(57, 97, 14, 27, RING),
}

BLACKOUT = blackout_table(REGIONS, {
    1: ("all six regions", ("full_ring", "left_ring", "right_ring", "enemy_score", "player_score",
                            "clock")),
    2: ("left ring", ("left_ring",)),
    3: ("right ring", ("right_ring",)),
    4: ("full ring", ("full_ring",)),
    5: ("enemy score", ("enemy_score",)),
    6: ("player score", ("player_score",)),
    7: ("enemy + player score", ("enemy_score", "player_score")),
    8: ("clock", ("clock",)),
    9: ("enemy + player score + clock", ("enemy_score", "player_score", "clock")),
})

RAM_OBS = {
    1: RamObsMode("hide ring", lambda ram: {RING_COLOUR: INVISIBLE}),
    2: RamObsMode("hide enemy (and its score)", lambda ram: {ENEMY_COLOUR: INVISIBLE}),
    3: RamObsMode("hide player (and its score)", lambda ram: {PLAYER_COLOUR: INVISIBLE}),
}


def _colour_flip(start_ram, state, u, p, decide):
    """Toggle ``flipped`` with prob p (only when deciding); write the colours before EVERY frame."""
    fired = False
    if decide and u < p:
        state["flipped"] = not state["flipped"]
        fired = True
    a, b = int(start_ram[PLAYER_COLOUR]), int(start_ram[ENEMY_COLOUR])
    if state["flipped"]:
        a, b = b, a
    return {PLAYER_COLOUR: a, ENEMY_COLOUR: b}, fired


def _hit_cancel(prev_ram, ram, start_ram, state, u, u_choice, p, episode_frame):
    hit = changed(prev_ram, ram, SCORES)
    if hit.size != 1 or not u < p:
        return NO_EVENT
    i = int(hit[0])
    # ALE reports minus the cancelled reward on the next frame: the worker removes it.
    return EventOutcome(writes={i: int(prev_ram[i])}, fired=True, zero_reward=True,
                        cancel_next_reward=True)


def _displace_to_corners(start_ram, state, u, p, decide):
    if not decide or not u < p:
        return {}, False
    return {PLAYER_X: int(start_ram[ENEMY_X]), PLAYER_Y: int(start_ram[ENEMY_Y]),
            ENEMY_X: int(start_ram[PLAYER_X]), ENEMY_Y: int(start_ram[PLAYER_Y])}, True


EVENTS = {
    1: EventRule("colour flip (persistent)", pre_frame=_colour_flip,
                 new_state=lambda: {"flipped": False}),
    2: EventRule("hit cancel (a cancelled hit nets 0)", post_frame=_hit_cancel),
    3: EventRule("displace the boxers to each other's start corner",
                 pre_frame=_displace_to_corners),
}


def boxing_score(byte):
    """A boxer's score from its byte: BCD 0..99, and 100 for a knockout (0xC0, which BCD would
    read as 120), as ALE's reward counts it."""
    return bcd(byte) - 20 * (byte == KNOCKOUT)


LABELS = {
    "player_x": lambda ram: ram[..., PLAYER_X],
    "player_y": lambda ram: ram[..., PLAYER_Y],
    "enemy_x": lambda ram: ram[..., ENEMY_X],
    "enemy_y": lambda ram: ram[..., ENEMY_Y],
    "player_score": lambda ram: boxing_score(ram[..., PLAYER_SCORE]),
    "enemy_score": lambda ram: boxing_score(ram[..., ENEMY_SCORE]),
    "clock_minutes": lambda ram: ram[..., CLOCK_MINUTES] >> 4,
    "clock_seconds": lambda ram: bcd(ram[..., CLOCK_SECONDS]),
    **byte_labels(["player_colour", "enemy_colour", "ring_colour", "clock_colour"],
                  (PLAYER_COLOUR, ENEMY_COLOUR, RING_COLOUR, CLOCK_COLOUR)),
}

GAME = GameSpec(name="Boxing", rom_id="boxing", num_actions=18, start_lives=0,
                regions=REGIONS, blackout_modes=BLACKOUT, ram_obs_modes=RAM_OBS, event_modes=EVENTS,
                labels=LABELS)
