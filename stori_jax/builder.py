"""``stori_jax.make``: the settings checked, the worker split chosen, the backend built.

Each step is a small function of its own (testable alone); :func:`make` runs them in order.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import os

import numpy as np

from stori_jax.backends.layout import SCREEN, shared_bytes
from stori_jax.checks import MAX_INT32, MAX_SEED, check_int
from stori_jax.config import GRANULARITIES, Config
from stori_jax.fork_guard import refuse_if_forked_after_jax
from stori_jax.games import get_game
from stori_jax.pixels import OBSERVATION_LAYOUTS
from stori_jax.plan import OBS_KINDS, SCREENLESS_OBS, Plan, compile_plan
from stori_jax.presets import preset as get_preset

BACKENDS = ("subproc", "envpool")
FRAME_SKIP = 4  # make's default: emulator frames per agent step
MAX_EPISODE_FRAMES = 108_000  # make's default cap: 30 minutes of play at 60 frames a second


def make(game: str, preset: str | None = None, *, config: Config | None = None,
         num_envs: int, seed: int, backend: str = "subproc", num_workers: int | None = None,
         obs: str | None = None, frame_skip: int = FRAME_SKIP, granularity: str | None = None,
         max_episode_frames: int = MAX_EPISODE_FRAMES, noop_max: int = 0, autoreset: bool = True,
         inline_envs: int | None = None, frame_work: str | None = None):
    """A batched STORI environment of ``num_envs`` emulators.

    Args:
        game: Breakout, Boxing, Gopher, BankHeist, or any other ale-py game (without a preset).
        preset: a paper preset of ``game`` (``stori_jax.list_presets()``), or
        config: a :class:`stori_jax.Config`; neither means 3.1 (no stochasticity).
        num_envs, seed: the batch size and the run's seed (in [0, 2^31 - 1]).
        backend: ``subproc`` (every mode) or ``envpool`` (see docs/semantics.md).
        num_workers, inline_envs: emulator processes, and envs emulated in this process while
            they run; by default one worker per core but one, and this process an equal
            share (``num_workers=0``: every env here).  The split changes the speed only: a
            seed gives the same run with any.
        obs: ``raw`` (210x160x3), ``atari84`` (84x84 gray, 4 stacked; the default), ``dreamer64``
            (64x64 RGB) or ``ram`` (the 128 RAM bytes; the only choice for type 0).
        frame_skip, granularity: emulator frames per agent step; perturbations per ``frame``
            (the reference's) or per agent ``step`` (overrides the config's).
        max_episode_frames, noop_max: the episode cap in emulator frames; up to this many NOOP
            frames after each reset (drawn from the seed).
        autoreset: an ended episode's env returns its next episode's first observation in the
            same step (``info["final_obs"]`` holds the last one); False: on the next step.
        frame_work: where an unmasked screen becomes the observation (max-pool, luma, resize):
            ``workers`` (each emulating process, for its own envs: only the observation
            crosses between processes), ``caller`` (JAX in this process, on the whole batch),
            or None: ``workers`` where JAX's default device is the CPU, else ``caller``.  The
            bits are the same either way.

    Returns:
        an :class:`stori_jax.Env`.

    Raises:
        ValueError: a bad argument, named with the values allowed.
    """
    from stori_jax.env import Env

    refuse_if_forked_after_jax("stori_jax.make")
    spec = get_game(game)
    cfg = settle_config(spec, resolve_config(game, preset, config), granularity)
    settings = check_settings(num_envs=num_envs, seed=seed, autoreset=autoreset,
                              frame_skip=frame_skip, max_episode_frames=max_episode_frames,
                              noop_max=noop_max)
    obs = resolve_obs(cfg, obs, spec.name)
    if spec.screen_height != SCREEN[0] and obs not in SCREENLESS_OBS:
        raise ValueError(f"{spec.name}'s screen has {spec.screen_height} rows; stori-jax's screen "
                         f"observations are {SCREEN[0]} x {SCREEN[1]}: use obs one of "
                         f"{list(SCREENLESS_OBS)} for it")
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {list(BACKENDS)}, got {backend!r}")
    if backend == "subproc":
        check_memory(num_envs, frame_skip, screens=obs not in SCREENLESS_OBS,
                     final=bool(autoreset))
    else:  # envpool's buffers hold a screen per env whatever obs is
        check_memory(num_envs, frame_skip, buffers="envpool's frame buffers")
    plan = compile_plan(cfg, spec, num_envs=settings["num_envs"], frame_skip=frame_skip,
                        obs=obs, noop_max=settings["noop_max"], autoreset=settings["autoreset"])
    if backend == "envpool":
        plan, emulators = build_envpool(plan, settings["seed"], settings["max_episode_frames"],
                                        num_workers=num_workers, inline_envs=inline_envs,
                                        frame_work=frame_work)
    else:
        plan, emulators = build_subproc(plan, settings["seed"], settings["max_episode_frames"],
                                        num_workers=num_workers, inline_envs=inline_envs,
                                        frame_work=resolve_frame_work(frame_work))
    return Env(plan, cfg, settings["seed"], emulators)


def resolve_config(game: str, preset: str | None, config: Config | None) -> Config:
    """The config ``make`` was asked for: a preset of ``game``, a Config, or 3.1."""
    if preset is not None and config is not None:
        raise ValueError("pass either preset or config, not both")
    if config is None:
        return get_preset(game, preset) if preset is not None else Config()
    if not isinstance(config, Config):
        raise ValueError(f"config must be a stori_jax.Config, got {type(config).__name__}")
    return config


def sticky_actions_config(game: str, preset: str | None, config, prob: float,
                          granularity: str | None = None):
    """The Config of ``preset`` (or ``config``) with ALE's sticky actions at ``prob``
    (ale-py's and envpool's ``repeat_action_probability``): STORI's type 1
    ``ActionNoise(prob, sticky=True)`` at ``frame`` granularity, which repeats the previous
    executed action on each emulator frame with probability ``prob`` (NOOP after a reset), as
    ALE does.  A config that already corrupts actions, or draws per agent step, is refused:
    two action channels, or sticky actions per step, would not be ALE's."""
    from stori_jax.config import ActionNoise

    cfg = resolve_config(game, preset, config)
    what = (f"repeat_action_probability={prob!r} (ALE's sticky actions, STORI's type 1 "
            "ActionNoise(p, sticky=True))")
    noise = [part for _, part, _ in cfg.components() if isinstance(part, ActionNoise)]
    if noise:
        raise ValueError(f"{what}: this {'preset' if preset else 'config'} already corrupts "
                         f"actions ({cfg.describe()}): the env's action noise is STORI's type 1; "
                         "leave repeat_action_probability 0, or pass a Config with the action "
                         "noise you want")
    if (granularity or cfg.granularity) != "frame":
        raise ValueError(f"{what}: ALE repeats actions per emulator frame, and this env draws "
                         "per agent step (granularity 'step'); use granularity 'frame'")
    return cfg.replace(action_noise=ActionNoise(prob, sticky=True))


