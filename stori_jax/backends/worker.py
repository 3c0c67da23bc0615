"""The emulator worker process: owns a slice of the batch's emulators
(``stori_jax.backends.emulator``) and steps them on command.

Protocol over a Pipe, one command a message: b"S" step this worker's envs, b"R" reset all
(b"R" + a seed in ASCII: first restart every emulator from that batch seed, as a new env of
it), b"C" close, b"P" snapshot (the reply carries the pickled emulator states), b"L" + the
path of a file of pickled states: restore (a file, so that every command stays small: see
interrupts.py).  Replies: b"K" done (+ a payload for b"P"), or b"E" + a traceback.
"""

from __future__ import annotations

import os
import pickle
import signal
import threading
import time
import traceback

from stori_jax.backends.emulator import EmulatorSpec, make_emulators

def reset_command(batch_seed: int | None) -> bytes:
    """The command that resets every emulator (from ``batch_seed`` afresh, unless None)."""
    return b"R" if batch_seed is None else b"R%d" % batch_seed


def reset_seed(command: bytes) -> int | None:
    """The batch seed a reset command restarts from (None: a plain reset)."""
    return int(command[1:]) if len(command) > 1 else None


def _exit_with_parent(parent_pid: int, interval: float = 0.5) -> None:
    """Exit as soon as the parent process is gone (no orphans after a hard kill of it).  A
    watchdog thread, not Linux's PR_SET_PDEATHSIG: that fires when the parent's *thread* that
    started this worker exits, which would kill the workers of an env made in a short-lived
    thread (a thread pool, a data loader) while the env is still in use."""
    def watch():
        while os.getppid() == parent_pid:
            time.sleep(interval)
        os._exit(0)

    threading.Thread(target=watch, daemon=True, name="stori-jax-parent-watch").start()


def worker_main(spec: EmulatorSpec, buffers, conn, parent_pid: int) -> None:
    """Entry point of a worker process."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    if os.getppid() != parent_pid:
        return
    _exit_with_parent(parent_pid)
    try:
        emulators = make_emulators(spec, buffers.views())
        conn.send_bytes(b"K")
    except BaseException:
        conn.send_bytes(b"E" + traceback.format_exc().encode())
        return
    while True:
        try:
            command = conn.recv_bytes()
        except (EOFError, OSError):
            return
        try:
            reply = b"K"
            if command == b"S":
                for emulator in emulators:
                    emulator.step()
            elif command[:1] == b"R":
                for emulator in emulators:
                    emulator.start_episode(reset_seed(command))
            elif command == b"P":
                reply += pickle.dumps([emulator.snapshot() for emulator in emulators])
            elif command[:1] == b"L":
                with open(os.fsdecode(command[1:]), "rb") as file:
                    states = pickle.load(file)
                for emulator, snap in zip(emulators, states, strict=True):
                    emulator.restore(snap)
            elif command == b"C":
                conn.send_bytes(b"K")
                return
            else:
                raise RuntimeError(f"unknown command {command[:1]!r}")
            conn.send_bytes(reply)
        except (BrokenPipeError, EOFError):
            return
        except BaseException:
            try:
                conn.send_bytes(b"E" + traceback.format_exc().encode())
            finally:
                return
