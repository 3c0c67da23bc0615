"""Objects from the RAM: per game, a table of object classes whose boxes are RAM formulas.

``objects_of(game, ram)`` evaluates a game's table on a (B, 128) RAM batch in one jitted call:
``{class name: Boxes(x, y, w, h, present)}``, each field of shape (B, slots) (x, y, w, h int32,
present bool).  In each class the present objects come first, in the table's order; absent
slots are all 0.  The formulas are this project's, written from the RAM facts (addresses,
offsets) that OCAtari (https://github.com/k4ntz/OC_Atari, MIT) documents in its RAM mode, and
tests/test_objects.py checks them against OCAtari 2.2.1's own objects, frame by frame.

One module per game (``stori_jax/objects/<rom_id>.py``, a ``GAME`` table, see
:mod:`stori_jax.objects.table`); adding a game is adding its module to ``GAMES`` below.
"""

from __future__ import annotations

import functools
import importlib

import jax
import jax.numpy as jnp
import numpy as np

from stori_jax.objects.table import Boxes, GameObjects, ObjectClass  # noqa: F401 (re-exported)

RAM_SIZE = 128
SCREEN_HEIGHT, SCREEN_WIDTH = 210, 160

# the ALE ROM id of every covered game (its module's name)
GAMES = (
    "air_raid", "alien", "asterix", "bank_heist", "bowling", "boxing", "breakout",
    "crazy_climber", "demon_attack", "donkey_kong", "double_dunk", "fishing_derby", "freeway",
    "galaxian", "gopher", "ice_hockey", "jamesbond", "mario_bros", "ms_pacman", "name_this_game",
    "pacman", "pong", "seaquest", "star_gunner", "tennis", "up_n_down", "video_pinball",
    "yars_revenge",
    "riverraid", "frostbite", "kung_fu_master", "road_runner", "frogger", "pitfall", "venture",
    "private_eye", "battle_zone", "phoenix", "skiing", "kangaroo", "montezuma_revenge",
)


def _squash(name: str) -> str:
    return name.replace("_", "").lower()


@functools.lru_cache(maxsize=None)
def _tables() -> dict[str, GameObjects]:
    tables = {}
    # the tables' constants are made here, concrete, even where the first use is inside a
    # jit's trace (there jnp would make them tracers, which would leak)
    with jax.ensure_compile_time_eval():
        modules = [importlib.import_module(f"stori_jax.objects.{rom_id}") for rom_id in GAMES]
    for rom_id, module in zip(GAMES, modules):
        game = module.GAME
        assert game.rom_id == rom_id, (rom_id, game.rom_id)
        tables[rom_id] = game
    return tables


def covered_games() -> tuple[str, ...]:
    """The names of the games with an object table ('BankHeist', 'Boxing', ...), sorted."""
    return tuple(sorted(t.name for t in _tables().values()))


def object_table(game: str) -> GameObjects:
    """The object table of ``game``: its name ('BankHeist'), its ALE ROM id ('bank_heist') or
    OCAtari's name ('bankheist'), in any case."""
    if isinstance(game, GameObjects):
        return game
    if isinstance(game, str):
        for t in _tables().values():
            if _squash(game) == _squash(t.rom_id):
                return t
    raise ValueError(f"no object table for game {game!r}: the games with objects are "
                     f"{list(covered_games())}")


def classes_of(game: str) -> dict[str, int]:
    """{class name: slots} of ``game``, in its table's order."""
    return {c.name: c.slots for c in object_table(game).classes}


def listing() -> dict[str, dict[str, int]]:
    """{game name: {class name: slots}} for every covered game (``stori-jax list --objects``)."""
    return {name: classes_of(name) for name in covered_games()}


def _class_names(table: GameObjects, classes) -> tuple[str, ...]:
    known = [c.name for c in table.classes]
    if classes is None:
        return tuple(known)
    if isinstance(classes, str):
        classes = (classes,)
    bad = [c for c in classes if c not in known]
    if bad:
        raise ValueError(f"{table.name} has no object class {bad[0]!r}: its classes are {known}")
    return tuple(classes)


def _check_ram(ram):
    ram = jnp.asarray(ram)
    dtype = np.dtype(ram.dtype)
    if ram.ndim != 2 or ram.shape[-1] != RAM_SIZE:
        raise ValueError(f"ram must be an array of shape (B, {RAM_SIZE}) (the RAM bytes of each "
                         f"env), got shape {tuple(ram.shape)}")
    if dtype.kind not in "ui" or dtype == np.int8:
        raise ValueError(f"ram must hold the RAM bytes as uint8 (or a wider integer type), got "
                         f"dtype {dtype}")
    return ram


