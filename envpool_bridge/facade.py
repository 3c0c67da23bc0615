"""envpool's Python API over stori_jax: ``import envpool_bridge as envpool``, then a STORI task id.

    import envpool_bridge as envpool
    envs = envpool.make("Breakout-2.1-v5", env_type="gym", num_envs=8, episodic_life=True,
                        reward_clip=True, seed=1)
    handle, recv, send, step_env = envs.xla()
    obs = envs.reset()                                   # (8, 4, 84, 84) uint8, as envpool's
    handle, (obs, reward, done, info) = step_env(handle, actions)   # inside jit / lax.scan

Task ids: envpool's Atari ids (``Breakout-v5``, ``Pong-v5``: STORI's 3.1, the plain game) and a
STORI preset ``<Game>-<preset>-v5`` (``Breakout-2.1-v5``, ``Boxing-3.2C-v5``); ``config=`` takes a
:class:`stori_jax.Config` with a plain id.  The returned pool has envpool's surface: ``reset``,
``step``, ``async_reset``, ``send`` / ``recv``, ``xla()`` -> ``(handle, recv, send, step)``,
``action_space`` / ``observation_space`` (one env's, as envpool's), ``config``, and envpool's
info keys with envpool's meanings (``env_id``, ``lives``, ``reward`` unclipped, ``terminated``
the game's own end, ``elapsed_step``, and with ``env_type="gym"`` ``TimeLimit.truncated``),
beside STORI's own keys (``executed_action``, ``event_fired``, ``concept``, ``obs_masked``,
``ram``, ...).

``env_type="gym"`` is the gym API that envpool < 1.0 gave and CleanRL's and Cleanba's JAX
scripts were written for: ``reset()`` returns the observations alone (``gym_reset_return_info``
adds the info), ``step`` returns ``(obs, reward, done, info)``.  (envpool >= 1.0 gives the
gymnasium API for both names.)  ``env_type="gymnasium"``: ``reset()`` -> ``(obs, info)``,
``step`` -> ``(obs, reward, terminated, truncated, info)`` with envpool's
``terminated = done & ~truncated``.

Agent-side settings are computed here, on the host and inside ``xla()``'s step alike:
``episodic_life`` (done at a lost life while the game goes on; the game resets at its real
end only) and ``reward_clip`` (the reward's sign; ``info["reward"]`` keeps the game's).  What
differs from envpool, keyword by keyword, and what is refused: docs/drop-in.md and
:data:`DIFFERENCES`.
"""

from __future__ import annotations

import re
import warnings
import weakref
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from gymnasium import spaces as gym_spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from jax.experimental import io_callback

ENV_TYPES = ("gym", "gymnasium")
TASK_ID = re.compile(r"^(?P<game>[A-Za-z][A-Za-z0-9]*?)(?:-(?P<preset>[0-9][0-9A-Za-z.]*))?-v5$")

# envpool's Atari keywords and their defaults (envpool/atari/atari_env.h, registration), as this
# façade takes them; use_fire_reset defaults to False here (see DIFFERENCES)
ENVPOOL_DEFAULTS = dict(
    num_envs=1, batch_size=0, num_threads=0, max_num_players=1, thread_affinity_offset=-1,
    seed=42, gym_reset_return_info=False, max_episode_steps=27000, stack_num=4, frame_skip=4,
    noop_max=30, zero_discount_on_life_loss=False, episodic_life=False, reward_clip=False,
    use_fire_reset=False, img_height=84, img_width=84, full_action_space=False,
    repeat_action_probability=0.0, use_inter_area_resize=True, gray_scale=True, mode=-1,
    difficulty=-1)
# stori_jax's own keywords, passed to stori_jax.make
STORI_KEYWORDS = ("config", "granularity", "backend", "num_workers", "inline_envs")
# accepted at any value, with no effect on the run (performance knobs of envpool's thread pool)
NO_EFFECT = ("num_threads", "thread_affinity_offset")
# (height, width, gray_scale) -> stori_jax's observation, and the most frames it stacks
IMAGES = {(84, 84, True): ("atari84", 4), (64, 64, False): ("dreamer64", 1),
          (210, 160, False): ("raw", 1)}

