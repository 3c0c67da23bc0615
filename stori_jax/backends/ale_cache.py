"""Loaded ALE emulators, kept for reuse within a process.

Loading a ROM costs ~0.1 s (ALE rebuilds its colour-averaging palette on every load, whatever
the settings); restoring the state an emulator of the same ROM had right after a load with the
same settings and seed costs ~0.1 ms and leaves it in exactly that state, its RNG included.  So
an env made again, or reset with a seed, in a process that has loaded that ROM before reuses
what it can: closed envs give their emulators back (``release``), and the state after each
(ROM, frame limit, seed) load is remembered.  Both are bounded (least recently used first).
"""

from __future__ import annotations

import threading
from collections import OrderedDict

MAX_IDLE = 128      # emulators kept for reuse (~0.7 MB each)
MAX_STATES = 2048   # states right after a load kept (~15 KB each)

_lock = threading.Lock()
_idle: OrderedDict[tuple, list] = OrderedDict()     # (rom path, frame limit) -> emulators
_loaded: OrderedDict[tuple, object] = OrderedDict()  # (rom path, frame limit, seed) -> state


def acquire(rom_path: str, max_episode_frames: int, seed: int):
    """An ALE emulator of ``rom_path`` as a fresh load with this frame limit and seed leaves it."""
    key = (rom_path, max_episode_frames)
    with _lock:
        kept = _idle.get(key)
        ale = kept.pop() if kept else None
        if kept == []:
            del _idle[key]
    reused = ale is not None
    if not reused:
        from ale_py import ALEInterface, LoggerMode

        ALEInterface.setLoggerMode(LoggerMode.Error)
        ale = ALEInterface()
        ale.setFloat("repeat_action_probability", 0.0)
        ale.setInt("max_num_frames_per_episode", int(max_episode_frames))
    reload(ale, rom_path, max_episode_frames, seed, has_rom=reused)
    return ale


def reload(ale, rom_path: str, max_episode_frames: int, seed: int, has_rom: bool = True) -> None:
    """Put ``ale`` (made by :func:`acquire` with this frame limit; ``has_rom``: with
    ``rom_path`` loaded) in the state a fresh load of ``rom_path`` seeded ``seed`` leaves."""
    key = (rom_path, max_episode_frames, int(seed))
    with _lock:
        state = _loaded.get(key)
        if state is not None:
            _loaded.move_to_end(key)
    if state is not None and has_rom:
        ale.restoreState(state)
        return
    ale.setInt("random_seed", int(seed))
    ale.loadROM(rom_path)
    state = ale.cloneState(include_rng=True)
    with _lock:
        _loaded[key] = state
        while len(_loaded) > MAX_STATES:
            _loaded.popitem(last=False)


def release(ale, rom_path: str, max_episode_frames: int) -> None:
    """Give back an emulator (of ``rom_path``, made by :func:`acquire`) no env uses any more."""
    with _lock:
        key = (rom_path, max_episode_frames)
        _idle.setdefault(key, []).append(ale)
        _idle.move_to_end(key)
        while sum(len(kept) for kept in _idle.values()) > MAX_IDLE:
            oldest = next(iter(_idle))
            del _idle[oldest][0]
            if not _idle[oldest]:
                del _idle[oldest]
