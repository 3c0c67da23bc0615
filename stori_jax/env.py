"""The batched environment :class:`Env` (made by ``stori_jax.make``, see builder.py).

Its lifecycle is one :class:`Phase`; every public call begins in :meth:`Env._call`, which
refuses a call the phase does not allow (one table of messages, :data:`REFUSED`) and a call
while another thread's call of the same env runs.  The emulators sit behind the backend
protocol (``stori_jax.backends.protocol.Backend``); the JAX side is the pure ``before_step`` /
``finish_step`` of ``stori_jax.core``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import enum
import os
import threading
import time

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np

from stori_jax.backends.interrupts import (interrupts_deferred, note_lost_interrupts,
                                           raise_lost_interrupt)
from stori_jax.backends.layout import RAM_SIZE, SCREEN
from stori_jax.backends.protocol import Backend
from stori_jax.backends.subproc import MAX_TIMEOUT_S
from stori_jax.checks import MAX_SEED, check_actions, check_int, check_real, shown
from stori_jax.config import Config
from stori_jax.backends.layout import FINAL_OUTPUTS, FRAME_OUTPUTS, STEP_OUTPUTS
from stori_jax.core import (Draws, EnvState,
                            WorkerOutputs, before_step, ended, finish_step, initial_state)
from stori_jax.errors import (ConcurrentUseError, EnvClosedError, EnvStateError,
                              InterruptedStepError, WorkersLateError)
from stori_jax.functional.preprocess import ATARI84, DREAMER64, STACK
from stori_jax.games import get_game
from stori_jax.plan import Plan


class Phase(enum.Enum):
    """Where an env is in its lifecycle."""

    NEEDS_RESET = "needs reset"  # made, or a call was interrupted: reset() (or restore())
    READY = "ready"              # settled: step, send, xla, snapshot
    IN_FLIGHT = "in flight"      # send() started a step: recv() finishes it
    XLA_DRIVEN = "xla driven"    # stepped by env.xla()'s step function until reset()
    CLOSED = "closed"


_SETTLE = "reset() it, and recv() any step in flight, first"
_XLA = ("this env is stepped by the step function of env.xla(): keep using it, or call "
        "reset() to step the env from Python again")
_NEEDS_RESET = "(before the first step, and after an interrupted step or reset)"

# (call, phase) -> why the call is refused there; every other pair is allowed (close() always)
REFUSED = {
    ("send", Phase.NEEDS_RESET): f"call reset() first {_NEEDS_RESET}",
    ("send", Phase.IN_FLIGHT): "a step is already in flight: call recv() before send() again",
    ("send", Phase.XLA_DRIVEN): _XLA,
    ("step", Phase.NEEDS_RESET): f"call reset() first {_NEEDS_RESET}",
    ("step", Phase.IN_FLIGHT): ("a step is already in flight (send() started it): call recv() "
                                "to finish it before step()"),
    ("step", Phase.XLA_DRIVEN): _XLA,
    ("recv", Phase.READY): "nothing in flight: call send(actions) first",
    ("recv", Phase.NEEDS_RESET): f"nothing in flight, and the env needs reset() {_NEEDS_RESET}",
    ("recv", Phase.XLA_DRIVEN): _XLA,
    ("xla", Phase.XLA_DRIVEN): ("xla() was already called: keep stepping its latest handle, "
                                "or reset() the env first"),
    ("xla", Phase.NEEDS_RESET): f"xla() needs a settled env: {_SETTLE}",
    ("xla", Phase.IN_FLIGHT): f"xla() needs a settled env: {_SETTLE}",
    **{("snapshot", phase): (f"snapshot() needs a settled env: {_SETTLE} (an env stepped by "
                             "env.xla() needs reset())")
       for phase in (Phase.NEEDS_RESET, Phase.IN_FLIGHT, Phase.XLA_DRIVEN)},
}
_BUSY = ("the workers are still busy with a call that was interrupted: call reset(), which "
         "waits for them first")
_WAITS = ("reset", "restore")  # the calls that wait for the workers' replies themselves

NOT_COPIED = ("a stori_jax.Env owns its emulator worker processes and cannot be copied or "
              "pickled: env.snapshot() is picklable, and env.restore(snapshot) continues it in "
              "an env made with the same arguments")


def jit_key(plan: Plan) -> Plan:
    """``plan`` without the structure only the workers use (event rules, RAM-obs modes), so
    configs that differ only there share one compilation of the JAX side (numbers are traced:
    see stori_jax.plan)."""
    if plan.event is not None:
        plan = dataclasses.replace(plan, event=dataclasses.replace(plan.event, mode=0,
                                                                   ram_event=None))
    if plan.mask is not None and plan.mask.kind == "ram":
        plan = dataclasses.replace(plan, mask=dataclasses.replace(plan.mask, mode=0))
    return plan


def observation_space(plan: Plan) -> gym.spaces.Box:
    if plan.obs == "objects":  # per env: (rows, 5) int32, x, y, w, h, present (docs/objects.md)
        from stori_jax.objects import num_object_rows

        bounds = np.iinfo(np.int32)
        return gym.spaces.Box(bounds.min, bounds.max,
                              (plan.num_envs, num_object_rows(plan.game), 5), np.int32)
    shape = {"raw": SCREEN, "atari84": (ATARI84, ATARI84, STACK),
             "dreamer64": (DREAMER64, DREAMER64, 3), "ram": (RAM_SIZE,)}[plan.obs]
    return gym.spaces.Box(0, 255, (plan.num_envs,) + shape, np.uint8)


class Env:
    """A batch of B STORI environments; outputs are jax arrays with a leading batch axis.

    ``step(actions)`` = ``send(actions)`` + ``recv()``: between the two the emulators run, so an
    agent can compute meanwhile.  One call at a time: a call from a second thread while one
    runs raises :class:`stori_jax.errors.ConcurrentUseError` (``close()`` excepted).
    """

    def __init__(self, plan: Plan, config: Config, seed: int, backend: Backend):
        self.plan = plan
        self.config = config
        self.seed = seed
        self.game = get_game(plan.game)
        self.backend = backend
        self.num_envs = plan.num_envs
        self.num_actions = plan.num_actions
        self.action_space = gym.spaces.MultiDiscrete(np.full(plan.num_envs, plan.num_actions))
        self.observation_space = observation_space(plan)
        self.single_action_space = gym.spaces.Discrete(plan.num_actions)
        self.single_observation_space = gym.spaces.Box(0, 255, self.observation_space.shape[1:],
                                                       np.uint8)
        self._owner_pid = os.getpid()  # the workers (or envpool's threads) answer this process
        note_lost_interrupts()
        self._lock = threading.RLock()  # one call at a time (re-entrant: step = send + recv)
        self._running = None  # the public call under way
        self._phase = Phase.NEEDS_RESET
        self._jit_plan = jit_key(plan)
        self._zero_draws = None
        # nothing random happens before the emulators run: skip the JAX call of send()
        self._deterministic_before_step = (
            plan.noise is None and plan.event is None and plan.mask is None
            and plan.drift_schedule is None and plan.noop_max == 0)
        self._state = initial_state(plan, seed)
        self._episode_end_compiled = False  # see _compile_episode_end
        self._in_flight = None  # (state, draws, resets) of the step IN_FLIGHT
        self._restart_due = False  # reset(seed=...) asked, and no reset has completed since
        self._reset_pending = np.zeros(plan.num_envs, bool)  # envs to reset on the next step
        # stepping through env.xla(): the current chain of handles and its steps so far
        self._xla_epoch, self._xla_steps = 0, 0
        self._xla_key = None   # the key after the last step through xla(), for a later reset
        self._xla_step = None  # the jitted step, made once per env

    @property
    def phase(self) -> Phase:
        """The env's lifecycle phase (CLOSED once the backend is, e.g. by a worker's death)."""
        return Phase.CLOSED if self.backend.closed else self._phase

    @property
    def closed(self) -> bool:
        return self.backend.closed

    # -- the guard every call passes ---------------------------------------------------------

    @contextlib.contextmanager
    def _call(self, name: str):
        """Run the body of the public call ``name``: one thread at a time, and only where the
        phase allows it (:data:`REFUSED`)."""
        got = outer = False
        try:
            with interrupts_deferred():  # a Ctrl-C never leaves the lock taken
                got = self._lock.acquire(blocking=False)
                if got:
                    outer, self._running = self._running, self._running or name
            if not got:
                raise ConcurrentUseError(
                    f"{name}() was called while another thread's call of this env "
                    f"({self._running}()) runs: an env serves one call at a time; give each "
                    "thread its own env, or serialise the calls (e.g. with a threading.Lock)")
            self._check_open()
            if self._phase is Phase.READY and self.backend.pending and name not in _WAITS:
                # an interrupted call (a snapshot, say) left the workers owing a reply
                self._phase = Phase.NEEDS_RESET
                raise EnvStateError(_BUSY)
            refused = REFUSED.get((name, self._phase))
            if refused is not None:
                raise EnvStateError(refused)
            yield
        finally:
            if got:
                self._running = outer
                self._lock.release()

    def _check_open(self) -> None:
        if self._made_elsewhere():
            raise RuntimeError(
                f"this env was made in process {self._owner_pid}, and this process "
                f"({os.getpid()}) was forked from it: its workers answer that process only. "
                "Make an env in this process (started with the 'spawn' method)")
        if self.closed:
            raise EnvClosedError("this environment is closed; make a new one with stori_jax.make")
        if self._phase is Phase.IN_FLIGHT and not self.backend.pending:
            # the backend handed the step's outputs over, and this env never recorded them (a
            # Ctrl-C landed between the two): the emulators are ahead of this env's state
            self._in_flight, self._phase = None, Phase.NEEDS_RESET
        raise_lost_interrupt()  # a Ctrl-C Python dropped since: nothing has started yet

    def _made_elsewhere(self, getpid=os.getpid) -> bool:  # bound here: __del__ at exit
        return getattr(self, "_owner_pid", None) not in (None, getpid())

    # -- lifecycle ------------------------------------------------------------------------------

    def close(self) -> None:
        """Stop the workers (any thread may call it, also while a call runs; idempotent).  In
        a process forked from the one that made the env, only this process's handles close."""
        if self._phase is Phase.XLA_DRIVEN and not self.closed and not self._made_elsewhere():
            jax.effects_barrier()  # xla steps still queued finish first
        self.backend.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        if getattr(self, "backend", None) is not None:
            self.backend.close()

    def __copy__(self):
        raise TypeError(NOT_COPIED)

    def __deepcopy__(self, memo):
        raise TypeError(NOT_COPIED)

    def __reduce__(self):
        raise TypeError(NOT_COPIED)

    # -- reset ----------------------------------------------------------------------------------

    def reset(self, seed: int | None = None, timeout: float | None = None):
        """Reset every env.

        Args:
            seed: restart the whole run from this seed (emulators and key), as
                ``make(..., seed=seed)`` then ``reset()`` would, in the same worker processes;
                ``env.seed`` becomes it.  None: the next episodes of this run.
            timeout: seconds of waiting for the workers at most (a step in flight is finished
                first); past it ``TimeoutError`` names the late workers and the env needs
                ``reset()`` again (which waits for this one first).

        Returns:
            (obs, info)
        """
        with self._call("reset"):
            if seed is not None:
                seed = check_int("seed", seed, 0, MAX_SEED)
            deadline = self._deadline(timeout, "reset")
            late = ("the env needs reset(): call it again (it waits for this one first), or "
                    "close() it")
            self._settle_xla()
            # until this reset has finished, an interruption (Ctrl-C, a timeout) leaves an env
            # that needs one
            self._phase = Phase.NEEDS_RESET
            if seed is not None:  # until a reset completes, every reset restarts from it
                self.seed, self._restart_due = seed, True
            if self._in_flight is not None or self.backend.pending:
                # finish a step (or an interrupted reset) still in flight; a step interrupted
                # inside emulation needs nothing more: the reset below starts every emulator
                with contextlib.suppress(InterruptedStepError):
                    self._wait(deadline, timeout, late)
                self._in_flight = None
            if self._restart_due:
                self._state = initial_state(self.plan, self.seed)
            zeros = jnp.zeros((self.num_envs,), jnp.int32)
            state = self._state._replace(episode_step=zeros, prev_executed=zeros)
            state, draws = before_step(self._jit_plan, state, zeros, resetting=True)
            self._write_inputs(draws, reset_first=None)
            self.backend.send_reset(self.seed if self._restart_due else None)
            out = self._wait(deadline, timeout, late)
            everyone = np.ones(self.num_envs, bool)
            self._state, (obs, _, _, _, info), _ = self._finish(state, draws, out, everyone)
            self._compile_episode_end(self._state, out)
            # the record last, one fact per statement: a Ctrl-C between them leaves an env that
            # still needs reset(), never one that steps with an earlier step's resets due
            self._reset_pending[:] = False
            self._restart_due = False
            self._phase = Phase.READY
            return obs, info

    def _deadline(self, timeout, call: str) -> float | None:
        """When a wait bounded by ``timeout`` seconds from now ends (None: no bound); checked
        before anything is sent, so a refused timeout changes nothing."""
        if timeout is None:
            return None
        try:
            timeout = check_real("timeout", timeout, 0, MAX_TIMEOUT_S)
        except ValueError as error:
            raise ValueError(f"{error} (seconds; None waits as long as it takes)") from None
        if not self.backend.can_time_out:
            raise ValueError(f"{call}(timeout=...) needs backend='subproc': "
                             f"{type(self.backend).__name__} cannot bound its wait")
        return time.monotonic() + timeout

    def _wait(self, deadline: float | None, timeout, late: str):
        """The backend's recv, bounded by ``deadline``; late workers: TimeoutError ending in
        the caller's advice ``late``."""
        if deadline is None:
            return self.backend.recv()
        try:
            return self.backend.recv(timeout=max(0.0, deadline - time.monotonic()))
        except WorkersLateError as e:
            raise TimeoutError(f"{e} within {float(timeout):g} s; {late}") from None

    # -- stepping -------------------------------------------------------------------------------

    def validate_actions(self, actions) -> np.ndarray:
        """Host-side check: shape (B,), integer dtype, values in [0, num_actions)."""
        return check_actions(actions, self.num_envs, self.num_actions)

    def send(self, actions) -> None:
        """Start one step of every env with ``actions``, (B,) ints in [0, num_actions)."""
        with self._call("send"):
            a = self.validate_actions(actions)
            if self._deterministic_before_step:
                state, draws = self._state, self._host_draws(a)
            else:
                state, draws = before_step(self._jit_plan, self._state, a)
            self._write_inputs(draws, reset_first=self._reset_pending)
            with interrupts_deferred():  # the workers have the step, and this env knows it
                self.backend.send_step()
                self._in_flight = (state, draws, self._reset_pending.copy())
                self._phase = Phase.IN_FLIGHT

    def recv(self, timeout: float | None = None):
        """Finish the step started by :meth:`send`.

        Args:
            timeout: seconds of waiting for the worker processes at most (the envs emulated
                in this process are not bounded by it); past it ``TimeoutError`` names the
                late workers, and the step stays in flight for a later ``recv()``.  Only the
                ``subproc`` backend honours it.

        Returns:
            (obs, reward, terminated, truncated, info)
        """
        with self._call("recv"):
            deadline = self._deadline(timeout, "recv")
            state, draws, was_reset = self._in_flight
            late = "it is still in flight: call recv() again to keep waiting, or close() the env"
            try:
                state, result, pending = self._finish(state, draws,
                                                      self._wait(deadline, timeout, late),
                                                      was_reset)
            except BaseException:
                # interrupted (Ctrl-C) or timed out while waiting for the workers: the step
                # stays in flight and the next recv() resumes it.  Interrupted inside this
                # process's emulation, or after the emulators finished: they are ahead of the
                # env's state, and only reset() continues.
                if not self.backend.pending or self.backend.half_stepped:
                    self._in_flight, self._phase = None, Phase.NEEDS_RESET
                raise
            self._state = state
            self._reset_pending = pending  # before the step leaves the record (see above)
            self._in_flight = None
            self._phase = Phase.READY
            return result

    def step(self, actions, timeout: float | None = None):
        """One agent step of every env: (obs, reward, terminated, truncated, info).
        ``timeout`` bounds the wait for the workers as in :meth:`recv`."""
        with self._call("step"):
            self._deadline(timeout, "step")  # a timeout the backend cannot honour: unsent
            self.send(actions)
            return self.recv(timeout)

    # -- stepping inside jax.jit ---------------------------------------------------------------

    def xla(self):
        """``(handle, step)``: stepping inside ``jax.jit``, as envpool's xla handle.

        ``step(handle, actions) -> (handle, (obs, reward, terminated, truncated, info))`` is
        pure and jittable (also inside ``jax.lax.scan``; not ``vmap``), and gives exactly what
        :meth:`step` gives.  Each handle steps once: pass on the one the step returns.  Until
        ``reset()`` the env is stepped only through ``step``; a reset makes every handle stale
        (``xla()`` again; nothing recompiles).  Keep the env referenced while you step it.
        Details: docs/semantics.md."""
        from stori_jax import xla

        with self._call("xla"):
            self._xla_epoch = xla.new_epoch()
            self._xla_steps = 0
            self._phase = Phase.XLA_DRIVEN
            if self._xla_step is None:
                self._xla_step = xla.make_step(self._jit_plan, self._xla_emulate)
            # the handle gets copies: a caller's jit may donate it, and the env's own state must
            # survive that (reset() starts from it)
            state = jax.tree.map(jnp.copy, self._state)
            return (xla.initial_handle(state, self._reset_pending, self._xla_epoch),
                    self._xla_step)

    def _settle_xla(self) -> None:
        """Stop stepping through xla(): wait for xla steps still queued (asynchronous dispatch),
        make every handle stale, and go on with the key where the last xla step left it, as if
        the env had been stepped from Python."""
        if self._xla_step is not None:
            jax.effects_barrier()
        self._xla_epoch = 0
        if self._xla_key is not None:
            self._state = self._state._replace(key=jnp.asarray(self._xla_key))
            self._xla_key = None

    def _xla_emulate(self, *args):
        """The host callback of env.xla()'s step (its errors marked: the JaxRuntimeError that
        carries them is the report).  Runs in JAX's callback thread, outside :meth:`_call`."""
        from stori_jax.xla import marked

        try:
            return self._xla_emulate_step(*args)
        except BaseException as error:
            raise marked(error)

    def _xla_emulate_step(self, epoch, steps, key, actions, executed, event_u, event_active,
                          ram_render, noops, reset_first):
        """Run the emulators for one step of env.xla(); return copies of their outputs (the
        buffers are reused by the next step).  No JAX computation in here: this runs inside a
        callback (device_get of numpy arrays only passes them through)."""
        self._check_open()
        if int(epoch) != self._xla_epoch or self._phase is not Phase.XLA_DRIVEN:
            raise RuntimeError("stale xla handle: it comes from an earlier xla() of this env "
                               "(before a reset or restore) or from another env; step the "
                               "latest handle of this env's xla(), or reset() and call xla()")
        if int(steps) != self._xla_steps:
            raise RuntimeError(f"stale xla handle: it follows {int(steps)} steps, the env has "
                               f"taken {self._xla_steps}; step the handle the last step returned "
                               "(a handle steps once: the emulators cannot be rewound), or "
                               "reset()")
        self.validate_actions(actions)
        draws = Draws(executed=executed, event_u=event_u, event_active=event_active,
                      ram_render=ram_render, noops=noops, executed_slots=None, corrupted=None,
                      concept=None, mask_apply=None, mask_centres=None, step_active=None)
        try:
            self._write_inputs(draws, reset_first=reset_first)
            self.backend.send_step()
            out = self.backend.recv()
            names = STEP_OUTPUTS + (FINAL_OUTPUTS if self.plan.autoreset else ())
            result = WorkerOutputs(**{
                name: np.array(out[name]) if name not in FRAME_OUTPUTS or self.plan.screens
                else np.zeros((0,), np.uint8) for name in names})
        except BaseException:
            # the emulators may be ahead of the JAX side: only reset() continues
            self._phase = Phase.NEEDS_RESET
            raise
        self._xla_steps += 1
        self._xla_key = np.array(key)
        return result

    # -- snapshots ------------------------------------------------------------------------------

    def snapshot(self) -> dict:
        """Everything needed to continue this env bit for bit later: the emulators (ALE state
        with its RNG, STORI bookkeeping) and the JAX-side state.  Picklable; take it between
        steps.  :meth:`restore` it into an env made with the same arguments.

        Raises:
            ValueError: the backend cannot snapshot (envpool)."""
        with self._call("snapshot"):
            if not self.backend.can_snapshot:
                raise ValueError(f"backend {type(self.backend).__name__} cannot snapshot its "
                                 "emulators; use backend='subproc'")
            try:
                emulators = self.backend.snapshot()
            except BaseException:
                if self.backend.pending:  # interrupted while the workers copy
                    self._phase = Phase.NEEDS_RESET
                raise
            return dict(plan=self.plan, seed=self.seed, state=jax.device_get(self._state),
                        reset_pending=self._reset_pending.copy(), emulators=emulators)

    def restore(self, snapshot: dict) -> None:
        """Continue from ``snapshot`` (taken by :meth:`snapshot` of an env made alike; its seed
        may differ: the emulators and the key come from the snapshot, and so does ``seed``).

        Raises:
            ValueError: the snapshot is of another kind of env, or the backend cannot restore."""
        with self._call("restore"):
            if not self.backend.can_snapshot:  # first: no snapshot could ever fit
                raise ValueError(f"backend {type(self.backend).__name__} cannot restore "
                                 "emulators; use backend='subproc'")
            if not isinstance(snapshot, dict) or set(snapshot) != {
                    "plan", "seed", "state", "reset_pending", "emulators"}:
                raise ValueError("snapshot must be a dict returned by Env.snapshot()")
            differs = _differences(snapshot["plan"], self.plan)
            if not differs:  # an env alike: are the parts what its snapshot() gives?
                self._check_snapshot_parts(snapshot)
                differs = self.backend.restore_differences(snapshot["emulators"])
            if differs:
                raise ValueError("snapshot was taken of a different env (make this one with "
                                 "the same arguments): " + "; ".join(differs))
            self._settle_xla()
            self._phase = Phase.NEEDS_RESET  # until the emulators and the state are restored
            if self._in_flight is not None or self.backend.pending:
                with contextlib.suppress(InterruptedStepError):
                    self.backend.recv()
                self._in_flight = None
            self.backend.restore(snapshot["emulators"])
            self._state = EnvState(*jax.tree.map(jnp.asarray, tuple(snapshot["state"])))
            self.seed = snapshot["seed"]  # emulators and key are that seed's run now
            self._reset_pending = np.array(snapshot["reset_pending"], bool)
            self._restart_due = False
            self._phase = Phase.READY  # last: until here, an interruption needs a reset

    # -- internals ------------------------------------------------------------------------------

    def _check_snapshot_parts(self, snapshot: dict) -> None:
        """Refuse, before anything changes, a snapshot whose parts are not what
        :meth:`snapshot` gives for an env of this size (an edited or damaged one)."""
        check_int("snapshot['seed']", snapshot["seed"], 0, MAX_SEED)
        emulators = snapshot["emulators"]
        if not isinstance(emulators, (list, tuple)) or not all(
                isinstance(e, dict) for e in emulators):
            raise ValueError("snapshot['emulators'] must be the list of emulator states "
                             f"Env.snapshot() gives, got {type(emulators).__name__}")
        pending = snapshot["reset_pending"]
        if getattr(pending, "dtype", None) != np.bool_ or np.shape(pending) != (self.num_envs,):
            raise ValueError(f"snapshot['reset_pending'] must be a bool array of shape "
                             f"({self.num_envs},), got {shown(pending)}")
        state = snapshot["state"]
        expected = [(name, np.shape(x), jnp.result_type(x))
                    for name, x in zip(EnvState._fields, self._state)]
        if not isinstance(state, tuple) or len(state) != len(expected) or any(
                np.shape(x) != shape or getattr(x, "dtype", None) != dtype
                for x, (_, shape, dtype) in zip(state, expected)):
            raise ValueError("snapshot['state'] must be the EnvState Env.snapshot() gives for "
                             "this env: " + ", ".join(f"{name} {dtype}{list(shape)}"
                                                      for name, shape, dtype in expected))

    def _host_draws(self, actions: np.ndarray) -> Draws:
        """The Draws of a step without randomness, built on the host (numpy)."""
        b, skip = self.num_envs, self.plan.frame_skip
        if self._zero_draws is None:
            self._zero_draws = Draws(
                executed=None, executed_slots=None, corrupted=np.zeros((b, 1), bool),
                event_u=np.ones((b, skip, 2), np.float32), event_active=np.zeros(b, np.uint8),
                ram_render=np.zeros(b, np.uint8), noops=np.zeros(b, np.int32),
                concept=np.zeros(b, np.int32), mask_apply=np.zeros((b, 2), bool),
                mask_centres=np.zeros((b, 2, 2), np.int32), step_active=np.zeros(b, bool))
        slots = actions[:, None]
        if self.plan.per_frame:
            slots = np.repeat(slots, skip, axis=1)
        return self._zero_draws._replace(
            executed=np.repeat(actions[:, None], skip, axis=1), executed_slots=slots,
            corrupted=np.zeros(slots.shape, bool))

    def _write_inputs(self, draws, reset_first) -> None:
        """The workers' inputs of one step (or reset) from its Draws (jax or numpy arrays)."""
        views = self.backend.views
        host = jax.device_get((draws.executed, draws.event_u, draws.event_active,
                               draws.ram_render, draws.noops))
        (views["executed"][...], views["event_u"][...], views["event_active"][...],
         views["ram_render"][...], views["noops"][...]) = host
        views["reset_first"][...] = 0 if reset_first is None else reset_first

    def _compile_episode_end(self, state, out) -> None:
        """Compile, once, the step that ends an episode (it hands over the ended episodes' last
        screens too: another compilation), so that no step compiles, where a Ctrl-C would
        most likely land.  The result is thrown away: nothing changes."""
        if not self.plan.autoreset or self._episode_end_compiled:
            return
        zeros = np.zeros(self.num_envs, np.int32)
        if self._deterministic_before_step:
            draws = self._host_draws(zeros)
        else:
            _, draws = before_step(self._jit_plan, state, zeros)
        outputs = WorkerOutputs(**{name: out[name] for name in STEP_OUTPUTS + FINAL_OUTPUTS})
        jax.block_until_ready(finish_step(self._jit_plan, state, draws, outputs,
                                          np.zeros(self.num_envs, bool)))
        self._episode_end_compiled = True

    def _finish(self, state, draws, out, reset_first):
        """(state, (obs, reward, terminated, truncated, info), envs due for a reset) of the
        workers' outputs ``out`` for the whole batch (read before this returns: the workers
        overwrite their buffers on the next send)."""
        state, result, pending = finish_step(self._jit_plan, state, draws,
                                             self._worker_outputs(out), reset_first)
        jax.block_until_ready(result)
        return state, result, pending

    def _worker_outputs(self, out) -> WorkerOutputs:
        """The backend's outputs (numpy views), the final_* ones only where an episode ended
        (the step compiled without them elsewhere)."""
        outputs = WorkerOutputs(**{name: out[name] for name in STEP_OUTPUTS})
        if self.plan.autoreset and ended(outputs).any():  # the ended episodes' last observations
            outputs = outputs._replace(**{name: out[name] for name in FINAL_OUTPUTS})
        return outputs

    def __repr__(self):
        return (f"Env({self.plan.game}, {self.config.describe()}, num_envs={self.num_envs}, "
                f"obs={self.plan.obs!r}, granularity={self.config.granularity!r})")


def _differences(snapshot_plan, plan: Plan) -> list[str]:
    """The fields in which two plans differ, as 'name A there, B here'."""
    if not isinstance(snapshot_plan, Plan):
        return [f"plan {snapshot_plan!r} there"]
    return [f"{f.name} {getattr(snapshot_plan, f.name)!r} there, {getattr(plan, f.name)!r} here"
            for f in dataclasses.fields(Plan)
            if getattr(snapshot_plan, f.name) != getattr(plan, f.name)]