DIFFERENCES = {
    "use_fire_reset": "defaults to False: a STORI episode starts as ale-py's does, without a "
                      "FIRE pressed for the agent; True is refused (the reset happens in the "
                      "emulator workers, whose no-op start cannot end on a FIRE frame)",
    "noop_max": "envpool plays 1..noop_max NOOP frames at a reset; here 0..noop_max-1 "
                "(stori_jax.make(noop_max=noop_max - 1): the same noop_max possible starts, "
                "each one frame earlier); noop_max=1 starts every episode alike",
    "max_episode_steps": "becomes stori_jax's frame cap max_episode_frames = max_episode_steps "
                         "x frame_skip, which counts the reset's no-op frames too",
    "episodic_life": "a lost life ends the agent's episode (done) and the game goes on with the "
                     "next step; envpool spends that next step on a reset (the action ignored, "
                     "NOOP frames and a FIRE, reward 0) and does not count it in elapsed_step",
    "repeat_action_probability": "ALE's sticky actions, done by STORI's type 1 "
                                 "ActionNoise(p, sticky=True) per emulator frame (from the "
                                 "seed's key, not ALE's RNG); refused with a preset that "
                                 "corrupts actions already",
    "observation": "the pixels are STORI's atari84 (ITU-R 601 luma of the max-pooled RGB "
                   "screen, exact area resize), not envpool's (ALE's grayscale palette, then "
                   "OpenCV): same shape and layout, not the same bytes",
    "num_threads / thread_affinity_offset": "accepted, no effect: stori_jax's worker processes "
                                            "(num_workers=, inline_envs=) emulate",
    "full_action_space": "stori_jax plays the game's minimal action set (envpool's default)",
    "zero_discount_on_life_loss": "it sets dm_env's discount only, and env_type='dm' is not "
                                  "offered",
    "use_inter_area_resize": "STORI's resize is an exact area average (OpenCV's INTER_AREA)",
    "batch_size": "0 or num_envs only: every recv() returns the whole batch, env_id in order",
    "reset(env_id=...)": "the whole batch only (stori_jax resets every env at once)",
    "reset(seed=k)": "restarts the run from seed k (envpool ignores it with a warning)",
    "async_reset()": "resets at once; the next recv() returns the reset, as envpool's",
    "xla()": "handle, recv, send, step as envpool's; recv does the step that send prepared; "
             "a reset() made after xla() steps makes that handle stale (call xla() again), "
             "except the first reset(), which shares the reset xla() made",
}


class FacadeHandle(NamedTuple):
    """The xla handle (a pytree): stori_jax's, and the agent-side state of the batch."""

    env: Any               # stori_jax.XlaHandle
    lives: jax.Array       # (B,) int32: lives after the last step (episodic_life)
    elapsed: jax.Array     # (B,) int32: envpool's elapsed_step


class SentHandle(NamedTuple):
    """What xla()'s ``send`` returns: the handle with the actions its ``recv`` steps with."""

    handle: FacadeHandle
    actions: jax.Array


def make(task_id: str, env_type: str = "gym", **kwargs) -> "StoriEnvPool":
    """envpool.make for STORI: see the module's docstring; every keyword envpool's Atari task
    takes, with envpool's meaning or a clear ValueError, and stori_jax's ``config``,
    ``granularity``, ``backend``, ``num_workers``, ``inline_envs``."""
    if env_type not in ENV_TYPES:
        raise ValueError(f"env_type must be one of {list(ENV_TYPES)}, got {env_type!r}"
                         + (" (dm_env's API is not offered)" if env_type == "dm" else ""))
    unknown = sorted(set(kwargs) - set(ENVPOOL_DEFAULTS) - set(STORI_KEYWORDS))
    if unknown:
        raise ValueError(f"unsupported keyword(s) {unknown} for envpool_bridge.make: it takes "
                         f"envpool's Atari keywords {sorted(ENVPOOL_DEFAULTS)} and stori_jax's "
                         f"{list(STORI_KEYWORDS)} (docs/drop-in.md)")
    settings = {**ENVPOOL_DEFAULTS, **kwargs}
    game, preset = parse_task_id(task_id)
    return (StoriGymnasiumEnvPool if env_type == "gymnasium" else StoriEnvPool)(
        task_id, game, preset, settings)


