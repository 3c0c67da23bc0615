"""ale-py's ``AtariEnv`` compatibility: what lets a script written for ale-py's
``ALE/<Game>-v5`` and ``<Game>NoFrameskip-v4`` run on a STORI env with its env id the one change
(docs/drop-in.md).

- The ids in ale-py's style: ``stori_ALE/<Game>-<preset>-v5`` (ale-py's ``ALE/<Game>-v5``: RGB
  frames, frameskip 4) and ``stori_ALE/<Game>NoFrameskip-<preset>-v4`` (``<Game>NoFrameskip-v4``:
  frameskip 1, for wrapper stacks that skip frames themselves), and the keywords those ids fix.
- ale-py's ``AtariEnv`` keywords, which every gymnasium env of stori_jax takes
  (:func:`take_ale_keywords`): ``obs_type`` (``rgb``, ``grayscale`` with ALE's own luminance,
  ``ram``), ``frameskip``, ``repeat_action_probability`` (ALE's sticky actions: STORI's type 1
  ``ActionNoise(p, sticky=True)`` per emulator frame), ``max_num_frames_per_episode`` and
  ``render_mode="rgb_array"``; ``full_action_space``, ``mode``, ``difficulty``, ``continuous``
  and ``sound_obs`` only at their defaults (a clear error otherwise).
- ``env.unwrapped.ale`` (:class:`StoriALE`), the stand-in for ale-py's ``ALEInterface``
  (``lives()``, ``getScreenRGB``, ``getScreenGrayscale``, ``getRAM``, ...), and
  ``get_action_meanings()`` (:func:`action_meanings`), so gymnasium's ``AtariPreprocessing`` and
  CleanRL's and SB3's Atari wrappers run unchanged.

The gymnasium envs and their registration are in :mod:`stori_jax.compat.gymnasium`; nothing
here imports gymnasium.
"""

from __future__ import annotations

import functools

import numpy as np

from stori_jax.checks import check_int, check_probability
from stori_jax.games import get_game

ALE_NAMESPACE = "stori_ALE"  # ale-py's style (gymnasium ids hold one namespace: no stori_jax/ALE/)

def ale_env_id(game: str, preset: str, frameskip: int = 4) -> str:
    """ale-py's style: ``stori_ALE/<Game>-<preset>-v5`` (frameskip 4), or
    ``stori_ALE/<Game>NoFrameskip-<preset>-v4`` (frameskip 1), as ale-py's ``ALE/<Game>-v5`` and
    ``<Game>NoFrameskip-v4``.  (Not ``stori_jax/<Game>-<preset>-v5``: gymnasium would call the
    -v0 ids out of date.)"""
    if frameskip == 1:
        return f"{ALE_NAMESPACE}/{game}NoFrameskip-{preset}-v4"
    return f"{ALE_NAMESPACE}/{game}-{preset}-v5"


# -- ale-py's AtariEnv keywords -------------------------------------------------------------------

SCREEN_DIMS = (210, 160)
RENDER_MODES = ("rgb_array",)
OBS_TYPES = ("rgb", "grayscale", "ram")
# ale-py's keyword -> make's keyword for the same setting
ALE_TWINS = {"obs_type": "obs", "frameskip": "frame_skip",
             "max_num_frames_per_episode": "max_episode_frames"}
# what ale-py's registered ids fix (ale_py/registration.py), but sticky actions (see below)
ALE_ID_DEFAULTS = dict(obs_type="rgb", repeat_action_probability=0.0, full_action_space=False,
                       max_num_frames_per_episode=108_000)
NO_CAP = 2**31 - 1  # max_num_frames_per_episode None or 0 (ALE: no cap), in frames


