"""The shared-memory buffers exchanged between the parent and the emulator workers.

One place for their names, shapes and dtypes; both sides build numpy views from this table.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass

import numpy as np

from stori_jax.pixels import OBSERVATION_SHAPES

SCREEN = (210, 160, 3)
RAM_SIZE = 128

# ram_render bits: bit j = render RAM-obs into screen slot j after a normal step;
# bit 2 + j = the same for the first observation of a new episode (after an autoreset / reset).
STEP_RENDER_BITS = (1, 2)
RESET_RENDER_BITS = (4, 8)


def buffer_specs(num_envs: int, frame_skip: int, screens: bool = True,
                 final: bool = False, frames_layout: str = "pair"
                 ) -> dict[str, tuple[tuple[int, ...], type]]:
    """Name -> (shape, dtype) of every buffer; without ``screens`` (a RAM observation) the
    frame buffers hold no pixels.  ``final`` (an autoresetting batch): also the buffers of an
    ended episode's last observation, written where a step's episode ended (the others hold
    the next episode's first).  ``frames_layout`` (stori_jax.pixels): an observation made by
    the emulating processes travels instead of the two screens."""
    b = num_envs
    if frames_layout in OBSERVATION_SHAPES and screens:
        frames = ((b,) + OBSERVATION_SHAPES[frames_layout], np.uint8)
    else:
        frames = ((2, b) + (SCREEN if screens else (0, 0, SCREEN[2])), np.uint8)
    specs = {
        # parent -> workers
        "executed": ((b, frame_skip), np.int32),      # minimal-set action index per frame
        "event_u": ((b, frame_skip, 2), np.float32),   # per frame: firing draw, choice draw
        "event_active": ((b,), np.uint8),              # event rule on (concept) for this step
        "ram_render": ((b,), np.uint8),                # RAM-obs render bits (see above)
        "noops": ((b,), np.int32),                     # no-op frames after a reset
        "reset_first": ((b,), np.uint8),               # reset this env instead of stepping it
        # workers -> parent
        "frames": frames,                              # the last two screens, slot-major
        #                                                (one frame in both: see single_frame)
        "ram": ((b, RAM_SIZE), np.uint8),
        "reward": ((b,), np.float32),
        "terminated": ((b,), np.uint8),
        "truncated": ((b,), np.uint8),
        "lives": ((b,), np.int32),
        "event_fired": ((b,), np.int32),
        "ram_rendered": ((b,), np.uint8),              # render bits actually applied (0..3)
        "single_frame": ((b,), np.uint8),              # both screens are one emulator frame
        "frames_played": ((b,), np.int32),             # emulator frames the step played (0:
        #                                                reset instead; < frame_skip: its
        #                                                episode ended before the last frame)
        "episode_return": ((b,), np.float32),          # final value where an episode ended
        "episode_length": ((b,), np.int32),
    }
    if final:  # what frames, single_frame and ram held before the autoreset replaced them
        specs.update(final_frames=frames, final_single_frame=((b,), np.uint8),
                     final_ram=((b, RAM_SIZE), np.uint8))
    return specs


def shared_bytes(num_envs: int, frame_skip: int, screens: bool = True,
                 final: bool = False, frames_layout: str = "pair") -> int:
    """The bytes :func:`buffer_specs` asks for (computed, nothing allocated)."""
    specs = buffer_specs(num_envs, frame_skip, screens, final, frames_layout)
    return sum(int(np.prod(shape, dtype=object)) * np.dtype(dtype).itemsize
               for shape, dtype in specs.values())


@dataclass
class SharedBuffers:
    """RawArrays (picklable into spawned workers) plus numpy views over them."""

    raw: dict

    @classmethod
    def allocate(cls, ctx, num_envs: int, frame_skip: int, screens: bool = True,
                 final: bool = False, frames_layout: str = "pair") -> "SharedBuffers":
        raw = {}
        specs = buffer_specs(num_envs, frame_skip, screens, final, frames_layout)
        for name, (shape, dtype) in specs.items():
            nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
            raw[name] = (ctx.RawArray(ctypes.c_uint8, nbytes), shape, np.dtype(dtype).str)
        return cls(raw)

    def views(self) -> dict[str, np.ndarray]:
        return {name: np.frombuffer(arr, dtype=np.dtype(dtype)).reshape(shape)
                for name, (arr, shape, dtype) in self.raw.items()}
