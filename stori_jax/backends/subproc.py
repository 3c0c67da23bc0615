"""The ``subproc`` backend: W worker processes, each stepping its share of the B ALE emulators
(``inline_envs`` of them are stepped in the parent process itself while the workers run).

Frames, RAM and flags travel through shared memory (no pickling); a one-byte Pipe message is the
signal in each direction.  A worker that dies is noticed through its process sentinel, so the
parent raises :class:`WorkerError` instead of hanging.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import pickle
import shutil
import sys
import tempfile
import threading
import time
import weakref
from multiprocessing.connection import wait

import numpy as np

from stori_jax.backends.interrupts import interrupts_deferred
from stori_jax.backends.layout import SharedBuffers
from stori_jax.backends.emulator import EmulatorSpec
from stori_jax.backends.worker import reset_command, reset_seed, worker_main
from stori_jax.errors import (EnvClosedError, InterruptedStepError, WorkerError,  # noqa: F401
                              WorkersLateError)
from stori_jax.pixels import OBSERVATION_LAYOUTS


# recv(timeout=...) at most: the workers' pipes are waited on in int32 milliseconds (2^31 ms is
# 24.8 days), so a longer finite wait cannot be honoured; None waits as long as it takes
MAX_TIMEOUT_S = 1_000_000


def split_batch(num_envs: int, num_workers: int) -> list[tuple[int, int]]:
    """Contiguous [lo, hi) env ranges, as even as possible (none for no workers)."""
    if num_workers == 0:
        return []
    base, extra = divmod(num_envs, num_workers)
    bounds, lo = [], 0
    for w in range(num_workers):
        hi = lo + base + (1 if w < extra else 0)
        bounds.append((lo, hi))
        lo = hi
    return bounds


def assign_envs(num_envs: int, num_workers: int,
                inline_envs: int) -> tuple[tuple[int, ...], list[tuple[int, ...]]]:
    """Which process emulates which env: (the calling process's envs, each worker's): envs
    0..inline_envs-1 here, then each worker a contiguous range, as even as possible."""
    workers = [tuple(range(inline_envs + lo, inline_envs + hi))
               for lo, hi in split_batch(num_envs - inline_envs, num_workers)]
    return tuple(range(inline_envs)), workers


def describe_envs(envs) -> str:
    """'3..5, 9..9' for the env indices (3, 4, 5, 9)."""
    runs, out = sorted(envs), []
    start = prev = None
    for i in runs + [None]:
        if i is not None and prev is not None and i == prev + 1:
            prev = i
            continue
        if start is not None:
            out.append(f"{start}..{prev}")
        start = prev = i
    return ", ".join(out)


_MAIN_MODULE_HIDDEN = threading.RLock()  # one thread at a time hides and restores it


@contextlib.contextmanager
def _main_module_not_reimported():
    """Spawned workers need nothing from ``__main__``; hide its path while starting them so
    that a user's unguarded script (no ``if __name__ == "__main__"``) is not re-run in them.
    Envs made in two threads at once take turns: otherwise the second saved the first's
    ``None`` and put it back for good (the user's own spawned processes then failed)."""
    with _MAIN_MODULE_HIDDEN:
        main = sys.modules.get("__main__")
        saved = {k: getattr(main, k) for k in ("__file__", "__spec__") if hasattr(main, k)}
        try:
            for k in saved:
                if k == "__file__":
                    delattr(main, k)
                else:
                    setattr(main, k, None)
            yield
        finally:
            for k, v in saved.items():
                setattr(main, k, v)


def _remove_folders(folders: list) -> None:
    while folders:
        shutil.rmtree(folders.pop(), ignore_errors=True)


STOP_WAIT_S = 1.0  # how long close() waits for the workers to stop, then to be terminated


def _shutdown(processes, conns, owner_pid: int, scratch: list, inline: list) -> None:
    """Stop every worker: ask politely, then terminate, then kill; give this process's
    emulators (``inline``) back for reuse.  In a process forked from the owner, the workers
    are the owner's: only this process's copies of the pipes close.
    A Ctrl-C meanwhile is raised once they are gone (each stage waits at most STOP_WAIT_S for
    all of them together, so about 3 s at most): the finalizer runs once, so one interrupted
    here left a worker that no later close() stopped."""
    with interrupts_deferred():
        while inline:
            inline.pop().release()
        _stop_workers(processes, conns, owner_pid, scratch)


def _stop_workers(processes, conns, owner_pid: int, scratch: list) -> None:
    if os.getpid() != owner_pid:
        for conn in conns:
            with contextlib.suppress(OSError):
                conn.close()
        return
    for conn in conns:
        try:
            conn.send_bytes(b"C")
        except (OSError, ValueError):
            pass
    for stop in (None, "terminate", "kill"):  # asked to close (above), then forced
        alive = [p for p in processes if p.is_alive()]
        for p in alive if stop else ():
            getattr(p, stop)()
        deadline = time.monotonic() + STOP_WAIT_S  # one wait for them all, not one each
        for p in alive:
            p.join(timeout=max(0.0, deadline - time.monotonic()))
    for conn in conns:
        try:
            conn.close()
        except OSError:
            pass
    _remove_folders(scratch)


_LIVE_BACKENDS: "weakref.WeakSet[SubprocBackend]" = weakref.WeakSet()


def _disown_inherited_workers() -> None:
    """In a child forked from a process with live envs: the workers are the parent's.  Drop
    them from multiprocessing's list of this process's children, whose exit handler would
    otherwise terminate them (and fail to join them) when the child exits."""
    children = getattr(mp.process, "_children", None)
    if children is None:  # another multiprocessing layout: nothing to drop
        return
    for backend in list(_LIVE_BACKENDS):
        for p in backend.processes:
            children.discard(p)


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_disown_inherited_workers)


