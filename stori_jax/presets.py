"""The 24 presets of the paper's experiments (docs/spec.md section 10), addressable as
(game, name)."""

from __future__ import annotations

from stori_jax.config import ActionNoise, Config, ConceptDrift, ObservationMask, RandomEvent


def _type1() -> Config:
    return Config(action_noise=ActionNoise(prob=0.3))


def _event(mode: int, prob: float) -> Config:
    return Config(event=RandomEvent(mode=mode, prob=prob))


def _mask(kind: str, mode: int, prob: float) -> Config:
    return Config(observation=ObservationMask(kind=kind, mode=mode, prob=prob))


def _drift(schedule: str, period: int, secondary: Config) -> Config:
    return Config(drift=ConceptDrift(schedule=schedule, period=period, secondary=secondary))


_BREAKOUT_32A = _mask("blackout", 10, 1.0)
_BOXING_32C = _mask("ram", 2, 0.7)
_GOPHER_32 = _mask("blackout", 6, 1.0)
_BANKHEIST_32 = _mask("ram", 3, 0.75)

# (game, preset name) -> (definition in words, config)
_PRESETS: dict[tuple[str, str], tuple[str, Config]] = {
    ("Breakout", "1"): ("type 1, p = 0.3", _type1()),
    ("Breakout", "2.1"): ("event mode 2 (block-hit cancel, reward 0), p = 0.25", _event(2, 0.25)),
    ("Breakout", "2.2"): ("sudden drift at T = 300 to 3.2A", _drift("sudden", 300, _BREAKOUT_32A)),
    ("Breakout", "3.1"): ("default", Config()),
    ("Breakout", "3.2A"): ("blackout mode 10, p = 1.0", _BREAKOUT_32A),
    ("Breakout", "3.2B"): ("crop mode 1 (left half), p = 0.75", _mask("crop", 1, 0.75)),
    ("Breakout", "3.2C"): ("crop mode 5 (torch), p = 1.0", _mask("crop", 5, 1.0)),
    ("Boxing", "1"): ("type 1, p = 0.3", _type1()),
    ("Boxing", "2.1"): ("event mode 1 (colour flip), p = 0.001", _event(1, 0.001)),
    ("Boxing", "2.2"): ("sudden drift at T = 300 to 3.2C", _drift("sudden", 300, _BOXING_32C)),
    ("Boxing", "3.1"): ("default", Config()),
    ("Boxing", "3.2A"): ("blackout mode 9 (scores + clock), p = 1.0", _mask("blackout", 9, 1.0)),
    ("Boxing", "3.2B"): ("crop mode 2 (right half), p = 0.75", _mask("crop", 2, 0.75)),
    ("Boxing", "3.2C"): ("RAM mode 2 (hide enemy), p = 0.7", _BOXING_32C),
    ("Gopher", "1"): ("type 1, p = 0.3", _type1()),
    ("Gopher", "2.1"): ("event mode 2 (hole stays open, reward 0), p = 0.3", _event(2, 0.3)),
    ("Gopher", "2.2"): ("cyclic drift, T = 600, to 3.2", _drift("cyclic", 600, _GOPHER_32)),
    ("Gopher", "3.1"): ("default", Config()),
    ("Gopher", "3.2"): ("blackout mode 6 (underground offset), p = 1.0", _GOPHER_32),
    ("BankHeist", "1"): ("type 1, p = 0.3, replacement from actions 0..9", _type1()),
    ("BankHeist", "2.1"): ("event mode 3 (city switch), p = 0.001", _event(3, 0.001)),
    ("BankHeist", "2.2"): ("cyclic drift, T = 600, to 3.2", _drift("cyclic", 600, _BANKHEIST_32)),
    ("BankHeist", "3.1"): ("default", Config()),
    ("BankHeist", "3.2"): ("RAM mode 3 (hide city blocks), p = 0.75", _BANKHEIST_32),
}


def list_presets() -> list[tuple[str, str]]:
    """All paper presets as (game, name) pairs, in the paper's order."""
    return list(_PRESETS)


def canonical_game(game: str) -> str:
    """``game`` spelt as the paper does ('breakout', 'bank_heist' -> 'Breakout', 'BankHeist'); a
    ValueError for a game without presets."""
    from stori_jax.games import stori_spec_named

    spec = stori_spec_named(game)  # every spelling make() and get_game() accept ('bank_heist')
    if spec is not None and any(g == spec.name for g, _ in _PRESETS):
        return spec.name
    games = sorted({g for g, _ in _PRESETS})
    raise ValueError(f"unknown game {game!r} for presets: allowed {games} (another ale-py game "
                     "takes no preset, which plays it as 3.1, or a Config)")


def spelt_as_the_paper(name: str) -> str:
    """A preset name spelt as the paper does ('3.2a' -> '3.2A'); unchanged if no game has it."""
    spellings = {n.lower(): n for _, n in _PRESETS}
    return spellings.get(name.lower(), name) if isinstance(name, str) else name


def canonical_preset(game: str, name: str) -> str:
    """Preset ``name`` of ``game`` spelt as the paper does ("3.2a" -> "3.2A"), as game names
    are matched whatever their case; an unknown one is a ValueError naming the allowed ones."""
    game = canonical_game(game)
    names = [n for g, n in _PRESETS if g == game]
    if not isinstance(name, str):
        raise ValueError(f"preset must be a name (a string) of {game}: allowed {names}, got "
                         f"{name!r} ({type(name).__name__})")
    if spelt_as_the_paper(name) not in names:
        raise ValueError(f"unknown preset {name!r} for {game}: allowed {names}")
    return spelt_as_the_paper(name)


def preset(game: str, name: str) -> Config:
    """The Config of paper preset ``name`` of ``game``, e.g. preset("Breakout", "3.2A")."""
    game = canonical_game(game)
    return _PRESETS[(game, canonical_preset(game, name))][1].for_game(game)


def describe_preset(game: str, name: str) -> str:
    """The paper's definition of a preset, in words."""
    game = canonical_game(game)
    return _PRESETS[(game, canonical_preset(game, name))][0]
