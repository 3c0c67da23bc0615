"""Named 2.1 RAM events on games outside STORI's four: a :class:`stori_jax.RamEvent` with a
name (docs/objects.md lists them).  The addresses are those the object tables read."""

from __future__ import annotations

from stori_jax.config import RamEvent

# (game, name) -> (what happens, RamEvent fields but prob)
NAMED_RAM_EVENTS = {
    ("Breakout", "paddle_jump"): (
        "the paddle jumps to one of four places", dict(address=72, values=(70, 100, 130, 160))),
    ("Pong", "paddle_jump"): (
        "the agent's paddle jumps to the top, the middle or the bottom",
        dict(address=51, values=(50, 120, 190))),
    ("Freeway", "chicken_back"): (
        "the agent's chicken is sent back to the kerb, once it has left it",
        dict(address=14, values=(6,), when=(14, ">", 6))),
}


def ram_event(game: str, name: str, prob: float) -> RamEvent:
    """The named RAM event ``name`` of ``game`` at probability ``prob``.

    Raises:
        ValueError: an unknown (game, name), naming the known ones.
    """
    if (game, name) not in NAMED_RAM_EVENTS:
        raise ValueError(f"no RAM event {name!r} for game {game!r}: the named RAM events are "
                         f"{[f'{g}/{n}' for g, n in NAMED_RAM_EVENTS]}")
    return RamEvent(prob=prob, **NAMED_RAM_EVENTS[game, name][1])