def ale_grayscale(rgb) -> np.ndarray:
    """ALE's ``getScreenGrayscale`` of RGB screens (..., 3) -> (...): its palette's luminance,
    ``round(0.2989 R + 0.5870 G + 0.1140 B)`` in double precision, rounding half up (ALE's
    ColourPalette; stori_jax's atari84 uses integer ITU-R 601 weights instead)."""
    rgb = np.asarray(rgb)
    y = rgb[..., 0] * 0.2989 + rgb[..., 1] * 0.5870 + rgb[..., 2] * 0.1140  # float64
    whole = np.floor(y)
    return (whole + (y - whole >= 0.5)).astype(np.uint8)


@functools.lru_cache(maxsize=None)
def action_meanings(game: str) -> tuple[str, ...]:
    """ale-py's ``get_action_meanings()`` of ``game``'s minimal action set (the actions a
    stori_jax env takes, in order)."""
    from ale_py import Action, ALEInterface, LoggerMode, roms

    ALEInterface.setLoggerMode(LoggerMode.Error)
    ale = ALEInterface()
    ale.loadROM(roms.get_rom_path(get_game(game).rom_id))
    names = {value: name for name, value in Action.__members__.items()}
    return tuple(names[a] for a in ale.getMinimalActionSet())


def take_ale_keywords(kwargs: dict, ale_style: bool, id_name: str | None = None) -> dict:
    """Replace ale-py's ``AtariEnv`` keywords in ``kwargs`` (make's keywords) by make's own, in
    place; returns what the adapter does itself: ``obs_type`` (None: make's ``obs``),
    ``render_mode`` and ``repeat_action_probability``.  ``ale_style``: an id in ale-py's
    style, which takes ale-py's names only."""
    for ale_name, make_name in ALE_TWINS.items():
        if make_name in kwargs and (ale_style or ale_name in kwargs):
            where = f"the ale-py-style id {id_name}" if ale_style else "this env"
            raise ValueError(
                f"{make_name} and ale-py's {ale_name} name the same setting of {where}: pass "
                f"{ale_name} only" + (f" (stori_jax's own {make_name} is the -v0 id's)"
                                      if ale_style else f" or {make_name} only"))
    out = {"obs_type": None, "render_mode": None, "repeat_action_probability": 0.0}
    if "obs_type" in kwargs:
        obs_type = kwargs.pop("obs_type")
        if not isinstance(obs_type, str) or obs_type not in OBS_TYPES:
            raise ValueError(f"obs_type must be one of {list(OBS_TYPES)} (ale-py's), got "
                             f"{obs_type!r}")
        kwargs["obs"] = "ram" if obs_type == "ram" else "raw"
        out["obs_type"] = obs_type
    if "frameskip" in kwargs:
        frameskip = kwargs.pop("frameskip")
        if isinstance(frameskip, tuple):
            raise ValueError(f"frameskip: ale-py's stochastic frame skip {frameskip!r} is not "
                             "supported (STORI steps a fixed number of frames); pass an int")
        kwargs["frame_skip"] = check_int("frameskip", frameskip, 1)
    if "max_num_frames_per_episode" in kwargs:
        frames = kwargs.pop("max_num_frames_per_episode")
        capped = frames is not None and frames != 0  # ALE: 0 is no cap
        kwargs["max_episode_frames"] = (check_int("max_num_frames_per_episode", frames, 1, NO_CAP)
                                        if capped else NO_CAP)
    out["repeat_action_probability"] = check_probability(
        "repeat_action_probability", kwargs.pop("repeat_action_probability", 0.0))
    for name, why in (("full_action_space", "stori_jax plays the game's minimal action set "
                                            "(ale-py's default; the paper's)"),
                      ("continuous", "STORI's actions are discrete"),
                      ("sound_obs", "the workers do not record sound")):
        value = kwargs.pop(name, False)
        if value is not False:
            raise ValueError(f"{name}={value!r} is not supported: {why}; leave it False")
    for name in ("mode", "difficulty"):
        value = kwargs.pop(name, None)
        if value is not None:
            raise ValueError(f"{name}={value!r} is not supported: STORI plays each game's default "
                             f"{name} (the presets are defined on it); leave it None")
    # ale-py uses it with continuous=True only, which is refused above
    kwargs.pop("continuous_action_threshold", None)
    render_mode = kwargs.pop("render_mode", None)
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(f"render_mode must be None or one of {list(RENDER_MODES)}, got "
                         f"{render_mode!r} (for a window, wrap the env in gymnasium's "
                         "HumanRendering; `stori-jax record` writes GIFs)")
    out["render_mode"] = render_mode
    return out