def parse_task_id(task_id) -> tuple[str, str | None]:
    """(game, preset or None) of ``<Game>-v5`` or ``<Game>-<preset>-v5``."""
    match = TASK_ID.match(task_id) if isinstance(task_id, str) else None
    if match is None:
        raise ValueError(f"task_id must be envpool's Atari id '<Game>-v5' (e.g. 'Breakout-v5', "
                         f"STORI's 3.1) or a STORI preset '<Game>-<preset>-v5' (e.g. "
                         f"'Breakout-2.1-v5'), got {task_id!r}")
    return match["game"], match["preset"]


def _check_flag(name: str, value, allowed=(True, False)) -> None:
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    if bool(value) not in allowed:
        why = DIFFERENCES.get(name)
        raise ValueError(f"{name}={value!r} is not supported" + (f": {why}" if why else ""))


def _observation_kind(settings: dict, ram_observation: bool) -> tuple[str, int]:
    """(stori_jax's obs, frames stacked) for envpool's image keywords, or a ValueError."""
    from stori_jax.checks import check_int

    height = check_int("img_height", settings["img_height"], 1)
    width = check_int("img_width", settings["img_width"], 1)
    stack = check_int("stack_num", settings["stack_num"], 1)
    gray = settings["gray_scale"]
    _check_flag("gray_scale", gray)
    if ram_observation:  # type 0: the observation is the RAM, no image keyword applies
        if (height, width, stack, bool(gray)) != (84, 84, 4, True):
            raise ValueError("a type-0 config (ram_observation) observes the 128 RAM bytes: "
                             "leave img_height, img_width, stack_num and gray_scale at envpool's "
                             "defaults")
        return "ram", 1
    key = (height, width, bool(gray))
    if key not in IMAGES or stack > IMAGES[key][1]:
        offered = "; ".join(f"img_height={h}, img_width={w}, gray_scale={g}, stack_num 1.."
                            f"{IMAGES[(h, w, g)][1]}" for h, w, g in IMAGES)
        raise ValueError(f"img_height={height}, img_width={width}, gray_scale={bool(gray)}, "
                         f"stack_num={stack} cannot be honoured exactly: stori_jax's "
                         f"observations are {offered}")
    return IMAGES[key][0], stack


