"""The batched environment: ``stori_jax.make`` and :class:`Env`."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import os
import time

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np

from stori_jax.backends.interrupts import (interrupts_deferred, note_lost_interrupts,
                                           raise_lost_interrupt)
from stori_jax.backends.layout import RAM_SIZE, SCREEN, shared_bytes
from stori_jax.backends.subproc import (MAX_TIMEOUT_S, EnvClosedError, InterruptedStepError,
                                        SubprocBackend, WorkersLate)
from stori_jax.backends.worker import emulator_seed
from stori_jax.checks import (MAX_INT32, MAX_SEED, check_actions, check_int, check_real,
                              shown)
from stori_jax.config import Config, GRANULARITIES
from stori_jax.core import (FINAL_OUTPUTS, FRAME_OUTPUTS, STEP_OUTPUTS, Draws, EnvState,
                            WorkerOutputs, before_step, ended, finish_step, initial_state)
from stori_jax.fork_guard import refuse_if_forked_after_jax
from stori_jax.functional.preprocess import ATARI84, DREAMER64, STACK
from stori_jax.games import get_game
from stori_jax.plan import OBS_KINDS, Plan, compile_plan
from stori_jax.presets import preset as get_preset

BACKENDS = ("subproc", "envpool")


def emulator_seeds(seed: int, num_envs: int) -> list[int]:
    """ALE seeds of envs 0..B-1: a function of the seed and the env index alone."""
    return [emulator_seed(seed, i) for i in range(num_envs)]


def resolve_config(game: str, preset: str | None, config: Config | None) -> Config:
    if preset is not None and config is not None:
        raise ValueError("pass either preset or config, not both")
    if config is None:
        return get_preset(game, preset) if preset is not None else Config()
    if not isinstance(config, Config):
        raise ValueError(f"config must be a stori_jax.Config, got {type(config).__name__}")
    return config


FRAME_SKIP = 4  # make's default: emulator frames per agent step
MAX_EPISODE_FRAMES = 108_000  # make's default cap: 30 minutes of play at 60 frames a second


def make(game: str, preset: str | None = None, *, config: Config | None = None,
         num_envs: int, seed: int, backend: str = "subproc", num_workers: int | None = None,
         obs: str | None = None, frame_skip: int = FRAME_SKIP, granularity: str | None = None,
         max_episode_frames: int = MAX_EPISODE_FRAMES, noop_max: int = 0, autoreset: bool = True,
         inline_envs: int | None = None) -> "Env":
    """A batched STORI environment of ``num_envs`` emulators.

    ``preset``: a paper preset name of ``game`` (see ``stori_jax.list_presets()``), or ``config``:
    a :class:`stori_jax.Config`; neither means the default game (3.1).  ``obs``: ``raw``
    (210x160x3), ``atari84`` (84x84 gray, 4 stacked; the default), ``dreamer64`` (64x64 RGB), or
    ``ram`` (the 128 RAM bytes; the default and only choice for type 0).  ``granularity``
    overrides the config's (``frame``: perturbations per emulator frame, as the reference;
    ``step``: once per agent step).  With ``autoreset`` (default) an env whose episode ended
    returns the first observation of its next episode in the same step.

    ``num_workers`` emulator processes share the batch; ``inline_envs`` envs are emulated in
    this process itself while the workers run theirs.  By default (both None) there is one
    worker per core but one, and this process takes an equal share: every core emulates, and
    nothing waits on a process switch (see benchmarks/README.md).  ``num_workers=0`` starts no
    process and emulates every env here, one after another inside ``recv()``; it is the default
    inside a daemonic process (a DataLoader worker, gymnasium's async vector env), which may
    have no children.  The split changes the speed only: a seed gives the same run with any.
    """
    refuse_if_forked_after_jax("stori_jax.make")
    spec = get_game(game)
    cfg = resolve_config(game, preset, config)
    if cfg.game is not None and get_game(cfg.game) is not spec:
        raise ValueError(f"config is bound to game {cfg.game!r} but make() was asked for {game!r}")
    cfg.for_game(spec.name)  # the game's modes, the drift's secondary included, or a clear error
    if granularity is not None:
        if granularity not in GRANULARITIES:
            raise ValueError(f"granularity must be one of {list(GRANULARITIES)} or None, "
                             f"got {granularity!r}")
        drift = cfg.drift
        if drift is not None:  # the override covers concept 2 too: its field back to the default
            drift = dataclasses.replace(drift, secondary=drift.secondary.replace(
                granularity="frame"))
        cfg = cfg.replace(granularity=granularity, drift=drift)
    num_envs = check_int("num_envs", num_envs, 1)
    seed = check_int("seed", seed, 0, MAX_SEED)
    if not isinstance(autoreset, (bool, np.bool_)):
        raise ValueError(f"autoreset must be True or False, got {autoreset!r}")
    frame_skip = check_int("frame_skip", frame_skip, 1)
    max_episode_frames = check_int("max_episode_frames", max_episode_frames, 1, MAX_INT32)
    noop_max = check_int("noop_max", noop_max, 0, MAX_INT32 - 1)
    if obs is None:
        obs = "ram" if cfg.ram_observation else "atari84"
    if obs not in OBS_KINDS:
        raise ValueError(f"obs must be one of {list(OBS_KINDS)}, got {obs!r}")
    if backend == "subproc":
        check_memory(num_envs, frame_skip, screens=obs != "ram", final=bool(autoreset))
    elif backend == "envpool":  # its buffers hold a screen per env whatever obs is
        check_memory(num_envs, frame_skip, buffers="envpool's frame buffers")
    if cfg.ram_observation and obs != "ram":
        raise ValueError(f"type 0 (ram_observation) observes the RAM: obs must be 'ram', got {obs!r}")
    if obs == "ram" and any(name == "observation" for name, _, _ in cfg.components()):
        where = "Config.observation" if cfg.observation is not None \
            else "Config.drift.secondary.observation"
        raise ValueError(f"obs='ram' cannot show an observation mask (type 3.2, {where}); "
                         "use a screen obs")
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {list(BACKENDS)}, got {backend!r}")
    plan = compile_plan(cfg, spec, num_envs=num_envs, frame_skip=frame_skip, obs=obs,
                        noop_max=noop_max, autoreset=bool(autoreset))
    if backend == "envpool":
        for name, value in (("num_workers", num_workers), ("inline_envs", inline_envs)):
            if value is not None:
                raise ValueError(f"{name} applies to backend='subproc' only (envpool runs its "
                                 f"own threads); leave it None, got {value!r}")
        from envpool_bridge import FRAMES_LAYOUT, make_envpool_backend

        plan = dataclasses.replace(plan, frames_layout=FRAMES_LAYOUT)
        # raises a clear ValueError naming what needs the subproc backend
        return Env(plan, cfg, seed, make_envpool_backend(plan, seed, max_episode_frames))
    daemonic_default = num_workers is None and _in_daemonic_process()
    if daemonic_default:
        num_workers = 0  # it may start no processes: every env is emulated here
    if num_workers is not None:
        num_workers = check_int("num_workers", num_workers, 0)
    if num_workers == 0:
        if inline_envs is not None:
            inline_envs = check_int("inline_envs", inline_envs)  # True == 1, but is no count
        if inline_envs not in (None, num_envs):
            why = ("inside a daemonic process, which may start none, the default num_workers "
                   "is 0: it emulates" if daemonic_default else "num_workers=0 emulates")
            raise ValueError(f"{why} all num_envs ({num_envs}) envs in this process: leave "
                             f"inline_envs None or set it to {num_envs}, got {inline_envs!r}")
        inline_envs = num_envs
    elif inline_envs is not None:  # every worker needs at least one env
        inline_envs = check_int("inline_envs", inline_envs)
        if not 0 <= inline_envs < num_envs:
            raise ValueError(f"inline_envs must be in [0, num_envs - 1 = {num_envs - 1}] with "
                             "worker processes (each needs an env; num_workers=0 emulates all "
                             f"{num_envs} here), got {inline_envs}")
    if num_workers is None:
        num_workers, default_inline = default_split(num_envs, _available_cores())
        if inline_envs is None:
            inline_envs = default_inline
        else:  # the envs left to the workers bound how many there can be
            num_workers = min(num_workers, num_envs - inline_envs)
    inline_envs = inline_envs or 0
    if num_workers > num_envs:
        raise ValueError(f"num_workers must be <= num_envs ({num_envs}), got {num_workers}")
    if num_workers + inline_envs > num_envs:
        raise ValueError(f"num_workers ({num_workers}) + inline_envs ({inline_envs}) must be "
                         f"<= num_envs ({num_envs}): every worker needs at least one env")
    wants_screens = obs != "ram"
    pool_in_workers = wants_screens and not plan.needs_both_screens
    plan = dataclasses.replace(plan, frames_layout="pooled" if pool_in_workers else "pair")
    event, mask = plan.event, plan.mask
    worker_backend = SubprocBackend(
        game=spec.name, seeds=emulator_seeds(seed, num_envs), num_workers=num_workers,
        frame_skip=frame_skip, per_frame=plan.per_frame,
        event_mode=event.mode if event else None, event_prob=event.prob if event else 0.0,
        ram_obs_mode=mask.mode if mask is not None and mask.kind == "ram" else None,
        want_screens=wants_screens, max_episode_frames=max_episode_frames,
        autoreset=plan.autoreset, pool_screens=pool_in_workers,
        inline_envs=inline_envs)
    return Env(plan, cfg, seed, worker_backend)


def jit_key(plan: Plan) -> Plan:
    """``plan`` without the facts only the workers use (event mode and probability, RAM-obs
    mode), so configs that differ only there share one compilation of the JAX side."""
    if plan.event is not None:
        plan = dataclasses.replace(plan, event=dataclasses.replace(plan.event, mode=0, prob=0.0))
    if plan.mask is not None and plan.mask.kind == "ram":
        plan = dataclasses.replace(plan, mask=dataclasses.replace(plan.mask, mode=0))
    return plan


def _differences(snapshot_plan, plan: Plan) -> list[str]:
    """The fields in which two plans differ, as 'name A there, B here'."""
    if not isinstance(snapshot_plan, Plan):
        return [f"plan {snapshot_plan!r} there"]
    return [f"{f.name} {getattr(snapshot_plan, f.name)!r} there, {getattr(plan, f.name)!r} here"
            for f in dataclasses.fields(Plan)
            if getattr(snapshot_plan, f.name) != getattr(plan, f.name)]


def default_split(num_envs: int, cores: int) -> tuple[int, int]:
    """(worker processes, envs emulated in this process) for a batch on ``cores`` cores."""
    if cores < 2 or num_envs < 2:
        return 1, 0
    workers = min(cores - 1, num_envs - 1)
    return workers, num_envs // (workers + 1)


def check_memory(num_envs: int, frame_skip: int, screens: bool = True,
                 buffers: str = "shared buffers", flag: str | None = None,
                 final: bool = True) -> None:
    """Refuse a batch whose shared buffers alone would not fit in this machine's memory, before
    anything is allocated (a typo of num_envs would otherwise allocate for minutes, then fail
    deep inside multiprocessing, or in envpool's C++ as std::bad_alloc).  ``buffers`` names
    them in the error: envpool's are estimated by the subproc backend's, a lower bound.
    ``flag``: the command-line flag that set num_envs (the only size it offers to change).
    ``final`` (make's default, autoreset): the buffers of the ended episodes' screens too."""
    need = shared_bytes(num_envs, frame_skip, screens, final)
    try:
        have = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # not known here: nothing to compare with
        return
    if need > have:
        asked = f"{flag} {num_envs}" if flag else f"num_envs={num_envs}"
        raise ValueError(f"{asked} with frame_skip={frame_skip} needs "
                         f"{need / 2**30:.1f} GiB of {buffers} (about "
                         f"{shared_bytes(1, frame_skip, screens, final) / 2**10:.1f} KiB "
                         "per env), "
                         f"more than this machine's {have / 2**30:.1f} GiB: choose a smaller "
                         + (flag or "num_envs or frame_skip"))


def _in_daemonic_process() -> bool:
    import multiprocessing

    return multiprocessing.current_process().daemon


def _available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def observation_space(plan: Plan) -> gym.spaces.Box:
    shape = {"raw": SCREEN, "atari84": (ATARI84, ATARI84, STACK),
             "dreamer64": (DREAMER64, DREAMER64, 3), "ram": (RAM_SIZE,)}[plan.obs]
    return gym.spaces.Box(0, 255, (plan.num_envs,) + shape, np.uint8)


NOT_COPIED = ("a stori_jax.Env owns its emulator worker processes and cannot be copied or "
              "pickled: env.snapshot() is picklable, and env.restore(snapshot) continues it in "
              "an env made with the same arguments")


class Env:
    """A batch of B STORI environments. Outputs are jax arrays with a leading batch axis.

    ``step(actions)`` = ``send(actions)`` + ``recv()``: between the two the emulators run, so an
    agent can compute on the device meanwhile.
    """

    def __init__(self, plan: Plan, config: Config, seed: int, backend):
        self.plan = plan
        self.config = config
        self.seed = seed
        self._owner_pid = os.getpid()  # the workers (or envpool's threads) answer this process
        note_lost_interrupts()
        self.game = get_game(plan.game)
        self.backend = backend
        self.num_envs = plan.num_envs
        self.num_actions = plan.num_actions
        self.action_space = gym.spaces.MultiDiscrete(np.full(plan.num_envs, plan.num_actions))
        self.observation_space = observation_space(plan)
        self.single_action_space = gym.spaces.Discrete(plan.num_actions)
        self.single_observation_space = gym.spaces.Box(0, 255, self.observation_space.shape[1:],
                                                       np.uint8)
        self._jit_plan = jit_key(plan)
        self._zero_draws = None
        # nothing random happens before the emulators run: skip the JAX call of send()
        self._deterministic_before_step = (
            plan.noise is None and plan.event is None and plan.mask is None
            and plan.drift_schedule is None and plan.noop_max == 0)
        self._state = initial_state(plan, seed)
        self._in_flight = None
        self._needs_reset = True
        self._reseed_due = False  # reset(seed=...) asked, and no reset has completed since
        self._reset_pending = np.zeros(plan.num_envs, bool)
        # stepping through env.xla(): the current chain of handles and its steps so far
        self._xla_epoch, self._xla_steps, self._xla_driven = 0, 0, False
        self._xla_key = None   # the key after the last step through xla(), for a later reset
        self._xla_step = None  # the jitted step, made once per env

    # -- lifecycle ------------------------------------------------------------------------------

    def close(self) -> None:
        """Stop the workers.  In a process forked from the one that made the env, only this
        process's copy of the subproc backend's pipes closes (the workers, and envpool's
        threads, are the other process's)."""
        if self._xla_driven and not self.closed and not self._made_elsewhere():
            jax.effects_barrier()  # xla steps still queued finish first
        self._close_backend()

    def _close_backend(self) -> None:
        # a backend that knows its owner (subproc) closes only its own pipe ends elsewhere
        if not self._made_elsewhere() or hasattr(self.backend, "owner_pid"):
            self.backend.close()

    @property
    def closed(self) -> bool:
        return self.backend.closed

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        if getattr(self, "backend", None) is not None:
            self._close_backend()

    def __copy__(self):
        raise TypeError(NOT_COPIED)

    def __deepcopy__(self, memo):
        raise TypeError(NOT_COPIED)

    def __reduce__(self):
        raise TypeError(NOT_COPIED)

    def _made_elsewhere(self, getpid=os.getpid) -> bool:  # bound here: __del__ at exit
        return getattr(self, "_owner_pid", None) not in (None, getpid())

    def _check_open(self):
        """Where every call of the env begins."""
        if self._made_elsewhere():
            raise RuntimeError(
                f"this env was made in process {self._owner_pid}, and this process "
                f"({os.getpid()}) was forked from it: its workers answer that process only. "
                "Make an env in this process (started with the 'spawn' method)")
        if self.closed:
            raise EnvClosedError("this environment is closed; make a new one with stori_jax.make")
        self._drop_unrecorded_step()  # every call begins with a record that agrees
        raise_lost_interrupt()  # a Ctrl-C Python dropped since: nothing has started yet

    # -- reset ----------------------------------------------------------------------------------

    def reset(self, seed: int | None = None, timeout: float | None = None):
        """Reset every env. Returns (obs, info).

        ``seed``: restart the whole run from this seed (emulators and key), exactly as
        ``make(..., seed=seed)`` followed by ``reset()`` would, without starting new worker
        processes; ``env.seed`` becomes it.  None (the default) goes on with the current
        streams: the next episodes of this run.

        ``timeout``: at most this many seconds of waiting for the worker processes in all (a step
        still in flight is finished first), then ``TimeoutError`` naming the late workers; the env
        then needs ``reset()`` again, which first waits for the late reset (and restarts from
        the seed asked for, if the late one did).  As in :meth:`recv`."""
        self._check_open()
        if seed is not None:
            seed = check_int("seed", seed, 0, MAX_SEED)
        deadline = self._deadline(timeout, "reset")
        late = "the env needs reset(): call it again (it waits for this one first), or close() it"
        # until this reset has finished, an interruption (Ctrl-C, a timeout) leaves an env that
        # needs one
        self._needs_reset = True
        if seed is not None:  # until a reset completes, every reset restarts from it
            self.seed, self._reseed_due = seed, True
        self._settle_xla()
        if self._in_flight is not None or getattr(self.backend, "pending", False):
            # finish a step (or an interrupted reset) still in flight; a step interrupted inside
            # emulation needs nothing more: the reset below starts every emulator afresh
            with contextlib.suppress(InterruptedStepError):
                self._wait(deadline, timeout, late)
            self._in_flight = None
        if self._reseed_due:
            self._state = initial_state(self.plan, self.seed)
        zeros = jnp.zeros((self.num_envs,), jnp.int32)
        state = self._state._replace(episode_step=zeros, prev_executed=zeros)
        state, draws = before_step(self._jit_plan, state, zeros, resetting=True)
        self._write_inputs(draws, reset_first=None)
        self.backend.send_reset(self.seed if self._reseed_due else None)
        out = self._wait(deadline, timeout, late)
        everyone = np.ones(self.num_envs, bool)
        (obs, _, _, _, info), _ = self._finish(state, draws, out, everyone)
        # the record last, one fact per statement: a Ctrl-C between them leaves an env that
        # still needs reset(), never one that steps with an earlier step's resets due
        self._reset_pending[:] = False
        self._reseed_due = False
        self._needs_reset = False
        return obs, info

    def _refuse_if_xla_driven(self) -> None:
        if self._xla_driven:
            raise RuntimeError("this env is stepped by the step function of env.xla(): keep "
                               "using it, or call reset() to step the env from Python again")

    def _deadline(self, timeout, call: str) -> float | None:
        """When a wait bounded by ``timeout`` seconds from now ends (None: no bound); checked
        before anything is sent, so a refused timeout changes nothing."""
        if timeout is None:
            return None
        try:
            timeout = check_real("timeout", timeout, 0, MAX_TIMEOUT_S)
        except ValueError as error:
            raise ValueError(f"{error} (seconds; None waits as long as it takes)") from None
        if not getattr(self.backend, "RECV_TIMEOUT", False):
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
        except WorkersLate as e:
            raise TimeoutError(f"{e} within {float(timeout):g} s; {late}") from None

    def validate_actions(self, actions) -> np.ndarray:
        """Host-side check: shape (B,), integer dtype, values in [0, num_actions)."""
        return check_actions(actions, self.num_envs, self.num_actions)

    def send(self, actions) -> None:
        """Start one step of every env with ``actions`` (B,) ints."""
        self._check_open()
        if self._needs_reset:
            raise RuntimeError("call reset() first (before the first step, and after an "
                               "interrupted step or reset)")
        self._refuse_if_xla_driven()
        if self._in_flight is not None:
            raise RuntimeError("a step is already in flight: call recv() before send() again")
        self._refuse_if_workers_busy()
        a = self.validate_actions(actions)
        if self._deterministic_before_step:
            state, draws = self._state, self._host_draws(a)
        else:
            state, draws = before_step(self._jit_plan, self._state, a)
        self._write_inputs(draws, reset_first=self._reset_pending)
        with interrupts_deferred():  # the workers have the step, and this env knows it
            self.backend.send_step()
            self._in_flight = (state, draws, self._reset_pending.copy())

    def _drop_unrecorded_step(self) -> None:
        """A step in flight whose outputs the backend has handed over, though this env never
        recorded them (a Ctrl-C landed between the two): the emulators are ahead of this
        env's state, so it needs reset()."""
        if self._in_flight is not None and not getattr(self.backend, "pending", True):
            self._in_flight, self._needs_reset = None, True

    def _refuse_if_workers_busy(self) -> None:
        """This env has nothing in flight: neither may its workers.  An interrupted snapshot
        (or any call stopped while the workers owed a reply) leaves them busy; reset() waits
        for them."""
        if getattr(self.backend, "pending", False):
            self._needs_reset = True
            raise RuntimeError("the workers are still busy with a call that was interrupted: "
                               "call reset(), which waits for them first")

    def recv(self, timeout: float | None = None):
        """Finish the step started by :meth:`send`: (obs, reward, terminated, truncated, info).

        ``timeout``: at most this many seconds of waiting for the worker processes (the envs
        emulated in this process, ``inline_envs``, are not bounded by it), then ``TimeoutError``
        naming the late workers; the step stays in flight and a later ``recv()`` finishes it
        as if it had never stopped.  ``None`` (the default) waits as long as it takes; a worker
        that dies is reported either way.  Only the ``subproc`` backend can honour it, for at
        most ``MAX_TIMEOUT_S`` (a million seconds)."""
        self._check_open()
        deadline = self._deadline(timeout, "recv")
        if self._in_flight is None:
            self._refuse_if_xla_driven()
            if not self._needs_reset:
                self._refuse_if_workers_busy()
            if self._needs_reset:
                raise RuntimeError("nothing in flight, and the env needs reset() (before the "
                                   "first step, and after an interrupted step or reset)")
            raise RuntimeError("nothing in flight: call send(actions) first")
        state, draws, was_reset = self._in_flight
        try:
            out = self._wait(deadline, timeout, "it is still in flight: call recv() again to "
                                                "keep waiting, or close() the env")
            result, pending = self._finish(state, draws, out, was_reset)
        except BaseException:
            # interrupted (Ctrl-C) or timed out while waiting: the step stays in flight and the
            # next recv() resumes it.  Interrupted inside this process's emulation
            # (InterruptedStepError) or after the emulators finished: they are ahead of this
            # env's state, so it needs a reset rather than silently diverging.
            if not getattr(self.backend, "pending", False):
                self._in_flight, self._needs_reset = None, True
            raise
        self._reset_pending = pending  # before the step leaves the record (see above)
        self._in_flight = None
        return result

    def step(self, actions, timeout: float | None = None):
        """One agent step of every env: (obs, reward, terminated, truncated, info).
        ``timeout`` bounds the wait for the workers as in :meth:`recv`."""
        self._check_open()
        self._deadline(timeout, "step")  # a timeout the backend cannot honour: refused unsent
        self.send(actions)
        return self.recv(timeout)

    # -- stepping inside jax.jit ---------------------------------------------------------------

    def xla(self):
        """``(handle, step)``: stepping inside ``jax.jit``, as envpool's xla handle.

        ``step(handle, actions) -> (handle, (obs, reward, terminated, truncated, info))`` is a
        pure function (jitted inside; host actions, numpy or a list, are checked on the way in)
        that can sit inside the caller's ``jit`` and ``jax.lax.scan``
        (not ``vmap``: the batch is already the envs).  It gives exactly what :meth:`step`
        gives.  Each handle steps once: pass on the one the step returns.  Take it from a
        settled env (after ``reset()``, nothing in flight); from then on the env is stepped
        only through ``step``, until ``reset()``, which makes every handle stale (call
        ``xla()`` again for a new one; ``step`` is the same function, so nothing recompiles).
        The handle, like every observation, is the caller's own: a jit that donates it
        (``donate_argnums``) leaves the env's state intact.
        Errors in the emulators (a dead worker, an action out of range, a stale handle or one
        of another env) surface as a ``jax.errors.JaxRuntimeError`` whose last line is the
        error; on an accelerator, when the step's results are read (a handle of an env of
        another size or observation is refused sooner, with a ValueError while tracing).
        After an error inside a scan, no handle is current: ``reset()``.  ``step`` holds the
        env weakly (JAX's caches keep it forever): keep the env referenced while you step it,
        or its workers close."""
        from stori_jax import xla

        self._check_open()
        if self._xla_driven:
            raise RuntimeError("xla() was already called: keep stepping its latest handle, or "
                               "reset() the env first")
        if self._in_flight is None and not self._needs_reset:
            self._refuse_if_workers_busy()
        if self._in_flight is not None or self._needs_reset:
            raise RuntimeError("xla() needs a settled env: reset() it, and recv() any step in "
                               "flight, first")
        self._xla_epoch = xla.new_epoch()
        self._xla_steps, self._xla_driven = 0, True
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
        self._xla_driven = False
        if self._xla_key is not None:
            self._state = self._state._replace(key=jnp.asarray(self._xla_key))
            self._xla_key = None

    def _xla_emulate(self, *args):
        """The host callback of env.xla()'s step (its errors marked: the JaxRuntimeError that
        carries them is the report)."""
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
        if int(epoch) != self._xla_epoch or not self._xla_driven:
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
                name: np.array(out[name]) if name not in FRAME_OUTPUTS or self.plan.obs != "ram"
                else np.zeros((0,), np.uint8) for name in names})
        except BaseException:
            # the emulators may be ahead of the JAX side: only reset() continues
            self._xla_driven, self._needs_reset = False, True
            raise
        self._xla_steps += 1
        self._xla_key = np.array(key)
        return result

    # -- snapshots ------------------------------------------------------------------------------

    def snapshot(self) -> dict:
        """Everything needed to continue this env bit for bit later: the emulators (ALE state
        with its RNG, STORI bookkeeping) and the JAX-side state.  Picklable; take it between
        steps (nothing in flight).  Restore it with :meth:`restore` into an env made with the
        same arguments (e.g. after a restart, to resume training)."""
        self._check_open()
        if self._in_flight is not None or self._needs_reset or self._xla_driven:
            raise RuntimeError("snapshot() needs a settled env: reset() it, and recv() any step "
                               "in flight, first (an env stepped by env.xla() needs reset())")
        if not hasattr(self.backend, "snapshot"):
            raise ValueError(f"backend {type(self.backend).__name__} cannot snapshot its "
                             "emulators; use backend='subproc'")
        self._refuse_if_workers_busy()
        try:
            emulators = self.backend.snapshot()
        except BaseException:
            if getattr(self.backend, "pending", False):  # interrupted while the workers copy
                self._needs_reset = True
            raise
        return dict(plan=self.plan, seed=self.seed, state=jax.device_get(self._state),
                    reset_pending=self._reset_pending.copy(), emulators=emulators)

    def restore(self, snapshot: dict) -> None:
        """Continue from ``snapshot`` (taken by :meth:`snapshot` of an env made alike; its seed
        may differ: the emulators and the key come from the snapshot, and so does ``seed``)."""
        self._check_open()
        if not hasattr(self.backend, "restore"):  # first: no snapshot could ever fit
            raise ValueError(f"backend {type(self.backend).__name__} cannot restore emulators; "
                             "use backend='subproc'")
        if not isinstance(snapshot, dict) or set(snapshot) != {
                "plan", "seed", "state", "reset_pending", "emulators"}:
            raise ValueError("snapshot must be a dict returned by Env.snapshot()")
        differs = _differences(snapshot["plan"], self.plan)
        if not differs:  # an env alike: are the parts what its snapshot() gives?
            self._check_snapshot_parts(snapshot)
        if not differs and hasattr(self.backend, "restore_differences"):
            differs = self.backend.restore_differences(snapshot["emulators"])
        if differs:
            raise ValueError("snapshot was taken of a different env (make this one with the "
                             "same arguments): " + "; ".join(differs))
        self._needs_reset = True  # until the emulators and the state are both restored
        self._settle_xla()
        if self._in_flight is not None or getattr(self.backend, "pending", False):
            with contextlib.suppress(InterruptedStepError):
                self.backend.recv()
            self._in_flight = None
        self.backend.restore(snapshot["emulators"])
        self._state = EnvState(*jax.tree.map(jnp.asarray, tuple(snapshot["state"])))
        self.seed = snapshot["seed"]  # emulators and key are that seed's run now
        self._reset_pending = np.array(snapshot["reset_pending"], bool)
        self._reseed_due = False
        self._needs_reset = False  # last: until here, an interruption leaves it needing reset

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

    def _finish(self, state, draws, out, reset_first):
        """((obs, reward, terminated, truncated, info), envs due for a reset) of the workers'
        outputs ``out``; the env's state moves on."""
        outputs = WorkerOutputs(**{name: out[name] for name in STEP_OUTPUTS})
        if self.plan.autoreset and ended(outputs).any():  # the ended episodes' last observations
            outputs = outputs._replace(**{name: out[name] for name in FINAL_OUTPUTS})
        state, result, pending = finish_step(self._jit_plan, state, draws, outputs, reset_first)
        # the workers overwrite their buffers on the next send: finish reading them now
        jax.block_until_ready(result)
        self._state = state
        return result, pending

    def __repr__(self):
        return (f"Env({self.plan.game}, {self.config.describe()}, num_envs={self.num_envs}, "
                f"obs={self.plan.obs!r}, granularity={self.config.granularity!r})")
