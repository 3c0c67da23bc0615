"""Argument handling shared by the benchmark scripts: checks (a bad value is a one-line usage
error that names the option, never a traceback from inside a measurement), and the part of a
results file's name that says which options differ from their defaults."""

from __future__ import annotations

import argparse


def require_at_least_one(parser: argparse.ArgumentParser, **options) -> None:
    """Every count in ``options`` (an int or a list of ints, keyed by the option's name without
    dashes) is >= 1."""
    for name, value in options.items():
        values = value if isinstance(value, list) else [value]
        if value is not None and min(values) < 1:
            parser.error(f"--{name.replace('_', '-')}: must be >= 1, got {value}")


def fits_in_memory(parser: argparse.ArgumentParser, flag: str, sizes: list[int]) -> None:
    """Every batch size in ``sizes`` fits this machine's memory (stori_jax's check of make()),
    checked before anything is measured: a typo of a size otherwise allocated for minutes or
    hung building emulators."""
    from stori_jax.builder import FRAME_SKIP, check_memory

    try:
        check_memory(max(sizes), FRAME_SKIP, flag=flag)
    except ValueError as error:
        parser.error(str(error))


def options_in_name(parser: argparse.ArgumentParser, args, prefixes: dict[str, str]) -> str:
    """'-<prefix><value>' for every option in ``prefixes`` (its dest -> its prefix in a file
    name) that differs from its default, lists joined by '-' (``--sizes 8 32``: '-B8-32'): a run
    with other options never overwrites a default run of the same day, nor one with others."""
    def shown(value):
        return f"{value:g}" if isinstance(value, float) else str(value)

    parts = []
    for name, prefix in prefixes.items():
        value = getattr(args, name)
        if value != parser.get_default(name):
            values = value if isinstance(value, list) else [value]
            parts.append(prefix + "-".join(shown(v) for v in values))
    return "".join(f"-{part}" for part in parts)


def output_directory(parser: argparse.ArgumentParser, path) -> None:
    """--out must be a directory that can be written, checked before anything is measured."""
    from stori_jax.cli import check_out

    try:
        check_out("--out", path, directory=True)
    except ValueError as error:
        parser.error(str(error))


def stori_games(parser: argparse.ArgumentParser, flag: str, names: list[str]) -> list[str]:
    """The STORI games ``names`` name, spelt canonically ('breakout' is Breakout)."""
    from baselines.evaluate import stori_game

    try:
        return [stori_game(name) for name in names]
    except ValueError as error:
        parser.error(f"{flag}: {error}")


def stori_game_and_preset(parser: argparse.ArgumentParser, game: str,
                          preset: str) -> tuple[str, str]:
    """(game, preset) spelt as the paper does ('breakout', '3.2a': Breakout, 3.2A), after
    checking that the game has that preset."""
    from stori_jax.presets import canonical_preset

    game = stori_games(parser, "--game", [game])[0]
    try:
        return game, canonical_preset(game, preset)
    except ValueError as error:
        parser.error(f"--preset: {error}")
