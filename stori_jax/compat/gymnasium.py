"""Gymnasium's envs of stori_jax and their ids: ``stori_jax/<Game>-<preset>-v0`` for
``gymnasium.make`` (one env, numpy) and ``gymnasium.make_vec`` (a gymnasium VectorEnv, autoreset
mode NEXT_STEP).

    import gymnasium as gym, stori_jax
    env = gym.make("stori_jax/Breakout-2.1-v0")
    envs = gym.make_vec("stori_jax/Breakout-2.1-v0", num_envs=8)

``reset()`` without a seed is seed 0 (the env is reproducible by default); ``reset(seed=k)``
makes it seed k's.  After a worker died (the step raised ``WorkerError``), ``reset()`` makes the
env again from its seed (the seed's first episode, as a fresh env's).  ``make_vec``'s default
mode is the one to prefer: stori_jax steps its envs in its own worker processes.  Gymnasium's
``"async"`` mode puts each env in a daemonic process, which may start none, so there the env
emulates in that process (``num_workers=0``, the same run); it needs
``vector_kwargs={"context": "spawn"}``, since JAX hangs in a process forked after it started
(stori_jax refuses that with an error saying so).

Extra keyword arguments (``obs``, ``frame_skip``, ``granularity``, ``backend``, ``num_workers``,
``inline_envs``, ``max_episode_frames``, ``noop_max``) go to :func:`stori_jax.make`; the id fixes
the game and the preset.  A config of your own (type 0 included) goes through the classes:

    env = StoriGymEnv("Breakout", config=stori_jax.Config(ram_observation=True), obs="ram")
    envs = StoriVectorEnv(8, "Breakout", config=my_config)

ale-py's style (docs/drop-in.md): ``stori_ALE/<Game>-<preset>-v5`` and
``stori_ALE/<Game>NoFrameskip-<preset>-v4`` take ale-py's ``AtariEnv`` keywords, and every env
here takes them too; ``env.unwrapped.ale`` stands in for ale-py's ``ALEInterface``, with
``get_action_meanings()`` beside it (all of it in :mod:`stori_jax.compat.ale`).
``gymnasium.make("stori_jax:stori_ALE/...")`` imports stori_jax itself (gymnasium's
``module:id``), so a script's env id is the one change.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from stori_jax.checks import MAX_SEED, check_int
from stori_jax.compat.ale import (ALE_ID_DEFAULTS, RENDER_MODES, SCREEN_DIMS, StoriALE,
                                  action_meanings, ale_env_id, ale_grayscale, take_ale_keywords)
from stori_jax.games import get_game

NAMESPACE = "stori_jax"


def env_id(game: str, preset: str) -> str:
    return f"{NAMESPACE}/{game}-{preset}-v0"


def _numpy(x) -> np.ndarray:
    """A writable numpy copy (``np.asarray`` of a JAX array is a read-only view)."""
    return np.array(x)


def _vector_info(info: dict, num_envs: int) -> dict:
    """The batch's info as gymnasium's vector envs give it: numpy arrays, each key (nested
    dicts' too) beside its ``_key`` mask of the envs that report it (here every env)."""
    masks = iter(np.ones((_count_keys(info), num_envs), dtype=np.bool_))  # a row each, one
    # allocation: a step's ~60 keys each with its own np.ones doubled the conversion's time

    def with_masks(tree: dict) -> dict:
        out = {}
        for key, value in tree.items():
            out[key] = with_masks(value) if isinstance(value, dict) else _numpy(value)
            out[f"_{key}"] = next(masks)
        return out

    return with_masks(info)


def _count_keys(tree: dict) -> int:
    return sum(1 + (_count_keys(v) if isinstance(v, dict) else 0) for v in tree.values())


def _first_env_info(info: dict) -> dict:
    """The single env's info: env 0's entry of every batched leaf (``labels`` included)."""
    import jax

    # one transfer of the whole tree, then numpy indexing: indexing each JAX leaf was a JAX
    # dispatch per key (~60 of them), three quarters of a single env's step
    return jax.tree.map(lambda v: np.array(v[0]), jax.device_get(info))


def _names(game, preset, registered: tuple[str, str]) -> bool:
    """``game`` and ``preset`` name the registered pair, whatever their case."""
    from stori_jax.presets import canonical_preset

    try:
        return (get_game(game).name,
                canonical_preset(registered[0], preset)) == registered
    except ValueError:
        return False


def _closed_error(message: str) -> Exception:
    from stori_jax.backends.subproc import EnvClosedError  # not imported until needed

    return EnvClosedError(message)


class _Owner:
    """Holds one stori_jax Env (made again only after a worker died)."""

    def _init_env(self, game, preset, num_envs, seed, make_kwargs):
        from stori_jax.builder import make  # the env and JAX load on first use

        registered = make_kwargs.pop("registered_as", None)
        if registered is not None:  # a spec saved as JSON or YAML gives it back as a list
            registered = tuple(registered)
        ale_style = make_kwargs.pop("ale_style", False)
        if ale_style not in (False, True):
            raise ValueError(f"ale_style must be True or False, got {ale_style!r}")
        id_name = None
        if registered is not None:
            id_name = (ale_env_id(*registered, make_kwargs.get("frameskip", 4)) if ale_style
                       else env_id(*registered))
        if registered is not None and "config" in make_kwargs:
            raise ValueError(f"config: the id {id_name} fixes the preset; for a "
                             "Config of your own use stori_jax.compat.gymnasium.StoriGymEnv(game, "
                             "config=...) or StoriVectorEnv(num_envs, game, config=...)")
        if registered is not None and not _names(game, preset, registered):
            raise ValueError(f"this id is {id_name}: it fixes game and preset, got "
                             f"game={game!r} preset={preset!r}; use that preset's own id")
        if "max_episode_steps" in make_kwargs:  # make_vec's default mode, or the classes
            # (gymnasium.make takes it itself, for its TimeLimit wrapper)
            raise ValueError("max_episode_steps: stori_jax envs cap episodes in emulator "
                             "frames: pass max_episode_frames (steps x frame_skip), got "
                             f"max_episode_steps={make_kwargs['max_episode_steps']!r}")
        for name in ("num_envs", "autoreset"):
            if name in make_kwargs:
                raise ValueError(f"{name} is set by the gymnasium adapter ({self._fixed}), got "
                                 f"{name}={make_kwargs[name]!r}")
        ale = take_ale_keywords(make_kwargs, ale_style, id_name)
        if ale["render_mode"] is not None and not self._renders:
            raise ValueError(f"render_mode: a stori_jax vector env does not render, got "
                             f"render_mode={ale['render_mode']!r}; a single env does "
                             "(gymnasium.make(id, render_mode='rgb_array')), and `stori-jax "
                             "record` writes GIFs")
        if ale["render_mode"] is not None and make_kwargs.get("obs") != "raw":
            raise ValueError(f"render_mode={ale['render_mode']!r} needs the screens: obs_type "
                             "'rgb' or 'grayscale' (obs='raw' on a -v0 id), got "
                             + (f"obs={make_kwargs.get('obs', 'atari84')!r}"
                                if ale["obs_type"] is None
                                else f"obs_type={ale['obs_type']!r}"))
        self._obs_type = ale["obs_type"]
        self.render_mode = ale["render_mode"]
        if ale["repeat_action_probability"] > 0:
            from stori_jax.builder import sticky_actions_config

            make_kwargs["config"] = sticky_actions_config(
                game, preset, make_kwargs.get("config"), ale["repeat_action_probability"],
                make_kwargs.get("granularity"))
            preset = None
        self._game_name = game
        self._frameskip = make_kwargs.get("frame_skip", 4)  # ale-py's name: AtariPreprocessing
        self._make = lambda s: make(game, preset, num_envs=num_envs, seed=s, autoreset=False,
                                    **make_kwargs)
        # an int: gymnasium takes no numpy seed
        self._seed = 0 if seed is None else check_int("seed", seed, 0, MAX_SEED)
        self._env = self._make(self._seed)
        self._fresh = True  # no reset yet: the env is exactly as made from self._seed
        self._gym_reset_done = False  # gymnasium's reset not yet called (np_random unseeded)
        self.closed = False

    def get_action_meanings(self) -> list[str]:
        """ale-py's: the meaning of each action (the game's minimal action set)."""
        return list(action_meanings(self._game_name))

    def _spaces(self, single: gym.spaces.Box) -> gym.spaces.Box:
        """One env's observation space as the adapter hands it out."""
        if self._obs_type == "grayscale":
            return gym.spaces.Box(0, 255, SCREEN_DIMS, np.uint8)
        return single

    def _observation(self, obs) -> np.ndarray:
        obs = _numpy(obs)
        return ale_grayscale(obs) if self._obs_type == "grayscale" else obs

    def _check_open(self):
        if self.closed:
            raise _closed_error("this environment is closed; make a new one with "
                                "gymnasium.make or gymnasium.make_vec")

    def _check_steppable(self):
        self._check_open()
        if self._env.closed:  # closed by a worker's death (only close() closes it otherwise)
            raise _closed_error("a worker of this environment died (the step that said so "
                                "raised WorkerError); reset() makes the env again from its "
                                "seed")

    def _reset_env(self, seed):
        """Reset the env: an explicit seed restarts everything (emulators and key) from that
        seed, in the same worker processes; after a worker died, the env is made again."""
        self._check_open()
        if isinstance(seed, (list, tuple, np.ndarray)):
            raise ValueError(f"seed must be one int for all envs (env i's emulator seed derives "
                             f"from it and i); per-env seed lists are not supported, got {seed!r}")
        if seed is not None:
            seed = check_int("seed", seed, 0, MAX_SEED)  # a refused seed changes nothing
        reseed = seed is not None and not (self._fresh and seed == self._seed)
        if reseed:
            self._seed = seed  # asked for, so kept even if this reset fails (a worker dies)
        if self._env.closed:  # a worker died (the step said so): start again from the seed
            self._env, reseed = self._make(self._seed), False
        self._fresh = False
        return self._env.reset(seed=seed if reseed else None)

    def _gym_seed(self, seed):
        """The seed for gymnasium's own ``reset`` (np_random, np_random_seed), after
        ``_reset_env``: the int the env plays, also on a first reset without a seed (gymnasium
        would draw a random one); None on a later one (np_random goes on)."""
        first, self._gym_reset_done = not self._gym_reset_done, True
        return self._seed if seed is not None or first else None

    @staticmethod
    def _check_options(options):
        if options is not None and not isinstance(options, dict):
            raise ValueError(f"options must be a dict or None (gymnasium's reset), got "
                             f"{options!r}")
        if options:  # None or {}: nothing asked
            raise ValueError(f"reset options are not supported by stori_jax envs (reset() "
                             f"resets every env; no partial reset_mask), got {options!r}")

    def close(self, **kwargs):
        if getattr(self, "_env", None) is not None:
            self._env.close()
        self.closed = True  # a later reset(seed=...) must not make the env again


class StoriGymEnv(_Owner, gym.Env):
    """One STORI env with gymnasium's single-env API (numpy outputs).  Call ``reset()`` after
    an episode ends: a ``step()`` instead resets the env (the new episode's first observation,
    reward 0, ``info["reset_step"]`` True), as the batched env's next-step autoreset does.

    ``unwrapped.ale`` (:class:`StoriALE`) and ``get_action_meanings()`` answer as ale-py's
    ``AtariEnv`` does; ``render()`` with ``render_mode="rgb_array"`` returns the screen."""

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 60}
    _renders = True
    _fixed = ("one env, whose step after an episode's end starts the next one; "
              "gymnasium.make_vec(id, num_envs=N) for a batch")

    def __init__(self, game: str, preset: str | None = None, seed: int | None = None,
                 **make_kwargs):
        self._last = None  # the last reset's or step's screen, lives, flags and RAM
        self._init_env(game, preset, 1, seed, make_kwargs)
        # 60 emulator frames a second, frameskip of them a step
        self.metadata = {**self.metadata, "render_fps": 60 / self._frameskip}
        self.observation_space = self._spaces(self._env.single_observation_space)
        self.action_space = self._env.single_action_space
        self.ale = StoriALE(self)

    def _record(self, obs, info, terminated=False, truncated=False):
        """What ``ale`` and ``render()`` answer until the next step; the observation out."""
        first = _first_env_info(info)
        screen = _numpy(obs[0]) if self._env.plan.obs == "raw" else None
        self._last = {"screen": screen, "lives": first["lives"], "ram": first["ram"],
                      "terminated": terminated, "truncated": truncated}
        obs = screen.copy() if screen is not None else _numpy(obs[0])
        return (ale_grayscale(obs) if self._obs_type == "grayscale" else obs), first

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self._check_options(options)
        obs, info = self._reset_env(seed)  # checks the seed before gymnasium's np_random
        super().reset(seed=self._gym_seed(seed))
        return self._record(np.asarray(obs), info)

    def step(self, action):
        self._check_steppable()
        a = np.asarray(action)
        if a.shape != () or not np.issubdtype(a.dtype, np.integer) or not 0 <= a < self.action_space.n:
            raise ValueError(f"action must be one int in [0, {self.action_space.n - 1}], "
                             f"got {action!r}")
        import jax

        # one transfer, then numpy: indexing JAX arrays is a JAX dispatch each
        obs, reward, terminated, truncated, info = jax.device_get(self._env.step(a.reshape(1)))
        terminated, truncated = bool(terminated[0]), bool(truncated[0])
        obs, info = self._record(obs, info, terminated, truncated)
        return obs, float(reward[0]), terminated, truncated, info

    def render(self):
        """The screen (210, 160, 3) with ``render_mode="rgb_array"``, as ale-py's (see
        :class:`StoriALE` for which frame)."""
        if self.render_mode != "rgb_array":
            raise ValueError(f"render() needs render_mode='rgb_array' (gymnasium.make(id, "
                             f"render_mode='rgb_array')), this env has render_mode="
                             f"{self.render_mode!r}; `stori-jax record GAME PRESET` writes an "
                             "episode as a GIF")
        return self.ale.getScreenRGB()


