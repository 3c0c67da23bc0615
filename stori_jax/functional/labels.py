"""Type 0: named state variables read from the RAM."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from stori_jax.backends.layout import RAM_SIZE
from stori_jax.games.base import GameSpec


def extract_labels(game, ram) -> dict:
    """{label: (...) int32} from ram (..., 128) for ``game`` (its name, or its GameSpec): the
    RAM bytes as uint8 (or a wider integer type holding them)."""
    if isinstance(game, str):
        from stori_jax.games import get_game

        game = get_game(game)  # a clear error for a game that is none
    elif not isinstance(game, GameSpec):
        raise ValueError(f"game must be a game's name or its GameSpec (stori_jax.get_game), "
                         f"got {game!r}")
    ram = jnp.asarray(ram)
    dtype = np.dtype(ram.dtype)
    if ram.ndim == 0 or ram.shape[-1] != RAM_SIZE:
        raise ValueError(f"ram must be an array of shape (..., {RAM_SIZE}) (the RAM bytes of "
                         f"each env), got shape {tuple(ram.shape)}")
    if dtype.kind not in "ui" or dtype == np.int8:
        raise ValueError(f"ram must hold the RAM bytes as uint8 (or a wider integer type), got "
                         f"dtype {dtype}")
    if dtype.itemsize > 1 and not isinstance(ram, jax.core.Tracer) and ram.size and (
            int(ram.min()) < 0 or int(ram.max()) > 255):  # traced: no values to check yet
        raise ValueError(f"ram must hold bytes (values in [0, 255]), got values "
                         f"{int(ram.min())}..{int(ram.max())}")
    ram = ram.astype(jnp.int32)
    return {name: jnp.asarray(fn(ram), jnp.int32) for name, fn in game.labels.items()}