def settle_config(spec, cfg: Config, granularity: str | None) -> Config:
    """``cfg`` checked against the game (its modes, a bound game) with ``granularity``'s
    override applied (it covers a drift's concept 2 too)."""
    if cfg.game is not None and get_game(cfg.game) is not spec:
        raise ValueError(f"config is bound to game {cfg.game!r} but make() was asked for "
                         f"{spec.name!r}")
    cfg.for_game(spec.name)  # the game's modes, the drift's secondary included, or a clear error
    if granularity is None:
        return cfg
    if granularity not in GRANULARITIES:
        raise ValueError(f"granularity must be one of {list(GRANULARITIES)} or None, "
                         f"got {granularity!r}")
    drift = cfg.drift
    if drift is not None:  # concept 2's field back to the default, so that the override holds
        drift = dataclasses.replace(drift, secondary=drift.secondary.replace(
            granularity="frame"))
    return cfg.replace(granularity=granularity, drift=drift)


def check_settings(*, num_envs, seed, autoreset, frame_skip, max_episode_frames,
                   noop_max) -> dict:
    """The scalar settings of ``make``, checked (a ValueError names the bad one)."""
    num_envs = check_int("num_envs", num_envs, 1)
    seed = check_int("seed", seed, 0, MAX_SEED)
    if not isinstance(autoreset, (bool, np.bool_)):
        raise ValueError(f"autoreset must be True or False, got {autoreset!r}")
    return dict(num_envs=num_envs, seed=seed, autoreset=bool(autoreset),
                frame_skip=check_int("frame_skip", frame_skip, 1),
                max_episode_frames=check_int("max_episode_frames", max_episode_frames, 1,
                                             MAX_INT32),
                noop_max=check_int("noop_max", noop_max, 0, MAX_INT32 - 1))


