"""stori-jax: the STORI stochastic-Atari benchmark as a JAX-native, vectorized suite.

    import stori_jax
    env = stori_jax.make("Breakout", "2.1", num_envs=8, seed=0)
    obs, info = env.reset()
    obs, reward, terminated, truncated, info = env.step(actions)

Light to import: configuration and game tables load eagerly; the env, rollout and the JAX
functions load on first use (the emulator workers import this package without JAX).
"""

from stori_jax import fork_guard  # noqa: F401 - notes a fork after JAX started
from stori_jax.config import (ActionNoise, Config, ConceptDrift, ObservationMask,  # noqa: F401
                              RamEvent, RandomEvent)
from stori_jax.games import STORI_GAMES, get_game  # noqa: F401
from stori_jax.presets import describe_preset, list_presets, preset  # noqa: F401
from stori_jax.reference_format import config_from_reference  # noqa: F401

__version__ = "0.1.0"

_LAZY = {
    "make": ("stori_jax.builder", "make"),
    "Env": ("stori_jax.env", "Env"),
    "rollout": ("stori_jax.rollout", "rollout"),
    "agent_key": ("stori_jax.core", "agent_key"),
    "Trajectory": ("stori_jax.rollout", "Trajectory"),
    "XlaHandle": ("stori_jax.xla", "XlaHandle"),
    "WorkerError": ("stori_jax.errors", "WorkerError"),
    "EnvClosedError": ("stori_jax.errors", "EnvClosedError"),
    "InterruptedStepError": ("stori_jax.errors", "InterruptedStepError"),
    "ConcurrentUseError": ("stori_jax.errors", "ConcurrentUseError"),
    "EnvStateError": ("stori_jax.errors", "EnvStateError"),
    "Phase": ("stori_jax.env", "Phase"),
    "functional": ("stori_jax.functional", None),
    "metrics": ("stori_jax.metrics", None),
    "ram_event": ("stori_jax.ram_events", "ram_event"),
}

__all__ = ["ActionNoise", "Config", "ConceptDrift", "ObservationMask", "RamEvent", "RandomEvent",
           "STORI_GAMES", "get_game", "describe_preset", "list_presets", "preset",
           "config_from_reference",
           *_LAZY]


def _register_gymnasium_ids() -> None:
    """Register ``stori_jax/<Game>-<preset>-v0`` with gymnasium, except inside emulator workers
    (spawned children that never need it and should start fast)."""
    import multiprocessing
    import sys

    if multiprocessing.parent_process() is None or "gymnasium" in sys.modules:
        from stori_jax.compat.gymnasium import register_all

        register_all()


_register_gymnasium_ids()


def __getattr__(name):
    if name in _LAZY:
        import importlib

        module_name, attr = _LAZY[name]
        module = importlib.import_module(module_name)
        value = module if attr is None else getattr(module, attr)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'stori_jax' has no attribute {name!r}")
