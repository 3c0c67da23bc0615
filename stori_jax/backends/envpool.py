"""The ``envpool`` backend: STORI on envpool's Atari environments, the fastest path for configs
that need no RAM writes and no per-frame actions.

envpool runs its own C++ thread pool and emulator build and does the frame skip itself (raw RGB
210x160, one frame per stack, the last two screens max-pooled by envpool).  Supported:

- type 1 (uniform or sticky) at ``step`` granularity, 3.1, 3.2 crop and blackout at ``step``
  granularity, 2.2 drift over those, and type 0 (the RAM comes in envpool's info);
- autoreset on the NEXT step (envpool's own): pass ``autoreset=False`` to ``stori_jax.make``.

Anything else (2.1 events and RAM-obs modes write the RAM; ``frame`` granularity needs an action
or a mask per emulator frame) raises ValueError naming what needs the ``subproc`` backend.
Same seed -> same run on this backend too, but envpool ships its own emulator build and seeds it
its own way, so runs are not bit-identical to the ``subproc`` backend.  envpool seeds env i with
``base + i``; the base is hashed from the seed (:func:`envpool_seed`), so that runs of
consecutive seeds share no env's emulator stream (with ``base = seed``, env i + 1 of seed s was
env i of seed s + 1).

An episode that ends before a step's last two frames: envpool stops its frame loop before
taking the screens, so the final observation (``autoreset=False``) repeats the step before's;
the ``subproc`` backend shows the episode's last frame.  Nor does envpool say which frame
ended it: ``info['frames_played']`` is frame_skip for every stepped env.

Episode ends: ``max_episode_frames`` becomes envpool's step cap (frames / frame skip, rounded up),
which does not count the reset's no-op frames as ALE's frame cap on ``subproc`` does (with
``noop_max`` > 0 a truncation can come up to about noop_max / frame_skip + 1 steps later here).
A game that ends on the step that reaches the cap is ``terminated`` and ``truncated``, as on
``subproc``.

No-op starts: envpool plays at least one NOOP frame at every reset (its ``noop_max=N`` draws
1..N frames), so this backend passes ``noop_max + 1`` and an episode starts after 1..noop_max+1
NOOP frames (one frame later than on ``subproc``, which plays 0..noop_max; the same number of
possible starts).  With the default ``noop_max=0`` every episode starts one frame in.
"""

from __future__ import annotations

import os

import numpy as np

from stori_jax.backends.interrupts import interrupts_deferred
from stori_jax.backends.layout import SCREEN, buffer_specs
from stori_jax.errors import EnvClosedError

FRAMES_LAYOUT = "pooled_chw"  # (B, 3, 210, 160): envpool's max-pooled screen, channels first
MIN_ENVPOOL_MAJOR = 1  # pyproject's envpool>=1.0: older ones have no info['ram']
MAX_BASE_SEED = 2**30 - 1  # envpool's int32 seed: base + i stays below 2**31 for B < 2**30


def envpool_seed(seed: int) -> int:
    """envpool's seed (the base it adds env i to) for a stori_jax ``seed``: a hash of it."""
    return int(np.random.SeedSequence([seed, 0xE27]).generate_state(1)[0]) & MAX_BASE_SEED


def unsupported_reasons(plan) -> list[str]:
    """Every reason why ``plan`` needs the subproc backend (none: envpool can run it)."""
    reasons = []
    if plan.event is not None:
        reasons.append("2.1 random events write the RAM between frames")
    if plan.mask is not None and plan.mask.kind == "ram":
        reasons.append("RAM observation modes render frames from a modified RAM")
    if plan.mask is not None and plan.mask.kind == "objects":
        reasons.append("hidden objects need the RAM of each of a step's last two frames")
    if plan.per_frame and plan.noise is not None:
        reasons.append("type 1 at 'frame' granularity needs an action per emulator frame "
                       "(use granularity='step')")
    if plan.per_frame and plan.mask is not None and plan.mask.kind != "ram":
        reasons.append("masks at 'frame' granularity need each emulator frame "
                       "(use granularity='step')")
    if plan.autoreset:
        reasons.append("envpool autoresets on the next step: pass autoreset=False")
    return reasons


def make_envpool_backend(plan, seed: int, max_episode_frames: int) -> "EnvpoolBackend":
    reasons = unsupported_reasons(plan)
    if reasons:
        raise ValueError(f"backend='envpool' cannot run this config: {'; '.join(reasons)}; "
                         "use backend='subproc' (the default), which supports every mode")
    return EnvpoolBackend(plan, seed, max_episode_frames)