def resolve_obs(cfg: Config, obs: str | None, game: str | None = None) -> str:
    """The observation kind: the default for ``cfg`` (``ram`` for type 0, else ``atari84``),
    or ``obs`` checked against what ``cfg`` (and ``game``) can show."""
    if obs is None:
        return "ram" if cfg.ram_observation else "atari84"
    if obs not in OBS_KINDS:
        raise ValueError(f"obs must be one of {list(OBS_KINDS)}, got {obs!r}")
    if cfg.ram_observation and obs not in SCREENLESS_OBS:
        raise ValueError(f"type 0 (ram_observation) observes the RAM: obs must be one of "
                         f"{list(SCREENLESS_OBS)}, got {obs!r}")
    if obs in SCREENLESS_OBS and any(name == "observation" for name, _, _ in cfg.components()):
        where = "Config.observation" if cfg.observation is not None \
            else "Config.drift.secondary.observation"
        raise ValueError(f"obs={obs!r} cannot show an observation mask (type 3.2, {where}); "
                         "use a screen obs")
    if obs == "objects" and game is not None:
        from stori_jax.objects import check_classes

        check_classes(game, (), "obs='objects'")  # the game has an object table
    return obs


def worker_split(num_envs: int, num_workers: int | None, inline_envs: int | None, *,
                 daemonic: bool, cores: int) -> tuple[int, int]:
    """(worker processes, envs emulated in the calling process) of a batch, from the user's
    choices (None: the default) and the machine.  ``daemonic``: the caller may start no
    process (the default is then every env here)."""
    daemonic_default = num_workers is None and daemonic
    if daemonic_default:
        num_workers = 0
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
        return 0, num_envs
    if inline_envs is not None:  # every worker needs at least one env
        inline_envs = check_int("inline_envs", inline_envs)
        if not 0 <= inline_envs < num_envs:
            raise ValueError(f"inline_envs must be in [0, num_envs - 1 = {num_envs - 1}] with "
                             "worker processes (each needs an env; num_workers=0 emulates all "
                             f"{num_envs} here), got {inline_envs}")
    if num_workers is None:
        num_workers, default_inline = default_split(num_envs, cores)
        if inline_envs is None:
            inline_envs = default_inline
        else:  # the envs left to the workers bound how many there can be (one at least)
            num_workers = min(max(num_workers, 1), num_envs - inline_envs)
    inline_envs = inline_envs or 0
    if num_workers > num_envs:
        raise ValueError(f"num_workers must be <= num_envs ({num_envs}), got {num_workers}")
    if num_workers + inline_envs > num_envs:
        raise ValueError(f"num_workers ({num_workers}) + inline_envs ({inline_envs}) must be "
                         f"<= num_envs ({num_envs}): every worker needs at least one env")
    return num_workers, inline_envs


def default_split(num_envs: int, cores: int) -> tuple[int, int]:
    """(worker processes, envs emulated in this process) for a batch on ``cores`` cores: a
    single env here, else one worker per core but one, and this process an equal share (a smaller share, to leave this
    process time for its JAX work, measured slower on 2 cores: benchmarks/README.md)."""
    if num_envs < 2:  # one env: emulated here, as ale-py's own env is (no process to start)
        return 0, num_envs
    if cores < 2:
        return 1, 0
    workers = min(cores - 1, num_envs - 1)
    return workers, num_envs // (workers + 1)