class StoriVectorEnv(_Owner, VectorEnv):
    """B STORI envs as a gymnasium VectorEnv (numpy, autoreset mode NEXT_STEP)."""

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}
    _renders = False
    _fixed = ("gymnasium's NEXT_STEP autoreset: the step after an env's episode ends starts "
              "its next one")

    def __init__(self, num_envs: int, game: str, preset: str | None = None,
                 seed: int | None = None, **make_kwargs):
        self._init_env(game, preset, num_envs, seed, make_kwargs)
        self.num_envs = num_envs
        self.single_observation_space = self._spaces(self._env.single_observation_space)
        self.single_action_space = self._env.single_action_space
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space,
                                                              num_envs)
        self.action_space = self._env.action_space

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self._check_options(options)
        obs, info = self._reset_env(seed)
        super().reset(seed=self._gym_seed(seed))  # np_random(_seed), as gymnasium's vector envs
        return self._observation(obs), _vector_info(info, self.num_envs)

    def step(self, actions):
        self._check_steppable()
        obs, reward, terminated, truncated, info = self._env.step(actions)
        return (self._observation(obs), _numpy(reward), _numpy(terminated), _numpy(truncated),
                _vector_info(info, self.num_envs))


def register_all() -> None:
    """Register every paper preset (idempotent): ``<Game>-<preset>-v0`` (stori_jax's defaults),
    ``<Game>-<preset>-v5`` and ``<Game>NoFrameskip-<preset>-v4`` (ale-py's)."""
    from stori_jax.presets import list_presets

    for game, preset in list_presets():
        common = {"game": game, "preset": preset, "registered_as": (game, preset)}
        ids = [(env_id(game, preset), common)]
        for frameskip in (4, 1):
            ids.append((ale_env_id(game, preset, frameskip),
                        {**common, "ale_style": True, **ALE_ID_DEFAULTS, "frameskip": frameskip}))
        for gid, kwargs in ids:
            if gid in gym.registry:
                continue
            gym.register(id=gid, entry_point="stori_jax.compat.gymnasium:StoriGymEnv",
                         vector_entry_point="stori_jax.compat.gymnasium:StoriVectorEnv",
                         kwargs=kwargs)