def _evaluate(cls: ObjectClass, r) -> Boxes:
    batch = r.shape[0]
    parts = []
    for v in cls.boxes(r):
        v = jnp.asarray(v)
        if v.ndim == 1 and cls.slots == 1:  # one object: (B,) per env
            v = v[:, None]  # (with several slots, a 1-D array is one value per slot)
        parts.append(v)
    width = max([1] + [v.shape[-1] for v in parts if v.ndim])
    x, y, w, h, present = (jnp.broadcast_to(v, (batch, width)) for v in parts)
    present = present.astype(bool)
    if width < cls.slots:  # fewer candidates than slots: the rest are absent
        x, y, w, h, present = (jnp.pad(v, ((0, 0), (0, cls.slots - width)))
                               for v in (x, y, w, h, present))
        width = cls.slots
    x, y, w, h = (jnp.where(present, v, 0).astype(jnp.int32) for v in (x, y, w, h))
    if width > 1:  # present objects first, in the formula's order; at most `slots` of them
        order = jnp.argsort(~present, axis=1, stable=True)[:, :cls.slots]
        x, y, w, h, present = (jnp.take_along_axis(v, order, axis=1)
                               for v in (x, y, w, h, present))
    return Boxes(x, y, w, h, present)


@functools.lru_cache(maxsize=None)
def _compiled(rom_id: str, classes: tuple[str, ...]):
    table = _tables()[rom_id]
    chosen = [c for c in table.classes if c.name in classes]

    @jax.jit
    def run(ram):
        r = ram.astype(jnp.int32)
        return {c.name: _evaluate(c, r) for c in chosen}
    return run


def objects_of(game: str, ram, classes=None) -> dict[str, Boxes]:
    """{class name: Boxes(x, y, w, h, present)} of ``game`` from ``ram`` (B, 128) (uint8 or a
    wider integer type): each field (B, slots), x, y, w, h int32 and present bool; present
    objects first in each class.  ``classes``: a class name or names to evaluate (default all).
    Works inside ``jax.jit`` too (``game`` and ``classes`` static)."""
    table = object_table(game)
    names = _class_names(table, classes)
    return _compiled(table.rom_id, names)(_check_ram(ram))


def objects_array(game: str, ram, classes=None):
    """The objects of :func:`objects_of` as one array (B, total slots, 5) int32: per class in
    table order, per slot, (x, y, w, h, present)."""
    table = object_table(game)
    names = _class_names(table, classes)
    out = objects_of(table, ram, names)
    order = [c.name for c in table.classes if c.name in names]
    return jnp.concatenate([jnp.stack([*out[n][:4], out[n].present.astype(jnp.int32)], axis=-1)
                            for n in order], axis=1)


def check_classes(game: str, classes, field: str = "classes") -> tuple[str, ...]:
    """``classes`` of ``game``, checked: a ValueError (naming ``field``) where the game has no
    object table (naming the games that have one) or no such class (naming its classes)."""
    try:
        table = object_table(game)
    except ValueError:
        raise ValueError(f"{field}: {game} has no object table (objects from its RAM); the games "
                         f"with objects are {list(covered_games())}") from None
    known = [c.name for c in table.classes]
    bad = [c for c in classes if c not in known]
    if bad:
        raise ValueError(f"{field}: {table.name} has no object class {bad[0]!r}: its classes "
                         f"are {known}")
    return tuple(classes)


def hidden_pixels(game: str, ram, classes) -> jax.Array:
    """(B, 210, 160) bool: the pixels inside a box of a present object of ``classes`` in
    ``ram`` (B, 128) (boxes clipped to the screen; traceable)."""
    out = objects_of(game, ram, tuple(classes))
    rows, cols = jnp.arange(SCREEN_HEIGHT), jnp.arange(SCREEN_WIDTH)
    covered = jnp.zeros((ram.shape[0], SCREEN_HEIGHT, SCREEN_WIDTH), jnp.float32)
    for boxes in out.values():
        x, y, w, h, present = (v[..., None] for v in boxes)  # (B, slots, 1)
        in_rows = present & (rows >= y) & (rows < y + h)      # (B, slots, 210)
        in_cols = (cols >= x) & (cols < x + w)                # (B, slots, 160)
        # how many boxes cover each pixel (exact: small integers in float32)
        covered = covered + jnp.einsum("bsr,bsc->brc", in_rows.astype(jnp.float32),
                                       in_cols.astype(jnp.float32))
    return covered > 0


def objects_layout(game: str) -> list[tuple[str, int]]:
    """The rows of ``obs="objects"`` / ``info["objects"]`` for ``game``: (class, slot) per row,
    in order (each row is x, y, w, h, present)."""
    return [(c.name, k) for c in object_table(game).classes for k in range(c.slots)]


def num_object_rows(game: str) -> int:
    return sum(c.slots for c in object_table(game).classes)


def has_objects(game: str) -> bool:
    try:
        object_table(game)
    except ValueError:
        return False
    return True