FRAME_WORK = ("workers", "caller")


def resolve_frame_work(frame_work: str | None) -> str:
    """``frame_work`` checked, or its default: the emulating processes where JAX computes on
    the CPU (there the caller's cores are the emulators' cores), else the accelerator."""
    if frame_work is None:
        import jax

        return "workers" if jax.default_backend() == "cpu" else "caller"
    if frame_work not in FRAME_WORK:
        raise ValueError(f"frame_work must be one of {list(FRAME_WORK)} or None (by JAX's "
                         f"default device), got {frame_work!r}")
    return frame_work


def subproc_frames_layout(plan: Plan, frame_work: str) -> str:
    """How the emulating processes hand over their screens (stori_jax.pixels): both screens
    where a mask is drawn per frame, the observation itself where they make it (no pixel mask
    to apply first), else the max-pooled screen."""
    if not plan.screens or plan.needs_both_screens:
        return "pair"
    pixel_mask = plan.mask is not None and plan.mask.kind != "ram"
    if frame_work == "workers" and plan.obs in OBSERVATION_LAYOUTS and not pixel_mask:
        return plan.obs
    return "pooled"


def build_subproc(plan: Plan, seed: int, max_episode_frames: int, *, num_workers,
                  inline_envs, frame_work: str = "workers"):
    """(plan with its frames layout, the subproc backend) of a checked plan."""
    from stori_jax.backends.subproc import SubprocBackend

    num_workers, inline_envs = worker_split(plan.num_envs, num_workers, inline_envs,
                                            daemonic=multiprocessing.current_process().daemon,
                                            cores=available_cores())
    wants_screens = plan.screens
    plan = dataclasses.replace(plan, frames_layout=subproc_frames_layout(plan, frame_work))
    event, mask = plan.event, plan.mask
    backend = SubprocBackend(
        game=plan.game, seeds=emulator_seeds(seed, plan.num_envs), num_workers=num_workers,
        frame_skip=plan.frame_skip, per_frame=plan.per_frame,
        event_mode=event.mode if event and not event.ram_event else None,
        ram_event=event.ram_event if event else None, event_prob=event.prob if event else 0.0,
        ram_obs_mode=mask.mode if mask is not None and mask.kind == "ram" else None,
        want_screens=wants_screens, max_episode_frames=max_episode_frames,
        autoreset=plan.autoreset, frames_layout=plan.frames_layout, inline_envs=inline_envs,
        want_screen_ram=plan.needs_screen_ram)
    return plan, backend


def build_envpool(plan: Plan, seed: int, max_episode_frames: int, *, num_workers,
                  inline_envs, frame_work=None):
    """(plan with envpool's frames layout, the envpool backend); a ValueError names what
    needs the subproc backend."""
    for name, value in (("num_workers", num_workers), ("inline_envs", inline_envs),
                        ("frame_work", frame_work)):
        if value is not None:
            raise ValueError(f"{name} applies to backend='subproc' only (envpool runs its "
                             f"own threads); leave it None, got {value!r}")
    from stori_jax.backends.envpool import FRAMES_LAYOUT, make_envpool_backend

    plan = dataclasses.replace(plan, frames_layout=FRAMES_LAYOUT)
    return plan, make_envpool_backend(plan, seed, max_episode_frames)


def emulator_seeds(seed: int, num_envs: int) -> list[int]:
    """ALE seeds of envs 0..B-1: a function of the seed and the env index alone."""
    from stori_jax.backends.emulator import emulator_seed

    return [emulator_seed(seed, i) for i in range(num_envs)]


def check_memory(num_envs: int, frame_skip: int, screens: bool = True,
                 buffers: str = "shared buffers", flag: str | None = None,
                 final: bool = True) -> None:
    """Refuse a batch whose shared buffers alone would not fit in this machine's memory, before
    anything is allocated.  ``buffers`` names them in the error (envpool's are estimated by
    the subproc backend's, a lower bound); ``flag``: the command-line flag that set num_envs;
    ``final`` (autoreset): the buffers of the ended episodes' screens too."""
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


def available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1