def _stori_make_kwargs(game: str, preset: str | None, settings: dict) -> tuple[dict, str, int]:
    """stori_jax.make's keywords for envpool's ``settings`` (validated); the obs and stack."""
    from stori_jax.checks import MAX_INT32, MAX_SEED, check_int, check_probability
    from stori_jax.builder import resolve_config, sticky_actions_config

    num_envs = check_int("num_envs", settings["num_envs"], 1)
    batch = check_int("batch_size", settings["batch_size"], 0)
    if batch not in (0, num_envs):
        raise ValueError(f"batch_size={batch}: {DIFFERENCES['batch_size']} (num_envs={num_envs})")
    if check_int("max_num_players", settings["max_num_players"], 1) != 1:
        raise ValueError("max_num_players must be 1 (Atari is one player)")
    for name in NO_EFFECT:
        check_int(name, settings[name])
    seed = settings["seed"]
    if isinstance(seed, (list, tuple, np.ndarray)):
        raise ValueError(f"seed must be one int (env i's streams derive from it and i); per-env "
                         f"seed lists are not supported, got {seed!r}")
    seed = check_int("seed", seed, 0, MAX_SEED)
    for name, allowed in (("episodic_life", (True, False)), ("reward_clip", (True, False)),
                          ("gym_reset_return_info", (True, False)),
                          ("use_fire_reset", (False,)), ("full_action_space", (False,)),
                          ("zero_discount_on_life_loss", (False,)),
                          ("use_inter_area_resize", (True,))):
        _check_flag(name, settings[name], allowed)
    for name in ("mode", "difficulty"):
        if settings[name] not in (-1, None):
            raise ValueError(f"{name}={settings[name]!r} is not supported: STORI plays each "
                             f"game's default {name} (the presets are defined on it); leave it -1")
    frame_skip = check_int("frame_skip", settings["frame_skip"], 1)
    steps = check_int("max_episode_steps", settings["max_episode_steps"], 1)
    noop_max = check_int("noop_max", settings["noop_max"])
    if not 1 <= noop_max <= MAX_INT32:
        raise ValueError(f"noop_max must be in [1, {MAX_INT32}] (envpool draws 1..noop_max NOOP "
                         f"frames at a reset; noop_max=1 starts every episode alike), got "
                         f"{noop_max}")
    config = settings.get("config")
    if config is not None and preset is not None:
        raise ValueError(f"config: the task id names preset {preset!r}; pass config= with a "
                         f"plain id ('{game}-v5')")
    sticky = check_probability("repeat_action_probability",
                               settings["repeat_action_probability"])
    cfg = (sticky_actions_config(game, preset, config, sticky, settings.get("granularity"))
           if sticky > 0 else resolve_config(game, preset, config))
    obs, stack = _observation_kind(settings, cfg.ram_observation)
    make_kwargs = dict(config=cfg, num_envs=num_envs, seed=seed, obs=obs,
                       frame_skip=frame_skip, noop_max=noop_max - 1, autoreset=False,
                       max_episode_frames=min(steps * frame_skip, MAX_INT32))
    for name in STORI_KEYWORDS[1:]:
        if settings.get(name) is not None:
            make_kwargs[name] = settings[name]
    return make_kwargs, obs, stack


def _to_envpool(xp, obs_kind: str, stack: int, episodic_life: bool, reward_clip: bool,
                gym_api: bool, outputs, prev_lives, prev_elapsed):
    """envpool's outputs of one stori_jax step (``xp``: numpy on the host, jax.numpy inside
    xla()'s step): (obs, reward, done, terminated, truncated, info, lives, elapsed)."""
    obs, reward, terminated, truncated, info = outputs
    b = reward.shape[0]
    lives = info["lives"].astype(xp.int32)
    reset_step = info["reset_step"].astype(bool)
    elapsed = xp.where(reset_step, 0, prev_elapsed + 1).astype(xp.int32)
    terminated, truncated = terminated.astype(bool), truncated.astype(bool)
    if episodic_life:  # atari_env.h: 0 < lives < lives before the step
        life_lost = (lives > 0) & (lives < prev_lives) & ~reset_step
    else:
        life_lost = xp.zeros((b,), bool)
    done = terminated | truncated | life_lost
    game_reward = reward.astype(xp.float32)
    out_info = {key: value for key, value in info.items() if key != "final_obs"}
    env_id = xp.arange(b, dtype=xp.int32)
    out_info.update({"env_id": env_id, "players": {"env_id": env_id}, "lives": lives,
                     "reward": game_reward, "terminated": terminated.astype(xp.int32),
                     "elapsed_step": elapsed})
    if gym_api:
        out_info["TimeLimit.truncated"] = truncated
    return (_observation(xp, obs_kind, stack, obs),
            xp.sign(game_reward) if reward_clip else game_reward,
            done, done & ~truncated, truncated, out_info, lives, elapsed)


def _observation(xp, obs_kind: str, stack: int, obs):
    """stori_jax's observation in envpool's layout: channels first, the newest ``stack``."""
    if obs_kind == "ram":
        return obs
    chw = xp.transpose(obs, (0, 3, 1, 2))
    return chw[:, chw.shape[1] - stack:] if obs_kind == "atari84" else chw