class SubprocBackend:
    """Owns the worker processes and the shared buffers of one batched env
    (:class:`stori_jax.backends.protocol.Backend`)."""

    name = "subproc"
    can_time_out = True  # recv(timeout) bounds the wait for the workers
    can_snapshot = True

    frames_layout = "pair"  # or "pooled", "atari84", "dreamer64" (set in __init__)

    def __init__(self, *, game: str, seeds: list[int], num_workers: int, frame_skip: int,
                 per_frame: bool, event_mode: int | None, event_prob: float,
                 ram_obs_mode: int | None, want_screens: bool, max_episode_frames: int,
                 autoreset: bool = True, frames_layout: str = "pair", inline_envs: int = 0,
                 want_screen_ram: bool = False, ram_event: tuple | None = None):
        num_envs = len(seeds)
        if num_workers and mp.current_process().daemon:  # Python forbids it: say what works
            raise RuntimeError(
                f"stori_jax.make cannot start its {num_workers} emulator worker process(es) "
                "inside a daemonic process (gymnasium's make_vec(..., "
                "vectorization_mode='async'), a DataLoader worker, SubprocVecEnv): leave "
                "num_workers None or set it to 0 to emulate every env in this process, or make "
                "the batch in the main process (gymnasium.make_vec(id, num_envs=N) in its default "
                "mode, or stori_jax.make(..., num_envs=N))")
        if num_workers == 0 and inline_envs != num_envs:
            raise ValueError(f"num_workers=0 needs inline_envs = num_envs ({num_envs}), "
                             f"got {inline_envs}")
        self.frames_layout = frames_layout
        self.max_episode_frames = max_episode_frames
        ctx = mp.get_context("spawn")
        # a pooled screen is written into slot 0 of the pair (outputs() hands that slot over)
        shared = frames_layout if frames_layout in OBSERVATION_LAYOUTS else "pair"
        self.buffers = SharedBuffers.allocate(ctx, num_envs, frame_skip, want_screens,
                                              final=autoreset, frames_layout=shared)
        self.views = self.buffers.views()
        if num_workers and not 0 <= inline_envs < num_envs:
            raise ValueError(f"inline_envs must be in [0, num_envs - 1], got {inline_envs}")
        inline, self.worker_envs = assign_envs(num_envs, num_workers, inline_envs)
        self.processes, self.conns = [], []
        self.owner_pid = os.getpid()
        self._scratch = []  # folders of restore files the workers are still to read
        self._inline = []  # the emulators of the calling process's envs
        self._finalizer = weakref.finalize(self, _shutdown, self.processes, self.conns,
                                           self.owner_pid, self._scratch, self._inline)
        _LIVE_BACKENDS.add(self)

        def spec_for(envs):
            return EmulatorSpec(game=game, envs=tuple(envs), seeds=tuple(seeds[i] for i in envs),
                              frame_skip=frame_skip, per_frame=per_frame, event_mode=event_mode,
                              event_prob=event_prob, ram_obs_mode=ram_obs_mode,
                              want_screens=want_screens, max_episode_frames=max_episode_frames,
                              autoreset=autoreset, frames_layout=frames_layout,
                              want_screen_ram=want_screen_ram, ram_event=ram_event)

        # the calling process emulates its envs while the workers run theirs
        if inline:
            from stori_jax.backends.emulator import make_emulators

            self._inline.extend(make_emulators(spec_for(inline), self.views))
        self._inline_command, self._inline_next, self._inline_broken = None, 0, None
        for envs in self.worker_envs:
            parent_conn, child_conn = ctx.Pipe(duplex=True)
            process = ctx.Process(target=worker_main, daemon=True,
                                  args=(spec_for(envs), self.buffers, child_conn, os.getpid()),
                                  name=f"stori-jax-worker-{len(self.processes)}")
            with _main_module_not_reimported():
                process.start()
            child_conn.close()
            self.processes.append(process)
            self.conns.append(parent_conn)
        self._rounds = 0  # replies each worker still owes for the command in flight
        self._what = "start"
        self._waiting = None
        try:
            self._rounds = 1
            self._wait_all("start")
        except BaseException:
            self.close()
            raise

    @property
    def closed(self) -> bool:
        return not self._finalizer.alive

    @property
    def pending(self) -> bool:
        """A command was sent and its replies are not all in (e.g. its wait was interrupted)."""
        return self._rounds > 0

    @property
    def half_stepped(self) -> bool:
        """A step was interrupted inside an emulator of this process: whatever the workers
        still owe, only a reset continues (their replies are awaited by it)."""
        return self._inline_broken is not None

    def _send_all(self, message: bytes) -> None:
        """Send every worker ``message``: one reply each."""
        self._send_each([message] * len(self.conns))

    def _send_each(self, messages: list[bytes]) -> None:
        """Send each worker its message: one reply each."""
        if self.closed:
            raise EnvClosedError("this environment is closed; make a new one with stori_jax.make")
        if self._rounds:
            raise RuntimeError("a step is already in flight: call recv() before sending again")
        with interrupts_deferred():  # every worker gets the command, and the record says so
            for w, (conn, message) in enumerate(zip(self.conns, messages, strict=True)):
                try:
                    conn.send_bytes(message)
                except (OSError, ValueError):
                    self._raise_dead(w, "while sending a command")
            self._rounds = 1

    def _envs_of(self, w: int) -> str:
        return f"envs {describe_envs(self.worker_envs[w])}"

    def _raise_dead(self, w: int, when: str):
        if self.closed:  # close() from another thread stopped the workers this one waits for
            raise EnvClosedError(f"the environment was closed {when} (by close(), from another "
                                 "thread or a signal handler); make a new one with "
                                 "stori_jax.make")
        p = self.processes[w]
        p.join(timeout=0.5)
        self.close()
        raise WorkerError(f"emulator worker {w} ({self._envs_of(w)}, pid {p.pid}) died {when} "
                          f"with exit code {p.exitcode}; the environment is closed")

    def _wait_all(self, what: str, timeout: float | None = None) -> dict[int, bytes]:
        """One round of replies: one from every worker."""
        # The workers still to reply live on self: if the wait is interrupted (Ctrl-C) or times
        # out, the command stays pending and the next recv() resumes it, instead of a later
        # command taking this one's replies (and the workers' half-written buffers) for its own.
        if self._waiting is None:
            self._waiting, self._replies = dict(enumerate(self.conns)), {}
        waiting = self._waiting
        deadline = None if timeout is None else time.monotonic() + timeout
        try:
            while waiting:
                # only the workers still to reply: a finished worker that dies meanwhile is
                # reported by the next command, instead of waking this loop over and over
                sentinels = {self.processes[w].sentinel: w for w in waiting}
                left = None if deadline is None else max(0.0, deadline - time.monotonic())
                ready = wait(list(waiting.values()) + list(sentinels), timeout=left)
                if not ready:
                    late = sorted(waiting)
                    raise WorkersLateError(what, late, [self.processes[w].pid for w in late])
                with interrupts_deferred():  # a reply read off its pipe is recorded
                    for obj in ready:
                        self._take_reply(obj, waiting, sentinels, what)
        except BaseException:
            if self.closed:  # a worker died or failed (or close() from another thread)
                self._waiting, self._rounds = None, 0
            raise
        with interrupts_deferred():
            self._waiting = None
            self._rounds -= 1
        if not self._rounds:
            _remove_folders(self._scratch)
        return self._replies

    def _take_reply(self, obj, waiting: dict, sentinels: dict, what: str) -> None:
        """Record the reply (or the death) of the worker whose pipe or sentinel ``obj`` is."""
        if obj in sentinels:
            w = sentinels[obj]
            try:
                replied = w in waiting and waiting[w].poll()
            except OSError:  # its pipe closed under this wait: close() from another thread
                replied = False
            if w in waiting and not replied:
                self._raise_dead(w, f"during {what}")
            return
        w = next(k for k, c in waiting.items() if c is obj)
        try:
            reply = obj.recv_bytes()
        except (EOFError, OSError):
            self._raise_dead(w, f"during {what}")
        if reply[:1] == b"E":
            self.close()
            raise WorkerError(f"emulator worker {w} ({self._envs_of(w)}) failed "
                              f"during {what}:\n{reply[1:].decode(errors='replace')}")
        self._replies[w] = reply[1:]
        del waiting[w]

    # -- the backend protocol ---------------------------------------------------------------

    def send_reset(self, seed: int | None = None) -> None:
        """Reset every emulator; with ``seed``, first restart each from that batch seed, as a
        new backend of it would start (the processes stay)."""
        command = reset_command(seed)
        with interrupts_deferred():
            self._send_all(command)
            self._inline_command = command
            self._what = "a reset"

    def send_step(self) -> None:
        """Step every emulator: the workers start at once, this process's envs in recv()."""
        with interrupts_deferred():
            self._send_all(b"S")
            self._inline_command = b"S"
            self._what = "a step"

    def recv(self, timeout: float | None = None) -> dict[str, np.ndarray]:
        """Finish the command in flight: emulate this process's envs, then wait for the
        workers' (at most ``timeout`` seconds, then :class:`WorkersLateError` with the command
        still pending: a later recv() resumes it).  The outputs stay valid until the next send."""
        if self.closed:
            raise EnvClosedError("this environment is closed; make a new one with stori_jax.make")
        if not self._rounds:
            raise RuntimeError("nothing in flight: call send_step() or send_reset() first")
        command = self._inline_command
        if command is not None and self._inline_broken is None:
            # one emulator at a time, so that an interrupted recv() resumes where it stopped
            while self._inline_next < len(self._inline):
                emulator = self._inline[self._inline_next]
                try:
                    if command == b"S":
                        emulator.step()
                    else:
                        emulator.start_episode(reset_seed(command))
                except BaseException:
                    # stopped inside an emulator's frame loop: its state is half a step
                    self._inline_broken = emulator.i
                    raise
                self._inline_next += 1
        self._wait_all(self._what, timeout)
        self._inline_next, self._inline_command = 0, None
        if self._inline_broken is not None:
            env, self._inline_broken = self._inline_broken, None
            raise InterruptedStepError(
                f"a step was interrupted while env {env} was being emulated in this process; "
                "its emulator is half a step ahead: call reset() before stepping again")
        return self.outputs()

    def outputs(self) -> dict[str, np.ndarray]:
        """The outputs of the last command, as the env reads them."""
        if self.frames_layout == "pooled":  # contiguous (B, H, W, 3)
            return dict(self.views, **{name: self.views[name][0] for name in
                                       ("frames", "final_frames") if name in self.views})
        return self.views

    def snapshot(self) -> list[dict]:
        """Every emulator's state (picklable), in env order; nothing may be in flight."""
        self._send_all(b"P")
        self._what = "a snapshot"
        states = {emulator.i: emulator.snapshot() for emulator in self._inline}
        replies = self._wait_all("a snapshot")
        for w in range(len(self.conns)):
            states.update(zip(self.worker_envs[w], pickle.loads(replies[w]), strict=True))
        return [states[i] for i in range(len(states))]

    def restore_differences(self, states: list[dict]) -> list[str]:
        """How the emulators of ``states`` differ from this backend's in what a restore cannot
        change ('name A there, B here'): their number and the episode frame limit (an ALE
        setting, not part of the state; snapshots of versions before it was recorded skip it)."""
        here = len(self._inline) + sum(len(envs) for envs in self.worker_envs)
        if len(states) != here:
            return [f"emulators {len(states)} there, {here} here"]
        limits = {s.get("max_episode_frames", self.max_episode_frames) for s in states}
        return [f"max_episode_frames {limit} there, {self.max_episode_frames} here"
                for limit in sorted(limits - {self.max_episode_frames})]

    def restore(self, states: list[dict]) -> None:
        """Put every emulator back in a state taken by :meth:`snapshot` of a like backend."""
        differs = self.restore_differences(states)
        if differs:
            raise ValueError("snapshot was taken of different emulators: " + "; ".join(differs))
        # the states go through files: a command of a few bytes is sent at once, where a
        # pickle larger than the pipe's buffer would block Ctrl-C until the worker reads it
        folder = tempfile.mkdtemp(prefix="stori-jax-restore-")
        self._scratch.append(folder)  # removed when the workers have read it (or at close)
        commands = []
        for w, envs in enumerate(self.worker_envs):
            path = os.path.join(folder, f"worker-{w}.pkl")
            with open(path, "wb") as file:
                pickle.dump([states[i] for i in envs], file)
            commands.append(b"L" + os.fsencode(path))
        self._send_each(commands)
        self._what = "a restore"
        for emulator in self._inline:
            emulator.restore(states[emulator.i])
        self._wait_all("a restore")

    def close(self) -> None:
        self._finalizer()

    @property
    def pids(self) -> list[int]:
        return [p.pid for p in self.processes]