class StoriALE:
    """``env.unwrapped.ale`` of a single stori_jax env: what wrappers call on ale-py's
    ``ALEInterface`` (gymnasium's ``AtariPreprocessing``, CleanRL's and SB3's ``EpisodicLifeEnv``
    ...), answered from the env's last ``reset()`` or ``step()``.  The emulators run in worker
    processes, so nothing here acts on them (no ``act``, ``cloneState``, ``setRAM``).

    Before the first ``reset()``, ``lives()`` and ``game_over()`` answer as ale-py's do (the
    game at power-on: Breakout's 5 lives, not over); the screen and the RAM need a ``reset()``
    (ale-py's power-on frame is not one a STORI episode shows).

    The screen is the observation's: the step's last frame at ``frameskip=1``; with ``frameskip``
    k > 1, the max of the step's last two frames (STORI's raw observation), where ale-py's is the
    last frame alone.  It needs a screen observation (obs_type ``rgb`` or ``grayscale``, or
    ``obs='raw'``)."""

    OFFERS = ("lives", "game_over", "getScreenRGB", "getScreenGrayscale", "getScreenDims",
              "getRAM", "getRAMSize", "getMinimalActionSet", "getLegalActionSet")

    def __init__(self, env: "StoriGymEnv"):
        self._owner = env

    def _last(self, name: str):
        last = self._owner._last
        if last is None:
            raise RuntimeError(f"ale.{name}(): call reset() first (the emulators start there)")
        return last

    def lives(self) -> int:
        if self._owner._last is None:  # before the first reset: the game's at power-on
            return get_game(self._owner._game_name).start_lives
        return int(self._last("lives")["lives"])

    def game_over(self, with_truncation: bool = True) -> bool:
        if self._owner._last is None:  # the game at power-on is not over (ale-py's answer)
            return False
        last = self._last("game_over")
        return bool(last["terminated"] or (with_truncation and last["truncated"]))

    def _screen(self, name: str) -> np.ndarray:
        screen = self._last(name)["screen"]
        if screen is None:
            raise RuntimeError(f"ale.{name}(): this env observes "
                               f"{self._owner._obs_type or self._owner._env.plan.obs!r}, without "
                               "the screen; make it with obs_type='rgb' or 'grayscale' "
                               "(obs='raw' on a -v0 id)")
        return screen

    @staticmethod
    def _into(out, value: np.ndarray) -> np.ndarray:
        if out is None:
            return value.copy()
        np.copyto(out, value.reshape(np.shape(out)))  # ale-py fills a given buffer
        return out

    def getScreenRGB(self, screen_data=None) -> np.ndarray:
        return self._into(screen_data, self._screen("getScreenRGB"))

    def getScreenGrayscale(self, screen_data=None) -> np.ndarray:
        return self._into(screen_data, ale_grayscale(self._screen("getScreenGrayscale")))

    def getScreenDims(self) -> tuple[int, int]:
        return SCREEN_DIMS

    def getRAM(self, ram=None) -> np.ndarray:
        return self._into(ram, self._last("getRAM")["ram"])

    def getRAMSize(self) -> int:
        return 128

    def getMinimalActionSet(self) -> list:
        from ale_py import Action

        return [Action.__members__[name] for name in self._owner.get_action_meanings()]

    def getLegalActionSet(self) -> list:
        from ale_py import Action

        return list(Action.__members__.values())

    def __getattr__(self, name: str):
        raise AttributeError(f"ale.{name}: stori_jax's stand-in for ale-py's ALEInterface offers "
                             f"{', '.join(self.OFFERS)} (the emulators run in worker processes; "
                             "step them with env.step)")
