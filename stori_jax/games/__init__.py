"""Game registry: the four STORI games, plus every other game that ale-py ships.

Other ALE games get a :class:`GameSpec` without blackout, RAM or event modes, so the
game-agnostic modes (type 1, sticky actions, crop, drift to those) work on them.
"""

from __future__ import annotations

import functools
import re

from stori_jax.games.base import GameSpec, Region  # noqa: F401  (re-exported)

STORI_GAMES = ("Breakout", "Boxing", "Gopher", "BankHeist")


@functools.lru_cache(maxsize=None)
def _stori_specs() -> dict[str, GameSpec]:
    from stori_jax.games import bankheist, boxing, breakout, gopher

    return {m.GAME.name: m.GAME for m in (breakout, boxing, gopher, bankheist)}


def rom_id_of(name: str) -> str:
    """'BankHeist' -> 'bank_heist', 'MontezumaRevenge' -> 'montezuma_revenge'."""
    return re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name).lower()


@functools.lru_cache(maxsize=None)
def ale_rom_ids() -> tuple[str, ...]:
    from ale_py import roms

    return tuple(roms.get_all_rom_ids())


def stori_spec_named(name) -> GameSpec | None:
    """The GameSpec of the STORI game ``name`` spells ('BankHeist', 'bankheist', 'bank_heist'), or
    None when ``name`` is not one of the four."""
    if not isinstance(name, str):
        return None
    for spec in _stori_specs().values():
        if name.lower() in (spec.name.lower(), spec.rom_id):
            return spec
    return None


def get_game(name: str) -> GameSpec:
    """The GameSpec of ``name`` (a STORI game, or any ale-py game id such as 'Pong' or 'pong';
    one spec per game, however it is spelled)."""
    if not isinstance(name, str) or not name:
        raise ValueError(f"game must be a non-empty string, got {name!r}")
    spec = stori_spec_named(name)
    if spec is not None:
        return spec
    rom_id = name if name in ale_rom_ids() else rom_id_of(name)
    if rom_id not in ale_rom_ids():
        raise ValueError(f"unknown game {name!r}: allowed are the STORI games {list(STORI_GAMES)} "
                         f"or any ale-py game id (e.g. 'Pong', 'space_invaders'); "
                         f"{len(ale_rom_ids())} ids ship with ale-py")
    return _other_game(rom_id)


@functools.lru_cache(maxsize=None)
def _other_game(rom_id: str) -> GameSpec:
    """A game outside STORI, named from its ROM id: 'space_invaders' -> 'SpaceInvaders'."""
    name = "".join(part.capitalize() for part in rom_id.split("_"))
    num_actions, start_lives, height = _power_on_facts(rom_id)
    return GameSpec(name=name, rom_id=rom_id, num_actions=num_actions, start_lives=start_lives,
                    screen_height=height)


def _power_on_facts(rom_id: str) -> tuple[int, int, int]:
    """The size of the game's minimal action set, its lives at power-on and its screen's rows,
    read from ALE with the ROM loaded (one load for all)."""
    from ale_py import ALEInterface, LoggerMode, roms

    ALEInterface.setLoggerMode(LoggerMode.Error)
    ale = ALEInterface()
    ale.loadROM(roms.get_rom_path(rom_id))
    return len(ale.getMinimalActionSet()), int(ale.lives()), int(ale.getScreenDims()[0])
