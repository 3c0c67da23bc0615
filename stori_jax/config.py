"""Configuration of a STORI environment: frozen, validated dataclasses.

A :class:`Config` names which perturbations are active.  Each part is optional and several may be
combined (the reference allows one at a time; its taxonomy ``type`` is derived from the parts):

- :class:`ActionNoise`      type 1    executed action != intended action
- :class:`RandomEvent`      type 2.1  game-specific RAM events
- :class:`ConceptDrift`     type 2.2  switch to a secondary concept over time
- :class:`ObservationMask`  type 3.2  crop, blackout or RAM-rendered hiding
- ``ram_observation=True``  type 0    the observation is the 128-byte RAM plus labels

Validation happens at construction; every error is a ``ValueError`` that names the field and the
allowed values.  Game-specific modes (blackout, RAM and event modes) are checked against the game
when ``game`` is given, and again by :func:`stori_jax.make`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from .checks import (MAX_INT32, check_action_indices, check_bool, check_int,
                     check_draw_probability, shown)
from .games import get_game
from .games.base import CROP_MODES, is_torch

GRANULARITIES = ("frame", "step")
DRIFT_SCHEDULES = ("sudden", "cyclic", "gradual")
MASK_KINDS = ("crop", "blackout", "ram", "objects")
OBJECTS_MODES = {1: "the classes' boxes black"}  # kind "objects": how a hidden object looks
TAXONOMY_TYPES = ("0", "1", "2.1", "2.2", "3.1", "3.2")
SECONDARY_TYPES = ("1", "2.1", "3.2")


def _check_choice(owner: str, name: str, value: Any, allowed) -> Any:
    """The one of ``allowed`` that ``value`` is, as its plain type (numpy's str_ becomes a str;
    a one-element array compares equal to a string but is none: it would reach the jitted code
    as an unhashable static argument)."""
    for choice in allowed:
        if isinstance(value, type(choice)) and value == choice:
            return choice
    raise ValueError(f"{owner}.{name} must be one of {list(allowed)}, got {value!r}")


@dataclass(frozen=True)
class ActionNoise:
    """Type 1: with probability ``prob`` per frame (or step) the intended action is replaced.

    ``sticky=False``: the replacement is drawn uniformly from ``replacement_actions`` (``None``
    means the game's default set: the whole minimal action set, or actions 0..9 on BankHeist).
    ``sticky=True``: the PREVIOUS executed action is repeated instead (Machado et al. 2018).
    """

    prob: float
    replacement_actions: tuple[int, ...] | None = None
    sticky: bool = False

    def __post_init__(self):
        object.__setattr__(self, "prob", check_draw_probability("ActionNoise.prob", self.prob))
        object.__setattr__(self, "sticky", check_bool("ActionNoise.sticky", self.sticky))
        if self.replacement_actions is not None:
            actions = check_action_indices(
                "ActionNoise.replacement_actions", self.replacement_actions,
                "a non-empty tuple of action indices >= 0 (or None)")
            if len(set(actions)) < len(actions):  # a repeat would weigh the uniform draw
                raise ValueError("ActionNoise.replacement_actions must name each action once, "
                                 f"got {self.replacement_actions!r}")
            if self.sticky:
                raise ValueError("ActionNoise.replacement_actions cannot be combined with "
                                 "sticky=True (sticky repeats the previous action)")
            object.__setattr__(self, "replacement_actions", actions)


@dataclass(frozen=True)
class RandomEvent:
    """Type 2.1: the game's random event ``mode`` fires with probability ``prob`` when its
    condition holds (per emulator frame at ``frame`` granularity, per agent step at ``step``)."""

    mode: int
    prob: float

    def __post_init__(self):
        mode = check_int("RandomEvent.mode", self.mode)
        object.__setattr__(self, "mode", mode)
        if mode < 1:
            raise ValueError(f"RandomEvent.mode must be >= 1 (a game's event modes), got {mode}")
        object.__setattr__(self, "prob", check_draw_probability("RandomEvent.prob", self.prob))


RAM_CONDITIONS = ("==", "!=", "<", "<=", ">", ">=")


@dataclass(frozen=True)
class RamEvent:
    """Type 2.1 on any game: with probability ``prob`` per frame (or step), where ``when``
    holds on the RAM after the frame (``(address, op, value)``, or None: always), write one of
    ``values`` (drawn uniformly) to RAM ``address``; the next frame plays from it.  Named
    examples: :func:`stori_jax.ram_events.ram_event`."""

    address: int
    values: tuple[int, ...]
    prob: float
    when: tuple[int, str, int] | None = None

    def __post_init__(self):
        object.__setattr__(self, "address", check_int("RamEvent.address", self.address, 0, 127))
        values = (self.values,) if isinstance(self.values, int) else self.values
        if not isinstance(values, (tuple, list)) or not values:
            raise ValueError(f"RamEvent.values must be a non-empty tuple of bytes (0..255), "
                             f"got {self.values!r}")
        object.__setattr__(self, "values", tuple(check_int("RamEvent.values", v, 0, 255)
                                                 for v in values))
        object.__setattr__(self, "prob", check_draw_probability("RamEvent.prob", self.prob))
        if self.when is not None:
            if not (isinstance(self.when, (tuple, list)) and len(self.when) == 3):
                raise ValueError("RamEvent.when must be (address, op, value) with op one of "
                                 f"{list(RAM_CONDITIONS)}, or None, got {self.when!r}")
            address, op, value = self.when
            object.__setattr__(self, "when", (
                check_int("RamEvent.when address", address, 0, 127),
                _check_choice("RamEvent", "when op", op, RAM_CONDITIONS),
                check_int("RamEvent.when value", value, 0, 255)))


@dataclass(frozen=True)
class ObservationMask:
    """Type 3.2: hide part of the observation with probability ``prob`` per frame (or step).

    kind ``crop`` (any game): mode 1 left half, 2 right half, 3 top half, 4 bottom half, 5 torch.
    kind ``blackout``: fill the game's named regions (see the game's blackout table).
    kind ``ram``: render the frame from a modified copy of the RAM (see the game's RAM table).
    kind ``objects`` (games with an object table, docs/objects.md): mode 1 blacks out the
    boxes of the object ``classes`` (from each screen's own RAM).
    """

    kind: str
    mode: int
    prob: float = 1.0
    classes: tuple[str, ...] | None = None

    def __post_init__(self):
        object.__setattr__(self, "kind",
                           _check_choice("ObservationMask", "kind", self.kind, MASK_KINDS))
        mode = check_int("ObservationMask.mode", self.mode)
        object.__setattr__(self, "mode", mode)
        if mode == 0:
            raise ValueError(f"ObservationMask.mode 0 is the spec's 'none' for kind "
                             f"{self.kind!r}: leave the mask out (no observation mask is 3.1)")
        if self.kind == "objects":
            _check_choice("ObservationMask", "mode (objects)", mode, tuple(OBJECTS_MODES))
            classes = (self.classes,) if isinstance(self.classes, str) else self.classes
            if (not isinstance(classes, (tuple, list)) or not classes
                    or not all(isinstance(c, str) for c in classes)):
                raise ValueError("ObservationMask.classes must name the object classes to hide "
                                 "(a non-empty tuple of names, e.g. ('Ball',): "
                                 f"stori-jax list --objects), got {self.classes!r}")
            if len(set(classes)) < len(classes):
                raise ValueError(f"ObservationMask.classes must name each class once, got "
                                 f"{self.classes!r}")
            object.__setattr__(self, "classes", tuple(classes))
        elif self.classes is not None:
            raise ValueError(f"ObservationMask.classes applies to kind 'objects' only, got "
                             f"classes={self.classes!r} with kind {self.kind!r}")
        if self.kind == "crop":
            _check_choice("ObservationMask", "mode (crop)", mode, CROP_MODES)
        elif mode < 1:
            raise ValueError(f"ObservationMask.mode must be >= 1 for kind {self.kind!r}, got {mode}")
        object.__setattr__(self, "prob", check_draw_probability("ObservationMask.prob", self.prob))


@dataclass(frozen=True)
class ConceptDrift:
    """Type 2.2: concept 1 is the default game (3.1); concept 2 is ``secondary``.

    Concept of 0-indexed agent step k of an episode (the counter restarts at every reset):
    - ``sudden``:  concept 2 iff k >= period
    - ``cyclic``:  concept 2 iff (k // period) % 2 == 1
    - ``gradual``: concept 2 with probability clip((k - period) / period, 0, 1)
    """

    schedule: str
    period: int
    secondary: "Config"

    def __post_init__(self):
        object.__setattr__(self, "schedule", _check_choice("ConceptDrift", "schedule",
                                                           self.schedule, DRIFT_SCHEDULES))
        period = check_int("ConceptDrift.period", self.period)
        object.__setattr__(self, "period", period)
        if period < 1:
            raise ValueError(f"ConceptDrift.period (T) must be >= 1 agent step, got {period}")
        if period > MAX_INT32:  # episode steps are counted in int32
            raise ValueError(f"ConceptDrift.period (T) must be <= {MAX_INT32} agent steps, "
                             f"got {shown(period)}")
        if not isinstance(self.secondary, Config):
            raise ValueError("ConceptDrift.secondary must be a Config of type "
                             f"{list(SECONDARY_TYPES)}, got {self.secondary!r}")
        secondary_type = self.secondary.type
        if self.secondary.drift is not None:
            raise ValueError("ConceptDrift.secondary cannot itself be a 2.2 concept drift "
                             f"(allowed secondary types: {list(SECONDARY_TYPES)})")
        if secondary_type not in SECONDARY_TYPES:
            raise ValueError(f"ConceptDrift.secondary must be of type {list(SECONDARY_TYPES)}, "
                             f"got type {secondary_type!r}")


@dataclass(frozen=True)
class Config:
    """A STORI environment configuration. All parts default to "off" (type 3.1)."""

    action_noise: ActionNoise | None = None
    event: RandomEvent | RamEvent | None = None
    drift: ConceptDrift | None = None
    observation: ObservationMask | None = None
    ram_observation: bool = False
    granularity: str = "frame"
    game: str | None = None
    type: str = field(default="")

    def __post_init__(self):
        for name, cls in (("action_noise", ActionNoise), ("event", (RandomEvent, RamEvent)),
                          ("drift", ConceptDrift), ("observation", ObservationMask)):
            value = getattr(self, name)
            if value is not None and not isinstance(value, cls):
                names = " or ".join(c.__name__ for c in (cls if isinstance(cls, tuple) else (cls,)))
                raise ValueError(f"Config.{name} must be a {names} or None, got {value!r}")
        object.__setattr__(self, "ram_observation",
                           check_bool("Config.ram_observation", self.ram_observation))
        object.__setattr__(self, "granularity", _check_choice("Config", "granularity",
                                                              self.granularity, GRANULARITIES))
        if self.ram_observation and self.observation is not None:
            raise ValueError("Config.ram_observation (type 0) observes the RAM, so it cannot be "
                             "combined with an observation mask (type 3.2)")
        derived = self._derive_type()
        if not isinstance(self.type, str):  # "" (the default) derives it; 0 or None is no type
            raise ValueError(f"Config.type must be one of {list(TAXONOMY_TYPES + ('mixed',))} "
                             f"(or left out), got {self.type!r}")
        if self.type:
            _check_choice("Config", "type", self.type, TAXONOMY_TYPES + ("mixed",))
            if self.type != derived:
                raise ValueError(f"Config.type {self.type!r} does not match its parts, which make "
                                 f"type {derived!r}")
        object.__setattr__(self, "type", derived)
        if self.drift is not None:
            self._check_secondary(self.drift.secondary)
        if self.game is not None:
            spec = get_game(self.game)
            object.__setattr__(self, "game", spec.name)  # one spelling: 'breakout' is Breakout
            spec.validate(self)

    def _check_secondary(self, secondary: "Config") -> None:
        """Concept 2 lives inside this config: nothing it sets may be ignored or contradict it."""
        for name in ("action_noise", "event", "observation"):
            if getattr(self, name) is not None and getattr(secondary, name) is not None:
                raise ValueError(f"Config.{name} is set both directly and in drift.secondary; "
                                 "set it in one place only")
        if self.ram_observation and secondary.observation is not None:
            raise ValueError("Config.ram_observation (type 0) observes the RAM, so it cannot be "
                             "combined with an observation mask (type 3.2) in drift.secondary")
        if secondary.granularity != "frame" and secondary.granularity != self.granularity:
            raise ValueError(f"Config.drift.secondary.granularity {secondary.granularity!r} is not "
                             f"used: both concepts draw events at Config.granularity "
                             f"({self.granularity!r}); set it there")
        if secondary.game is not None and self.game is not None \
                and get_game(secondary.game).rom_id != get_game(self.game).rom_id:
            raise ValueError(f"Config.drift.secondary is bound to game {secondary.game!r} but "
                             f"Config.game is {self.game!r}; a drift stays in one game")

    def _derive_type(self) -> str:
        parts = [t for t, on in (("0", self.ram_observation),
                                 ("1", self.action_noise is not None),
                                 ("2.1", self.event is not None),
                                 ("2.2", self.drift is not None),
                                 ("3.2", self.observation is not None)) if on]
        if not parts:
            return "3.1"
        return parts[0] if len(parts) == 1 else "mixed"

    # -- helpers -----------------------------------------------------------------------------

    def replace(self, **changes) -> "Config":
        """A copy with ``changes`` applied (re-validated; the type is derived again)."""
        changes.setdefault("type", "")
        return dataclasses.replace(self, **changes)

    def for_game(self, game: str) -> "Config":
        """This config bound to ``game`` (validated against its modes)."""
        return self.replace(game=game)

    def components(self) -> list[tuple[str, object, bool]]:
        """(name, part, under_drift) for every active part, the drift's secondary included."""
        out = []
        for name in ("action_noise", "event", "observation"):
            if getattr(self, name) is not None:
                out.append((name, getattr(self, name), False))
        if self.drift is not None:
            for name in ("action_noise", "event", "observation"):
                part = getattr(self.drift.secondary, name)
                if part is not None:
                    out.append((name, part, True))
        return out

    def is_deterministic(self) -> bool:
        """True when nothing here draws at random: no action noise or event at p > 0, masks
        only at p 0 or 1 and never the torch (its centre is drawn), no gradual drift. The env
        then plays the same game from every seed under the same actions (its emulators have no
        randomness of their own without sticky actions), unless ``make(noop_max=N)`` draws
        random no-ops at each reset."""
        for _, part, _ in self.components():
            if isinstance(part, ObservationMask):
                if part.prob not in (0.0, 1.0) or is_torch(part.kind, part.mode):
                    return False
            elif part.prob > 0:
                return False
        return self.drift is None or self.drift.schedule != "gradual"

    def describe(self) -> str:
        bits = []
        for name, part, drifted in self.components():
            bits.append(("concept 2: " if drifted else "") + _describe_part(part))
        if self.drift is not None:
            bits.insert(0, f"{self.drift.schedule} drift, T={self.drift.period}")
        if self.ram_observation:
            bits.append("RAM observation")
        return f"type {self.type}" + (" (" + "; ".join(bits) + ")" if bits else " (default)")


def _describe_part(part) -> str:
    if isinstance(part, RamEvent):
        when = f" when RAM[{part.when[0]}] {part.when[1]} {part.when[2]}" if part.when else ""
        return f"RAM[{part.address}] <- {list(part.values)}{when} p={part.prob:g}"
    if isinstance(part, ActionNoise):
        kind = "sticky" if part.sticky else "uniform replacement"
        return f"action noise {kind} p={part.prob:g}"
    if isinstance(part, RandomEvent):
        return f"event mode {part.mode} p={part.prob:g}"
    if isinstance(part, ObservationMask) and part.kind == "objects":
        return f"objects {'+'.join(part.classes)} hidden p={part.prob:g}"
    if isinstance(part, ObservationMask):
        return f"{part.kind} mode {part.mode} p={part.prob:g}"
    return repr(part)
