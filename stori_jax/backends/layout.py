"""The shared-memory buffers exchanged between the parent and the emulator workers.

One table of a step's per-env arrays (:data:`STEP_BUFFERS`: name, dtype, shape, writer): the
shared memory, ``core.WorkerOutputs``, ``env.xla()``'s callback shapes and the envpool
backend's outputs are all built from it.
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


@dataclass(frozen=True)
class StepBuffer:
    """One per-env array a step exchanges: ``shape`` per env (``"skip"`` is the frame skip,
    ``"frames"`` the screens as ``frames_layout`` hands them over), who writes it (``"caller"``:
    the env's draws, read by the emulating processes; ``"emulators"``: a step's output, read
    by the JAX side), and whether only an autoresetting batch has it (``final``)."""

    name: str
    dtype: type
    shape: tuple
    writer: str
    final: bool = False


STEP_BUFFERS = (
    # the caller's draws
    StepBuffer("executed", np.int32, ("skip",), "caller"),     # minimal-set action per frame
    StepBuffer("event_u", np.float32, ("skip", 2), "caller"),  # per frame: firing, choice draw
    StepBuffer("event_active", np.uint8, (), "caller"),        # event rule on (the concept)
    StepBuffer("ram_render", np.uint8, (), "caller"),          # RAM-obs render bits (above)
    StepBuffer("noops", np.int32, (), "caller"),               # no-op frames after a reset
    StepBuffer("reset_first", np.uint8, (), "caller"),         # reset instead of stepping
    # the step's outputs
    StepBuffer("frames", np.uint8, "frames", "emulators"),     # the last two screens (one
    #                                                            frame in both: single_frame)
    StepBuffer("ram", np.uint8, (RAM_SIZE,), "emulators"),
    StepBuffer("screen_ram", np.uint8, (2, RAM_SIZE), "emulators"),  # the RAM each screen of
    #                                                  the pair was made from (hidden objects)
    StepBuffer("ram_rendered", np.uint8, (), "emulators"),     # render bits applied (0..3)
    StepBuffer("single_frame", np.uint8, (), "emulators"),     # both screens one frame (a
    #                                                            reset, skip 1, an early end)
    StepBuffer("frames_played", np.int32, (), "emulators"),    # 0: reset instead; < skip:
    #                                                            the episode ended before
    StepBuffer("reward", np.float32, (), "emulators"),
    StepBuffer("terminated", np.uint8, (), "emulators"),
    StepBuffer("truncated", np.uint8, (), "emulators"),
    StepBuffer("lives", np.int32, (), "emulators"),
    StepBuffer("event_fired", np.int32, (), "emulators"),
    StepBuffer("episode_return", np.float32, (), "emulators"),  # where an episode ended
    StepBuffer("episode_length", np.int32, (), "emulators"),
    # an autoresetting batch: what frames, single_frame, ram, screen_ram held before the
    # autoreset
    StepBuffer("final_frames", np.uint8, "frames", "emulators", final=True),
    StepBuffer("final_single_frame", np.uint8, (), "emulators", final=True),
    StepBuffer("final_ram", np.uint8, (RAM_SIZE,), "emulators", final=True),
    StepBuffer("final_screen_ram", np.uint8, (2, RAM_SIZE), "emulators", final=True),
)
STEP_OUTPUTS = tuple(b.name for b in STEP_BUFFERS if b.writer == "emulators" and not b.final)
FINAL_OUTPUTS = tuple(b.name for b in STEP_BUFFERS if b.final)
FRAME_OUTPUTS = tuple(b.name for b in STEP_BUFFERS if b.shape == "frames")


def frames_shape(layout: str, num_envs: int, screens: bool = True) -> tuple[int, ...]:
    """The shape of a batch's screens handed over in ``layout`` (stori_jax.pixels): both
    screens slot-major (``pair``), one pooled screen (``pooled``, ``pooled_chw``: channels
    first), or an observation made by the emulating processes; without screens (a RAM
    observation), each env's two slots of no pixels."""
    height, width, channels = SCREEN
    if not screens:
        return (2, num_envs, 0, 0, channels)
    shapes = {"pair": (2, num_envs) + SCREEN, "pooled": (num_envs,) + SCREEN,
              "pooled_chw": (num_envs, channels, height, width),
              **{name: (num_envs,) + shape for name, shape in OBSERVATION_SHAPES.items()}}
    if layout not in shapes:
        raise ValueError(f"frames layout must be one of {list(shapes)}, got {layout!r}")
    return shapes[layout]


def buffer_specs(num_envs: int, frame_skip: int, screens: bool = True,
                 final: bool = False, frames_layout: str = "pair"
                 ) -> dict[str, tuple[tuple[int, ...], type]]:
    """Name -> (shape, dtype) of every :data:`STEP_BUFFERS` entry of a batch (the final ones
    only with ``final``, an autoresetting batch)."""
    sizes = {"skip": frame_skip}
    return {b.name: (frames_shape(frames_layout, num_envs, screens) if b.shape == "frames"
                     else (num_envs,) + tuple(sizes.get(d, d) for d in b.shape), b.dtype)
            for b in STEP_BUFFERS if final or not b.final}


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
