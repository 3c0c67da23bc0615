"""The shape of a game's facts: regions, mode tables, event rules and labels.

Everything here is plain Python/numpy (no JAX): the emulator workers import it.

Event rules are plain functions over RAM arrays (``np.uint8``, shape (128,)) and uniforms; they
return the RAM bytes to write and what happened.  The worker runs them per emulator frame (or once
per agent step at ``step`` granularity) and applies the writes with ``ALEInterface.setRAM``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

SCREEN_HEIGHT, SCREEN_WIDTH = 210, 160
BLACK = (0, 0, 0)

RamWrites = dict  # {address: value}


@dataclass(frozen=True)
class Region:
    """A screen rectangle, INCLUSIVE on both ends: columns x0..x1, rows y0..y1, and its fill."""

    x0: int
    x1: int
    y0: int
    y1: int
    fill: tuple[int, int, int] = BLACK

    def __post_init__(self):
        if not (0 <= self.x0 <= self.x1 < SCREEN_WIDTH and 0 <= self.y0 <= self.y1 < SCREEN_HEIGHT):
            raise ValueError(f"region out of the 160x210 screen: {self}")

    def with_fill(self, fill: tuple[int, int, int]) -> "Region":
        return Region(self.x0, self.x1, self.y0, self.y1, fill)


# 3.2 crop modes, the same for every game: 1..4 black out a half of the screen, 5 is the torch
CROP_REGIONS = {
    1: (Region(0, 79, 0, SCREEN_HEIGHT - 1),),
    2: (Region(80, SCREEN_WIDTH - 1, 0, SCREEN_HEIGHT - 1),),
    3: (Region(0, SCREEN_WIDTH - 1, 0, 104),),
    4: (Region(0, SCREEN_WIDTH - 1, 105, SCREEN_HEIGHT - 1),),
}
TORCH_MODE = 5
TORCH_RADIUS = 75
CROP_MODES = tuple(CROP_REGIONS) + (TORCH_MODE,)  # 0 ("none") is leaving the mask out


def is_torch(kind: str, mode: int) -> bool:
    """Whether an observation mask is the torch (a circle around a centre drawn at random)."""
    return kind == "crop" and mode == TORCH_MODE


@dataclass
class EventOutcome:
    """What a post-frame rule did: RAM writes, whether it fired, and the reward consequences."""

    writes: RamWrites = field(default_factory=dict)
    fired: bool = False
    zero_reward: bool = False  # set the reward of this frame (or step) to 0
    cancel_next_reward: bool = False  # ALE will report minus this reward next frame: remove it


NO_EVENT = EventOutcome()


@dataclass(frozen=True)
class EventRule:
    """A 2.1 event mode.

    ``pre_frame(start_ram, state, u, p, decide) -> (writes, fired)`` runs before every emulator
    frame; ``decide`` is False on the frames of a step after the first at ``step`` granularity
    (the rule must then only re-apply its standing effect).
    ``post_frame(prev_ram, ram, start_ram, state, u, u_choice, p, episode_frame) -> EventOutcome``
    runs after the frame (``prev_ram`` = RAM just before the frame, or before the step at ``step``
    granularity).  ``state`` is a per-episode dict made by ``new_state()``.
    """

    name: str
    pre_frame: Callable | None = None
    post_frame: Callable | None = None
    new_state: Callable[[], dict] = dict


_CONDITIONS = {"==": np.equal, "!=": np.not_equal, "<": np.less, "<=": np.less_equal,
               ">": np.greater, ">=": np.greater_equal}


def ram_write_rule(address: int, values: tuple[int, ...], when) -> EventRule:
    """The rule of a ``RamEvent``: after a frame (or a step's last), where ``when`` holds on
    the RAM, with probability p write ``values[floor(u_choice * len(values))]`` to
    ``address``."""
    def post_frame(prev_ram, ram, start_ram, state, u, u_choice, p, episode_frame):
        if when is not None and not _CONDITIONS[when[1]](int(ram[when[0]]), when[2]):
            return NO_EVENT
        if not u < p:
            return NO_EVENT
        value = values[min(int(u_choice * len(values)), len(values) - 1)]
        return EventOutcome(writes={address: value}, fired=True)

    return EventRule(f"RAM[{address}] <- {list(values)}", post_frame=post_frame)


@dataclass(frozen=True)
class BlackoutMode:
    name: str
    regions: tuple[Region, ...]  # painted in order (later regions overwrite earlier ones)


@dataclass(frozen=True)
class RamObsMode:
    """``writes(ram) -> {address: value}`` or ``None`` when its condition is not met (skip)."""

    name: str
    writes: Callable[[np.ndarray], RamWrites | None]


@dataclass(frozen=True)
class GameSpec:
    """Every STORI fact about one game, in one place."""

    name: str
    rom_id: str
    num_actions: int
    # ALE's lives() of the game at power-on (its ROM loaded, no reset yet): what ale-py's env
    # answers before its first reset; 0 for a game ALE counts no lives of (Boxing)
    start_lives: int
    regions: Mapping[str, Region] = field(default_factory=dict)
    blackout_modes: Mapping[int, BlackoutMode] = field(default_factory=dict)
    ram_obs_modes: Mapping[int, RamObsMode] = field(default_factory=dict)
    event_modes: Mapping[int, EventRule] = field(default_factory=dict)
    # name -> f(ram_int32[..., 128]) -> value; works on numpy and jax arrays alike
    labels: Mapping[str, Callable] = field(default_factory=dict)
    default_replacement_actions: tuple[int, ...] | None = None
    screen_height: int = 210  # ALE's rows of its screen (AirRaid, Pacman: 250)

    # -- validation --------------------------------------------------------------------------

    def validate(self, config) -> None:
        """Raise ValueError if ``config`` uses a mode or action this game does not have."""
        configs = [("Config", config)]
        if config.drift is not None:
            configs.append(("Config.drift.secondary", config.drift.secondary))
        for where, cfg in configs:
            if cfg.event is not None and hasattr(cfg.event, "mode"):  # RamEvent: any game
                self._check_mode(f"{where}.event.mode", cfg.event.mode, self.event_modes,
                                 "event modes")
            mask = cfg.observation
            if mask is not None and mask.kind == "blackout":
                self._check_mode(f"{where}.observation.mode", mask.mode, self.blackout_modes,
                                 "blackout modes")
            if mask is not None and mask.kind == "ram":
                self._check_mode(f"{where}.observation.mode", mask.mode, self.ram_obs_modes,
                                 "RAM observation modes")
            if mask is not None and mask.kind == "objects":
                from stori_jax.objects import check_classes  # JAX: not in the workers

                check_classes(self.name, mask.classes, f"{where}.observation.classes")
            noise = cfg.action_noise
            if noise is not None and noise.replacement_actions is not None:
                bad = [a for a in noise.replacement_actions if a >= self.num_actions]
                if bad:
                    raise ValueError(f"{where}.action_noise.replacement_actions {bad} out of range: "
                                     f"{self.name} has actions 0..{self.num_actions - 1}")

    def _check_mode(self, field_name: str, mode: int, table: Mapping, what: str) -> None:
        if mode not in table:
            allowed = sorted(table)
            raise ValueError(f"{field_name} {mode} is not one of {self.name}'s {what}: "
                             f"allowed {allowed}" if allowed else
                             f"{field_name}: {self.name} has no {what} (it is not a STORI game; "
                             "only game-agnostic modes work: type 1, crop, drift)")

    def replacement_actions(self, noise) -> tuple[int, ...]:
        if noise.replacement_actions is not None:
            return noise.replacement_actions
        if self.default_replacement_actions is not None:
            return self.default_replacement_actions
        return tuple(range(self.num_actions))


# -- small helpers shared by the game modules -------------------------------------------------

def bcd(value):
    """Binary-coded decimal byte -> int (numpy or jax int arrays)."""
    return (value >> 4) * 10 + (value & 15)


def byte_labels(names, addresses) -> dict[str, Callable]:
    """{name: ram -> ram[..., address]}: type-0 labels that are single RAM bytes."""
    return {name: (lambda a: lambda ram: ram[..., a])(int(a)) for name, a in zip(names, addresses)}


def full_width(y0: int, y1: int, fill=BLACK) -> Region:
    return Region(0, SCREEN_WIDTH - 1, y0, y1, fill)


def blackout_table(regions: Mapping[str, Region],
                   modes: Mapping[int, tuple[str, tuple[str, ...]]]) -> dict[int, BlackoutMode]:
    """Build {mode: BlackoutMode} from {mode: (description, region names in paint order)}."""
    return {mode: BlackoutMode(name, tuple(regions[r] for r in names))
            for mode, (name, names) in modes.items()}


def changed(prev_ram: np.ndarray, ram: np.ndarray, addresses) -> np.ndarray:
    """The addresses (from ``addresses``) whose byte differs between the two RAMs."""
    addresses = np.asarray(addresses)
    return addresses[prev_ram[addresses] != ram[addresses]]


def pick(items, u_choice: float):
    """One of ``items`` chosen uniformly by a uniform draw in [0, 1)."""
    return items[min(int(u_choice * len(items)), len(items) - 1)]