class EnvpoolBackend:
    """Adapts an envpool gymnasium-style pool to the backend protocol of ``stori_jax.Env``
    (:class:`stori_jax.backends.protocol.Backend`)."""

    name = "envpool"
    frames_layout = FRAMES_LAYOUT
    can_time_out = False  # the pool's wait is C++: it cannot be bounded
    can_snapshot = False  # envpool cannot clone its emulators' states
    half_stepped = False  # a step is never interrupted half way (Ctrl-C waits for the pool)

    def __init__(self, plan, seed: int, max_episode_frames: int):
        try:
            import envpool
        except ImportError as e:
            raise ValueError("backend='envpool' needs the envpool package: "
                             "pip install 'stori-jax[envpool]'") from e
        found = envpool.__version__
        if int(found.split(".")[0]) < MIN_ENVPOOL_MAJOR:
            raise ValueError(f"backend='envpool' needs envpool>={MIN_ENVPOOL_MAJOR}.0 (its info "
                             f"has the RAM from 1.0 on), found envpool {found}: "
                             "pip install 'stori-jax[envpool]'")
        from stori_jax.games import get_game

        game = get_game(plan.game)
        task = "".join(part.capitalize() for part in game.rom_id.split("_")) + "-v5"
        if task not in envpool.list_all_envs():
            raise ValueError(f"envpool has no Atari task {task!r} for game {plan.game!r}; "
                             "use backend='subproc' (the default), which runs every ale-py game")
        b = plan.num_envs
        self._make_pool = lambda seed: envpool.make(
            task, env_type="gymnasium", num_envs=b, batch_size=b, seed=envpool_seed(seed),
            num_threads=0, img_height=SCREEN[0], img_width=SCREEN[1], gray_scale=False,
            stack_num=1, frame_skip=plan.frame_skip, noop_max=plan.noop_max + 1,
            episodic_life=False, reward_clip=False, repeat_action_probability=0.0,
            use_fire_reset=False, full_action_space=False,
            # as on subproc: the episode ends at the step that reaches max_episode_frames
            max_episode_steps=-(-max_episode_frames // plan.frame_skip))
        self.pool = self._make_pool(seed)
        self.num_envs = b
        self._frame_skip = plan.frame_skip
        # the subproc backend's buffers, but one max-pooled screen per env, channels first
        self.views = {name: np.zeros(shape, dtype) for name, (shape, dtype) in
                      buffer_specs(b, plan.frame_skip, frames_layout="pooled_chw").items()}
        self._running_return = np.zeros(b, np.float64)
        self._running_length = np.zeros(b, np.int64)
        self._pending = None  # the command the pool has and whose result is not yet taken
        self._closed = False
        self._owner_pid = os.getpid()  # the pool's threads serve this process only

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def pending(self) -> bool:
        """A command was sent and its result not yet taken."""
        return self._pending is not None

    def _check(self):
        if self._closed:
            raise EnvClosedError("this environment is closed; make a new one with stori_jax.make")

    def _check_idle(self):
        self._check()
        if self._pending is not None:
            raise RuntimeError("a command is in flight: call recv() before sending again")

    # Each command is sent, and each result taken, with Ctrl-C held over the call and its
    # record (stori_jax.backends.interrupts): the pool's wait is C++ and cannot be interrupted
    # anyway, and a KeyboardInterrupt between a call and its record left a reset queued behind
    # the env's back (its next reset drove the emulators twice at once: a segfault) or a
    # result taken but not recorded (every later step one command behind).

    def send_reset(self, seed: int | None = None) -> None:
        """Reset every env; with ``seed``, on a new pool of that seed (envpool cannot reseed
        one: a pool of the same seed starts its emulators alike)."""
        self._check_idle()
        with interrupts_deferred():
            if seed is not None:
                pool, self.pool = self.pool, self._make_pool(seed)
                pool.close()
            self.pool.async_reset()
            self._pending = "reset"

    def send_step(self) -> None:
        self._check_idle()
        actions = self.views["executed"][:, 0].astype(np.int32)
        with interrupts_deferred():
            self.pool.send(actions)
            self._pending = "step"

    def outputs(self) -> dict:
        return self.views

    def recv(self, timeout: float | None = None) -> dict:
        self._check()
        if self._pending is None:
            raise RuntimeError("nothing in flight: call send_step() or send_reset() first")
        with interrupts_deferred():
            return self._take(self._pending)

    def _take(self, command: str) -> dict:
        """The pool's result of ``command``, in the views."""
        v = self.views
        if command == "reset":
            obs, info = self.pool.recv(reset=True, return_info=True)
            reward = np.zeros(self.num_envs, np.float32)
            terminated = truncated = np.zeros(self.num_envs, bool)
            reset_step = np.ones(self.num_envs, bool)
        else:
            obs, reward, _, truncated, info = self.pool.recv()
            # envpool's own terminated is "done and not truncated": a game over on the step that
            # reaches the cap would read as a truncation only.  Its info has ALE's game over.
            terminated = np.asarray(info["terminated"], bool)
            reset_step = v["reset_first"].astype(bool)  # envpool resets these itself
        self._pending = None
        v["frames"][...] = obs
        v["ram"][...] = info["ram"]
        v["lives"][...] = info["lives"]
        v["reward"][...] = reward
        v["terminated"][...] = terminated
        v["truncated"][...] = truncated
        # envpool does not say on which frame of the step an episode ended: every frame of a
        # stepped env counts as played
        v["frames_played"][...] = np.where(reset_step, 0, self._frame_skip)
        self._running_return = np.where(reset_step, 0.0, self._running_return + reward)
        self._running_length = np.where(reset_step, 0, self._running_length + 1)
        done = np.asarray(terminated) | np.asarray(truncated)
        v["episode_return"][...] = np.where(done, self._running_return, 0.0)
        v["episode_length"][...] = np.where(done, self._running_length, 0)
        return v

    def snapshot(self) -> list[dict]:
        raise ValueError("backend EnvpoolBackend cannot snapshot its emulators; use "
                         "backend='subproc'")

    def restore_differences(self, states: list[dict]) -> list[str]:
        raise ValueError("backend EnvpoolBackend cannot restore emulators; use "
                         "backend='subproc'")

    restore = restore_differences

    def close(self) -> None:
        """Close the pool; in a process forked from its owner, leave it to the owner (its
        threads are the owner's)."""
        if not self._closed:
            self._closed = True
            if os.getpid() == self._owner_pid:
                self.pool.close()
