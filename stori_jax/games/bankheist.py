"""BankHeist (docs/spec.md section 8). 18 actions; type 1 replaces actions from 0..9
(NOOP, FIRE and the eight directions: the reference's set; it leaves out the eight moves that
also fire, though FIRE itself, index 1, stays in).
"""

from __future__ import annotations

from stori_jax.games.base import (EventOutcome, EventRule, GameSpec, NO_EVENT, RamObsMode, Region,
                                  blackout_table, byte_labels, pick)

CITY = 0  # counts cities 0..10+ during play; the maze is CITY % 4
ROBBER_Y, ROBBER_X = 8, 28  # x 12..140
BOMB, DIRECTION, ORIENTATION = 12, 15, 51
SLOTS = (24, 25, 26)  # 253 bank, 254 police, 255 hidden
BANK, POLICE, HIDDEN = 253, 254, 255
POLICE_ORIENTATION = (52, 53, 54)
LIVES, FUEL = 85, 86  # fuel 0 full .. 25 empty
BACKGROUND_COLOUR, CITY_BLOCKS_A, CITY_BLOCKS_B = 69, 66, 68
HALF_TANK = 12
MAZES = 4
BACKGROUND_OF_MAZE = {0: 30, 1: 190, 2: 46, 3: 126}

LIVES_FUEL_FILL = (0, 0, 148)
SCORE_FILL = (162, 98, 33)

REGIONS = {
    "top_wall": Region(12, 147, 37, 44),
    "left_wall": Region(12, 15, 37, 177),
    "bottom_wall": Region(12, 147, 173, 177),
    "right_wall": Region(144, 147, 37, 177),
    "fuel": Region(12, 73, 11, 36, LIVES_FUEL_FILL),
    "lives": Region(78, 147, 11, 36, LIVES_FUEL_FILL),
    "score": Region(12, 147, 178, 186, SCORE_FILL),
}

WALLS = ("top_wall", "left_wall", "bottom_wall", "right_wall")

BLACKOUT = blackout_table(REGIONS, {
    1: ("all: four walls, fuel, lives, score", WALLS + ("fuel", "lives", "score")),
    2: ("all four walls", WALLS),
    3: ("top wall", ("top_wall",)),
    4: ("left wall", ("left_wall",)),
    5: ("bottom wall", ("bottom_wall",)),
    6: ("right wall", ("right_wall",)),
    7: ("left + right walls", ("left_wall", "right_wall")),
    8: ("fuel", ("fuel",)),
    9: ("lives", ("lives",)),
    10: ("score", ("score",)),
})


def _hide_slots(value: int):
    def writes(ram):
        hit = {a: HIDDEN for a in SLOTS if int(ram[a]) == value}
        return hit or None
    return writes


RAM_OBS = {
    1: RamObsMode("hide robber car", lambda ram: {ROBBER_Y: 155, ROBBER_X: 12}),
    2: RamObsMode("fuel gauge always full", lambda ram: {FUEL: 0}),
    3: RamObsMode("hide city blocks", lambda ram: {CITY_BLOCKS_A: 0, CITY_BLOCKS_B: 0}),
    4: RamObsMode("blend blocks and walls into the background",
                  lambda ram: {BACKGROUND_COLOUR: BACKGROUND_OF_MAZE[int(ram[CITY]) % MAZES]}),
    5: RamObsMode("hide banks (skipped when none)", _hide_slots(BANK)),
    6: RamObsMode("hide police (skipped when none)", _hide_slots(POLICE)),
}


def _dud_bomb(prev_ram, ram, start_ram, state, u, u_choice, p, episode_frame):
    if ram[BOMB] == start_ram[BOMB] or ram[BOMB] == prev_ram[BOMB] or not u < p:
        return NO_EVENT
    return EventOutcome(writes={BOMB: int(prev_ram[BOMB])}, fired=True)


def _fuel_leak(prev_ram, ram, start_ram, state, u, u_choice, p, episode_frame):
    city = int(ram[CITY]) % MAZES
    if city in state["leaked"] or int(ram[FUEL]) >= HALF_TANK or not u < p:
        return NO_EVENT
    state["leaked"].add(city)  # marked only when the leak is written
    return EventOutcome(writes={FUEL: HALF_TANK}, fired=True)


def _city_switch(prev_ram, ram, start_ram, state, u, u_choice, p, episode_frame):
    if not u < p:
        return NO_EVENT
    city = int(ram[CITY])
    maze = city % MAZES
    others = [m for m in range(MAZES) if m != maze]
    new_maze = pick(others, u_choice)
    return EventOutcome(writes={CITY: city - maze + new_maze}, fired=True)


def _bank_was_empty(prev_ram, ram, start_ram, state, u, u_choice, p, episode_frame):
    robbed = any(int(prev_ram[a]) == BANK and int(ram[a]) != BANK for a in SLOTS)
    if not robbed or not u < p:
        return NO_EVENT
    return EventOutcome(fired=True, zero_reward=True)


EVENTS = {
    1: EventRule("bomb is a dud", post_frame=_dud_bomb),
    2: EventRule("fuel leak (once per city per episode)", post_frame=_fuel_leak,
                 new_state=lambda: {"leaked": set()}),
    3: EventRule("city switch, level kept", post_frame=_city_switch),
    4: EventRule("bank was empty (reward set to 0)", post_frame=_bank_was_empty),
}

LABELS = {
    "city": lambda ram: ram[..., CITY] % MAZES,
    "city_count": lambda ram: ram[..., CITY],
    "robber_x": lambda ram: ram[..., ROBBER_X],
    "robber_y": lambda ram: ram[..., ROBBER_Y],
    "bomb": lambda ram: ram[..., BOMB],
    "direction": lambda ram: ram[..., DIRECTION],
    "orientation": lambda ram: ram[..., ORIENTATION],
    **byte_labels([f"slot_{k}" for k in range(len(SLOTS))], SLOTS),
    **byte_labels([f"police_orientation_{k}" for k in range(len(POLICE_ORIENTATION))],
                  POLICE_ORIENTATION),
    "lives": lambda ram: ram[..., LIVES],
    "fuel": lambda ram: ram[..., FUEL],
    "background_colour": lambda ram: ram[..., BACKGROUND_COLOUR],
    "city_blocks_66": lambda ram: ram[..., CITY_BLOCKS_A],
    "city_blocks_68": lambda ram: ram[..., CITY_BLOCKS_B],
}

GAME = GameSpec(name="BankHeist", rom_id="bank_heist", num_actions=18, start_lives=4,
                regions=REGIONS, blackout_modes=BLACKOUT, ram_obs_modes=RAM_OBS, event_modes=EVENTS,
                labels=LABELS, default_replacement_actions=tuple(range(10)))
