"""A Config compiled against a game and the env's settings into the facts the jitted functions
and the workers need.

A :class:`Plan` is a pytree: its structure (game, batch, observation, which components, their
kinds and modes) is static, its numbers (probabilities, the drift period) are leaves, traced
by ``jax.jit``.  Configs that differ only in numbers share every compilation."""

from __future__ import annotations

from dataclasses import dataclass, fields

import jax
import numpy as np

from stori_jax.config import ActionNoise, Config, ObservationMask, RamEvent, RandomEvent
from stori_jax.games.base import GameSpec

OBS_KINDS = ("raw", "atari84", "dreamer64", "ram", "objects")
SCREENLESS_OBS = ("ram", "objects")  # observations made from the RAM: no screen is handed over


def numbers_traced(*numbers: str):
    """Register a frozen dataclass as a pytree whose fields ``numbers`` (and nested plans) are
    leaves and whose other fields are static structure."""
    def register(cls):
        data = [f.name for f in fields(cls) if f.name in numbers]
        meta = [f.name for f in fields(cls) if f.name not in numbers]
        return jax.tree_util.register_dataclass(cls, data_fields=data, meta_fields=meta)
    return register


@numbers_traced("prob")
@dataclass(frozen=True)
class NoisePlan:
    prob: float
    replacement: tuple[int, ...]
    sticky: bool
    under_drift: bool


@numbers_traced("prob")
@dataclass(frozen=True)
class EventPlan:
    mode: int  # the game's event mode (0: a RamEvent)
    prob: float
    under_drift: bool
    ram_event: tuple | None = None  # a RamEvent's (address, values, when)


@numbers_traced("prob")
@dataclass(frozen=True)
class MaskPlan:
    kind: str  # crop | blackout | ram | objects
    mode: int
    prob: float
    under_drift: bool
    classes: tuple[str, ...] = ()  # kind objects: the classes hidden

    @property
    def torch(self) -> bool:
        from stori_jax.games.base import is_torch

        return is_torch(self.kind, self.mode)


@numbers_traced("noise", "event", "mask", "drift_period")
@dataclass(frozen=True)
class Plan:
    game: str
    num_envs: int
    num_actions: int
    frame_skip: int
    per_frame: bool
    obs: str
    noop_max: int
    autoreset: bool
    noise: NoisePlan | None = None
    event: EventPlan | None = None
    mask: MaskPlan | None = None
    drift_schedule: str | None = None
    drift_period: int = 0
    frames_layout: str = "pair"  # how the backend delivers screens (see pool_screens)

    @property
    def screens(self) -> bool:
        """Whether the emulators hand screens over (not for an observation of the RAM)."""
        return self.obs not in SCREENLESS_OBS

    @property
    def needs_both_screens(self) -> bool:
        """True when each of the last two screens must be masked on its own before the
        max-pool: a crop/blackout mask drawn per emulator frame, or hidden objects (each screen
        has its own boxes, from its own RAM)."""
        return self.mask is not None and (self.mask.kind == "objects" or
                                          (self.mask.kind != "ram" and self.per_frame))

    @property
    def needs_screen_ram(self) -> bool:
        """The RAM of each handed-over screen is needed (hidden objects' boxes)."""
        return self.mask is not None and self.mask.kind == "objects" and self.screens

    @property
    def num_slots(self) -> int:
        """Independent draws per agent step: one per emulator frame, or one per step."""
        return self.frame_skip if self.per_frame else 1

    def static_mask(self, game: GameSpec) -> tuple[np.ndarray, np.ndarray]:
        """(hidden, fill) of a crop-half or blackout mask."""
        from stori_jax.functional.masks import CROP_REGIONS, region_mask

        if self.mask.kind == "crop":
            return region_mask(CROP_REGIONS[self.mask.mode])
        return region_mask(game.blackout_modes[self.mask.mode].regions)


def compile_plan(config: Config, game: GameSpec, *, num_envs: int, frame_skip: int, obs: str,
                 noop_max: int, autoreset: bool = True) -> Plan:
    game.validate(config)
    parts = {"noise": None, "event": None, "mask": None}
    for name, part, under_drift in config.components():
        if isinstance(part, ActionNoise):
            parts["noise"] = NoisePlan(part.prob, game.replacement_actions(part), part.sticky,
                                       under_drift)
        elif isinstance(part, RandomEvent):
            parts["event"] = EventPlan(part.mode, part.prob, under_drift)
        elif isinstance(part, RamEvent):
            parts["event"] = EventPlan(0, part.prob, under_drift,
                                       (part.address, part.values, part.when))
        elif isinstance(part, ObservationMask):
            parts["mask"] = MaskPlan(part.kind, part.mode, part.prob, under_drift,
                                     part.classes or ())
    drift = config.drift
    return Plan(game=game.name, num_envs=num_envs, num_actions=game.num_actions,
                frame_skip=frame_skip, per_frame=config.granularity == "frame", obs=obs,
                noop_max=noop_max, autoreset=autoreset, **parts,
                drift_schedule=drift.schedule if drift else None,
                drift_period=drift.period if drift else 0)
