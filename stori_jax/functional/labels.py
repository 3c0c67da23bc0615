"""Type 0: named state variables read from the RAM."""

from __future__ import annotations

import jax.numpy as jnp


def extract_labels(game, ram) -> dict:
    """{label: (B,) int32} from ram (B, 128) for ``game`` (its name, or its GameSpec)."""
    if isinstance(game, str):
        from stori_jax.games import get_game

        game = get_game(game)  # a clear error for a game that is none
    ram = jnp.asarray(ram).astype(jnp.int32)
    return {name: jnp.asarray(fn(ram), jnp.int32) for name, fn in game.labels.items()}
