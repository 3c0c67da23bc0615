"""The shape of a game's object table: object classes, each with the RAM formula of its boxes.

A class is a name, a slot count and ``boxes(r) -> (x, y, w, h, present)``: ``r`` is the RAM
batch as int32 of shape (B, 128) (so no uint8 arithmetic wraps), and each of the five results
is a number, a (B, slots) array (one column per slot), a (slots,) array (one value per slot,
the same in every env) or, for a class of one slot, a (B,) array; written with ``jnp``.  A
formula may give more columns than the class has slots (candidates, e.g. every RAM slot that
may hold the class): the first ``slots`` present ones are kept; fewer columns than slots leave
the rest absent.  :func:`stori_jax.objects.objects_of` broadcasts them to (B, slots), zeroes the
boxes of absent slots and moves the present objects to the front (stably, so their order is the
formula's order, which is OCAtari's list order).

x, y are the top-left corner on the 160 x 210 screen (column, row), w, h the size in pixels, as
OCAtari reports them (its boxes are half-open: columns x .. x + w - 1).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, NamedTuple

import jax.numpy as jnp


class Boxes(NamedTuple):
    """One class's objects: each field (..., slots); x, y, w, h int32, present bool."""

    x: object
    y: object
    w: object
    h: object
    present: object


@dataclass(frozen=True)
class ObjectClass:
    name: str
    slots: int
    boxes: Callable  # r (B, 128) int32 -> (x, y, w, h, present)

    def __post_init__(self):
        if not (isinstance(self.slots, int) and self.slots >= 1):
            raise ValueError(f"object class {self.name!r}: slots must be an int >= 1, "
                             f"got {self.slots!r}")


@dataclass(frozen=True)
class GameObjects:
    """Every object class of one game, in the order of its table."""

    rom_id: str
    classes: tuple[ObjectClass, ...]
    notes: str = ""  # where and why the table departs from OCAtari

    @property
    def name(self) -> str:
        """The game's name as stori-jax spells it: 'bank_heist' -> 'BankHeist'."""
        return "".join(part.capitalize() for part in self.rom_id.split("_"))

    def __post_init__(self):
        names = [c.name for c in self.classes]
        if len(set(names)) != len(names):
            raise ValueError(f"{self.rom_id}: object classes named twice: {names}")


def table(rom_id: str, *classes: ObjectClass, notes: str = "") -> GameObjects:
    return GameObjects(rom_id, tuple(classes), notes)


def obj(name: str, slots: int = 1):
    """Decorator: ``@obj("Ball")`` over ``def ball(r): return x, y, w, h, present`` makes the
    function an :class:`ObjectClass`."""
    def make(fn):
        return ObjectClass(name, slots, fn)
    return make


# -- small helpers for the formulas ---------------------------------------------------------

def at(r, addresses):
    """The RAM bytes at ``addresses`` (a list or range): (B, len(addresses))."""
    return r[:, jnp.asarray(list(addresses), jnp.int32)]


def bit(value, k):
    """Bit ``k`` (0 = least significant) of ``value``, as bool."""
    return ((value >> k) & 1) == 1


def bcd(value):
    """A binary-coded decimal byte -> its value."""
    return (value >> 4) * 10 + (value & 15)


def where(cond, a, b):
    return jnp.where(cond, a, b)


def signed(value):
    """A byte read as a two's-complement int8."""
    return jnp.where(value > 127, value - 256, value)