def _weak_method(method):
    """``method`` (bound) through a weak reference: JAX's caches keep traced callbacks alive,
    and a strong one would keep the pool and its env's workers with it."""
    ref = weakref.WeakMethod(method)

    def call():
        bound = ref()
        if bound is not None:
            bound()

    return call


def _spaces(gym_api: bool):
    """The spaces module: old gym's where it is installed and the API is gym's (envpool < 1.0
    gave gym's spaces there, and CleanRL's scripts check ``isinstance(space,
    gym.spaces.Discrete)``), gymnasium's otherwise."""
    if gym_api:
        try:
            import gym

            return gym.spaces
        except Exception:  # not installed, or an old gym that fails to import
            pass
    return gym_spaces


def _numpy_tree(tree):
    return jax.tree.map(np.array, tree)


class StoriEnvPool:
    """A batch of STORI envs with envpool's Python API (``env_type="gym"``)."""

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}
    _gym_api = True  # envpool < 1.0's gym API: reset -> obs, step -> (obs, reward, done, info)

    def __init__(self, task_id: str, game: str, preset: str | None, settings: dict):
        import stori_jax

        make_kwargs, self._obs_kind, self._stack = _stori_make_kwargs(game, preset, settings)
        self._episodic_life = bool(settings["episodic_life"])
        self._reward_clip = bool(settings["reward_clip"])
        self._reset_info = bool(settings["gym_reset_return_info"])
        self.task_id = task_id
        self._env = stori_jax.make(game, **make_kwargs)
        b = self._env.num_envs
        self._config = {**{k: v for k, v in settings.items() if k in ENVPOOL_DEFAULTS},
                        "num_envs": b, "batch_size": b, "task": self._env.game.rom_id,
                        "stori_config": self._env.config, "stori_noop_max": make_kwargs["noop_max"],
                        "stori_max_episode_frames": make_kwargs["max_episode_frames"]}
        self.num_envs = b
        shape = self._env.single_observation_space.shape
        if self._obs_kind != "ram":
            shape = _observation(np, self._obs_kind, self._stack,
                                 np.zeros((1,) + shape, np.uint8)).shape[1:]
        spaces = _spaces(self._gym_api)
        # one env's spaces, as envpool's observation_space and action_space are
        self.observation_space = self.single_observation_space = spaces.Box(0, 255, shape,
                                                                            np.uint8)
        self.action_space = self.single_action_space = spaces.Discrete(self._env.num_actions)
        self.is_vector_env = True
        self._lives = np.zeros(b, np.int32)
        self._elapsed = np.zeros(b, np.int32)
        self._async_reset = None  # a reset async_reset() made, for the next recv()
        self._shared_reset = None  # the reset xla() made, for the first reset() after it
        self._xla = None  # (handle, recv, send, step) of the current xla() chain
        self._needs_reset = True  # no reset yet
        self._xla_stepped = False  # a step of the current xla() chain has run
        self.closed = False

    # -- envpool's attributes ---------------------------------------------------------------

    @property
    def config(self) -> dict:
        """envpool's config keys with the values in effect, and stori_jax's own."""
        return dict(self._config)

    @property
    def all_env_ids(self) -> np.ndarray:
        return np.arange(self.num_envs, dtype=np.int32)

    @property
    def is_async(self) -> bool:
        return False

    def __len__(self) -> int:
        return self.num_envs

    def seed(self, seed=None) -> None:
        warnings.warn("The `seed` function in envpool is abandoned. You can set seed by "
                      "envpool_bridge.make(..., seed=seed), or reset(seed=...), instead.",
                      stacklevel=2)

    def render(self, *args, **kwargs):
        raise ValueError("render: this pool does not render (obs gives the screens with "
                         "img_height=210, img_width=160, gray_scale=False, stack_num=1; "
                         "`stori-jax record` writes GIFs)")

    def close(self, **kwargs) -> None:
        self._env.close()
        self.closed = True

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self) -> str:
        return f"StoriEnvPool({self.task_id!r}, {self._env!r})"

    # -- host side --------------------------------------------------------------------------

    def _check_env_ids(self, env_id, what: str):
        """The order of a full batch's ``env_id`` (None: 0..B-1)."""
        if env_id is None:
            return None
        ids = np.asarray(env_id)
        if ids.ndim == 0:
            ids = ids.reshape(1)
        if sorted(ids.tolist()) != list(range(self.num_envs)):
            raise ValueError(f"{what}: env_id must name every env once ({DIFFERENCES['batch_size']}"
                             f"), got {env_id!r}")
        return ids.astype(np.int64)

    def _reset_outputs(self, obs, info):
        self._lives = np.asarray(info["lives"], np.int32)
        self._elapsed = np.zeros(self.num_envs, np.int32)
        zeros = np.zeros(self.num_envs, bool)
        outputs = (obs, np.zeros(self.num_envs, np.float32), zeros, zeros, info)
        # a reset is a step whose every env starts an episode (info['reset_step'] True)
        return self._host_outputs(outputs, self._lives, np.full(self.num_envs, -1, np.int32))

    def _host_outputs(self, outputs, prev_lives, prev_elapsed):
        outputs = _numpy_tree(outputs)
        obs, reward, done, terminated, truncated, info, lives, elapsed = _to_envpool(
            np, self._obs_kind, self._stack, self._episodic_life, self._reward_clip,
            self._gym_api, outputs, prev_lives, prev_elapsed)
        self._lives, self._elapsed = lives, elapsed
        return np.ascontiguousarray(obs), reward, done, terminated, truncated, info

    def _format(self, result, reset: bool, return_info: bool = True):
        obs, reward, done, terminated, truncated, info = result
        if reset:
            return obs if self._gym_api and not return_info else (obs, info)
        if self._gym_api:
            return obs, reward, done, info
        return obs, reward, terminated, truncated, info

    def _check_reset_options(self, options):
        if options is None:
            return None
        if not isinstance(options, dict) or set(options) - {"reset_mask"}:
            raise ValueError(f"reset options: only {{'reset_mask': ...}} (envpool's), got "
                             f"{options!r}")
        mask = np.asarray(options.get("reset_mask", np.ones(self.num_envs, bool)), bool)
        if mask.shape != (self.num_envs,) or not mask.all():
            raise ValueError(f"reset_mask: {DIFFERENCES['reset(env_id=...)']}, got {mask!r}")
        return None

    def _fresh_xla_reset(self) -> bool:
        """xla() made the last reset and its chain has not stepped: a reset() now shares it."""
        if self._shared_reset is None:
            return False
        jax.effects_barrier()  # xla steps dispatched but not yet run count too
        return not self._xla_stepped

    def _note_xla_step(self) -> None:
        self._xla_stepped = True

    def _do_reset(self, seed=None):
        if seed is None and self._fresh_xla_reset():
            return self._shared_reset
        self._shared_reset, self._xla, self._async_reset = None, None, None
        self._needs_reset = True  # until this reset is done
        self._last_reset = self._reset_outputs(*self._env.reset(seed=seed))
        self._needs_reset = False
        return self._last_reset

    def reset(self, env_id=None, *, seed: int | None = None, options: dict | None = None):
        """Reset every env: gym: obs (and info with ``gym_reset_return_info``); gymnasium:
        (obs, info).  ``seed``: restart the run from that seed."""
        self._check_env_ids(env_id, "reset")
        self._check_reset_options(options)
        return self._format(self._do_reset(seed), reset=True,
                            return_info=self._reset_info or not self._gym_api)

    def async_reset(self) -> None:
        """Reset every env (at once); the next ``recv()`` returns it."""
        self._async_reset = None
        self._async_reset = self._do_reset()

    def send(self, action, env_id=None) -> None:
        order = self._check_env_ids(env_id, "send")
        actions = np.asarray(action)
        if order is not None:
            full = np.empty_like(actions)
            full[order] = actions
            actions = full
        if self._async_reset is not None:
            raise RuntimeError("recv() the reset of async_reset() before send()")
        self._env.send(actions)

    def recv(self, reset: bool = False, return_info: bool = True):
        if self._async_reset is not None:
            result, self._async_reset = self._async_reset, None
        else:
            result = self._host_outputs(self._env.recv(), self._lives, self._elapsed)
        return self._format(result, reset=reset, return_info=return_info)

    def step(self, action, env_id=None):
        self.send(action, env_id)
        return self.recv()

    # -- inside jax.jit -----------------------------------------------------------------------

    def xla(self):
        """envpool's ``(handle, recv, send, step)``: ``step(handle, actions)`` ->
        ``(handle, (obs, reward, done, info))`` (gymnasium: ``(obs, reward, terminated,
        truncated, info)``), pure and traceable (``jax.jit``, ``jax.lax.scan``).  Pass on the
        handle each call returns.  Taken before the first ``reset()`` (as CleanRL's scripts do),
        it resets the envs itself, and that ``reset()`` returns the same reset."""
        if self._xla is not None:
            jax.effects_barrier()  # its steps dispatched but not yet run count too
            if not self._xla_stepped:  # that chain has not stepped: it is still the current one
                return self._xla
        env = self._env
        fresh = self._needs_reset
        if fresh:  # CleanRL's order: xla() first, then reset()
            self._do_reset()
            self._shared_reset = self._last_reset
        else:
            self._shared_reset = None
        stori_handle, stori_step = env.xla()
        self._xla_stepped = False
        note_step = _weak_method(self._note_xla_step)
        handle = FacadeHandle(stori_handle, jnp.asarray(self._lives), jnp.asarray(self._elapsed))
        settings = (self._obs_kind, self._stack, self._episodic_life, self._reward_clip,
                    self._gym_api)
        b = self.num_envs

        def step(handle, action, env_id=None):
            if not isinstance(handle, FacadeHandle):
                raise ValueError(f"handle must be the one xla() or the last step returned, got "
                                 f"{type(handle).__name__}"
                                 + (" (send() returned it: recv() it)"
                                    if isinstance(handle, SentHandle) else ""))
            action = jnp.asarray(action)
            if env_id is not None:  # a whole batch in env_id's order
                action = jnp.zeros((b,), action.dtype).at[jnp.asarray(env_id)].set(action)
            new_env, outputs = stori_step(handle.env, action)
            io_callback(note_step, None, ordered=True)  # for reset() (see _fresh_xla_reset)
            obs, reward, done, terminated, truncated, info, lives, elapsed = _to_envpool(
                jnp, *settings, outputs, handle.lives, handle.elapsed)
            out = ((obs, reward, done, info) if settings[-1]
                   else (obs, reward, terminated, truncated, info))
            return FacadeHandle(new_env, lives, elapsed), out

        def send(handle, action, env_id=None):
            if not isinstance(handle, FacadeHandle):
                raise ValueError(f"send: handle must be the one xla() or the last step/recv "
                                 f"returned, got {type(handle).__name__}")
            action = jnp.asarray(action)
            if env_id is not None:
                action = jnp.zeros((b,), action.dtype).at[jnp.asarray(env_id)].set(action)
            return SentHandle(handle, action)

        def recv(handle):
            if not isinstance(handle, SentHandle):
                raise ValueError("recv: handle must be the one send() returned (the envs step "
                                 "in recv, with the actions send() took), got "
                                 f"{type(handle).__name__}")
            return step(handle.handle, handle.actions)

        self._xla = (handle, recv, send, step)
        return self._xla


class StoriGymnasiumEnvPool(StoriEnvPool, VectorEnv):
    """``env_type="gymnasium"``: envpool's gymnasium API (a gymnasium VectorEnv, next-step
    autoreset)."""

    _gym_api = False
