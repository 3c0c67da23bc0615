"""Shared helpers of the tests/test_env_*.py files: black-box runs of ``stori_jax.make`` on real
emulators, recorded as numpy arrays."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field

import jax
import numpy as np

import stori_jax
from ale_py import ALEInterface, LoggerMode, roms

# Breakout's minimal action set and the RAM addresses a ball-tracking policy needs
NOOP, FIRE, RIGHT, LEFT = 0, 1, 2, 3
BALL_X, BALL_Y, PADDLE_X = 99, 101, 72


def make(game, config=None, **kw):
    """``stori_jax.make`` with small defaults: 2 envs, seed 0, RAM observations, every env
    emulated in this process (``num_workers=0``: no worker to start; a test of the workers
    asks for them)."""
    kw.setdefault("num_envs", 2)
    kw.setdefault("seed", 0)
    kw.setdefault("num_workers", 0)
    kw.setdefault("obs", "ram")
    return stori_jax.make(game, config=config, **kw)


def to_numpy(tree):
    return jax.tree.map(lambda x: np.asarray(x).copy(), tree)


@dataclass
class Run:
    """A recorded run: the reset's (obs, info), then per step (stacked on axis 0) the actions
    sent, obs, reward, terminated, truncated and info."""

    reset_obs: np.ndarray
    reset_info: dict
    actions: list = field(default_factory=list)
    obs: list = field(default_factory=list)
    reward: list = field(default_factory=list)
    terminated: list = field(default_factory=list)
    truncated: list = field(default_factory=list)
    info: list = field(default_factory=list)

    def record(self, actions, out):
        obs, reward, terminated, truncated, info = to_numpy(out)
        self.actions.append(np.asarray(actions).copy())
        self.obs.append(obs)
        self.reward.append(reward)
        self.terminated.append(terminated)
        self.truncated.append(truncated)
        self.info.append(info)

    def stacked(self, name):
        """Per-step array (T, B, ...) of ``obs``/``reward``/... or of an info key."""
        if name in ("actions", "obs", "reward", "terminated", "truncated"):
            return np.stack(getattr(self, name))
        return np.stack([i[name] for i in self.info])

    @property
    def ram(self):
        """(T + 1, B, 128): the RAM after the reset, then after every step."""
        return np.concatenate([self.reset_info["ram"][None], self.stacked("ram")])

    @property
    def done(self):
        return self.stacked("terminated") | self.stacked("truncated")


def run_lockstep(envs, num_steps, policy, reset_seed=None):
    """Reset every env of ``envs`` (``reset(seed=reset_seed)``) and step them together with the
    same actions.

    ``policy(k, runs)`` returns the actions of step k (it may read the runs so far).
    Returns one :class:`Run` per env."""
    runs = []
    for env in envs:
        obs, info = env.reset(seed=reset_seed)
        runs.append(Run(*to_numpy((obs, info))))
    for k in range(num_steps):
        actions = np.asarray(policy(k, runs), np.int32)
        for env, run in zip(envs, runs):
            run.record(actions, env.step(actions))
    return runs


def lockstep_with_twin(game, config, num_steps, policy, **kw):
    """(run of ``config``, run of its 3.1 twin), stepped with the same actions."""
    run_config, twin = make(game, config, **kw), make(game, **kw)
    try:
        return tuple(run_lockstep([run_config, twin], num_steps, policy))
    finally:
        run_config.close()
        twin.close()


def run_env(env, actions, reset_seed=None):
    """Reset ``env`` (``reset(seed=reset_seed)``) and step it through ``actions`` (T, B)."""
    return run_lockstep([env], len(actions), lambda k, runs: actions[k], reset_seed)[0]


def emulator_states(env) -> list[bytes]:
    """Every emulator's whole ALE state, its random number generator included (a settled env)."""
    return [emulator["ale"] for emulator in env.snapshot()["emulators"]]


def random_actions(num_actions, num_steps, num_envs, seed=0):
    return np.random.default_rng(seed).integers(0, num_actions, (num_steps, num_envs),
                                                dtype=np.int32)


def breakout_tracker(ram, offset=8):
    """Follow the ball with the paddle (RAM 72 vs 99); FIRE to launch when no ball is in play."""
    ram = np.asarray(ram).astype(np.int32)
    ball_x, ball_y, paddle = ram[:, BALL_X], ram[:, BALL_Y], ram[:, PADDLE_X] + offset
    action = np.where(paddle < ball_x - 2, RIGHT, np.where(paddle > ball_x + 2, LEFT, NOOP))
    return np.where(ball_y == 0, FIRE, action).astype(np.int32)


def last_ram(run):
    return run.info[-1]["ram"] if run.info else run.reset_info["ram"]


def binomial_ok(count, n, p, sigmas=5.0):
    """``count`` successes of ``n`` trials is within ``sigmas`` standard deviations of n*p."""
    sd = max((n * p * (1 - p)) ** 0.5, 1e-9)
    return abs(count - n * p) <= sigmas * sd


def process_gone(pid: int) -> bool:
    """The process no longer runs: no /proc entry, or a zombie waiting to be reaped."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("State:"):
                    return "Z" in line.split()[1]
    except (FileNotFoundError, ProcessLookupError):
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    return False


def wait_gone(pids, timeout=5.0) -> bool:
    """Every process of ``pids`` is gone within ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if all(process_gone(pid) for pid in pids):
            return True
        time.sleep(0.05)
    return all(process_gone(pid) for pid in pids)


def new_ale(rom_id: str, seed: int = 0) -> ALEInterface:
    """A bare ale-py emulator of ``rom_id`` (no sticky actions), for tests on real frames/RAM."""
    ALEInterface.setLoggerMode(LoggerMode.Error)
    ale = ALEInterface()
    ale.setInt("random_seed", seed)
    ale.setFloat("repeat_action_probability", 0.0)
    ale.loadROM(roms.get_rom_path(rom_id))
    return ale
