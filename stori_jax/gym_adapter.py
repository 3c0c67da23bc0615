"""Gymnasium adapter: ids ``stori_jax/<Game>-<preset>-v0`` for ``gymnasium.make`` (one env,
numpy) and ``gymnasium.make_vec`` (a gymnasium VectorEnv, autoreset mode NEXT_STEP).

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
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from stori_jax.checks import MAX_SEED, check_int

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

    return jax.tree.map(lambda v: _numpy(v[0]), info)


def _names(game, preset, registered: tuple[str, str]) -> bool:
    """``game`` and ``preset`` name the registered pair, whatever their case."""
    import stori_jax
    from stori_jax.presets import canonical_preset

    try:
        return (stori_jax.get_game(game).name,
                canonical_preset(registered[0], preset)) == registered
    except ValueError:
        return False


def _closed_error(message: str) -> Exception:
    from stori_jax.backends.subproc import EnvClosedError  # not imported until needed

    return EnvClosedError(message)


class _Owner:
    """Holds one stori_jax Env (made again only after a worker died)."""

    def _init_env(self, game, preset, num_envs, seed, make_kwargs):
        import stori_jax

        registered = make_kwargs.pop("registered_as", None)
        if registered is not None:  # a spec saved as JSON or YAML gives it back as a list
            registered = tuple(registered)
        if registered is not None and "config" in make_kwargs:
            raise ValueError(f"config: the id {env_id(*registered)} fixes the preset; for a "
                             "Config of your own use stori_jax.gym_adapter.StoriGymEnv(game, "
                             "config=...) or StoriVectorEnv(num_envs, game, config=...)")
        if registered is not None and not _names(game, preset, registered):
            raise ValueError(f"this id is {env_id(*registered)}: it fixes game and preset, got "
                             f"game={game!r} preset={preset!r}; use that preset's own id")
        if "max_episode_steps" in make_kwargs:  # make_vec's default mode, or the classes
            # (gymnasium.make takes it itself, for its TimeLimit wrapper)
            raise ValueError("max_episode_steps: stori_jax envs cap episodes in emulator "
                             "frames: pass max_episode_frames (steps x frame_skip), got "
                             f"max_episode_steps={make_kwargs['max_episode_steps']!r}")
        if make_kwargs.pop("render_mode", None) is not None:
            raise ValueError("render_mode: stori_jax envs do not render (render_modes []); "
                             "use `stori-jax record` for videos")
        for name in ("num_envs", "autoreset"):
            if name in make_kwargs:
                raise ValueError(f"{name} is set by the gymnasium adapter ({self._fixed}), got "
                                 f"{name}={make_kwargs[name]!r}")
        self._make = lambda s: stori_jax.make(game, preset, num_envs=num_envs, seed=s,
                                              autoreset=False, **make_kwargs)
        # an int: gymnasium takes no numpy seed
        self._seed = 0 if seed is None else check_int("seed", seed, 0, MAX_SEED)
        self._env = self._make(self._seed)
        self._fresh = True  # no reset yet: the env is exactly as made from self._seed
        self._gym_reset_done = False  # gymnasium's reset not yet called (np_random unseeded)
        self.closed = False

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

    def render(self):
        raise NotImplementedError("stori_jax envs do not render: `stori-jax record GAME PRESET` "
                                  "writes an episode as a GIF, and obs='raw' gives RGB frames")


class StoriGymEnv(_Owner, gym.Env):
    """One STORI env with gymnasium's single-env API (numpy outputs).  Call ``reset()`` after
    an episode ends: a ``step()`` instead resets the env (the new episode's first observation,
    reward 0, ``info["reset_step"]`` True), as the batched env's next-step autoreset does."""

    metadata = {"render_modes": []}
    _fixed = ("one env, whose step after an episode's end starts the next one; "
              "gymnasium.make_vec(id, num_envs=N) for a batch")

    def __init__(self, game: str, preset: str | None = None, seed: int | None = None,
                 **make_kwargs):
        self._init_env(game, preset, 1, seed, make_kwargs)
        self.observation_space = self._env.single_observation_space
        self.action_space = self._env.single_action_space

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self._check_options(options)
        obs, info = self._reset_env(seed)  # checks the seed before gymnasium's np_random
        super().reset(seed=self._gym_seed(seed))
        return _numpy(obs[0]), _first_env_info(info)

    def step(self, action):
        self._check_steppable()
        a = np.asarray(action)
        if a.shape != () or not np.issubdtype(a.dtype, np.integer) or not 0 <= a < self.action_space.n:
            raise ValueError(f"action must be one int in [0, {self.action_space.n - 1}], "
                             f"got {action!r}")
        obs, reward, terminated, truncated, info = self._env.step(a.reshape(1))
        return (_numpy(obs[0]), float(reward[0]), bool(terminated[0]), bool(truncated[0]),
                _first_env_info(info))


class StoriVectorEnv(_Owner, VectorEnv):
    """B STORI envs as a gymnasium VectorEnv (numpy, autoreset mode NEXT_STEP)."""

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}
    _fixed = ("gymnasium's NEXT_STEP autoreset: the step after an env's episode ends starts "
              "its next one")

    def __init__(self, num_envs: int, game: str, preset: str | None = None,
                 seed: int | None = None, **make_kwargs):
        self._init_env(game, preset, num_envs, seed, make_kwargs)
        self.num_envs = num_envs
        self.single_observation_space = self._env.single_observation_space
        self.single_action_space = self._env.single_action_space
        self.observation_space = self._env.observation_space
        self.action_space = self._env.action_space

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self._check_options(options)
        obs, info = self._reset_env(seed)
        super().reset(seed=self._gym_seed(seed))  # np_random(_seed), as gymnasium's vector envs
        return _numpy(obs), _vector_info(info, self.num_envs)

    def step(self, actions):
        self._check_steppable()
        obs, reward, terminated, truncated, info = self._env.step(actions)
        return (_numpy(obs), _numpy(reward), _numpy(terminated), _numpy(truncated),
                _vector_info(info, self.num_envs))


def register_all() -> None:
    """Register every paper preset (idempotent)."""
    from stori_jax.presets import list_presets

    for game, preset in list_presets():
        gid = env_id(game, preset)
        if gid in gym.registry:
            continue
        gym.register(id=gid, entry_point="stori_jax.gym_adapter:StoriGymEnv",
                     vector_entry_point="stori_jax.gym_adapter:StoriVectorEnv",
                     kwargs={"game": game, "preset": preset, "registered_as": (game, preset)})
