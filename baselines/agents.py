"""The agents the commands know (``stori-jax train NAME``, ``eval``, ``table``, ``grid``,
``suite --checkpoint``): one :class:`Agent` record each, defined beside its algorithm
(``baselines/ppo.py``'s ``AGENT``) and named here once.  A new agent is one file with an
``AGENT`` and one line in :data:`AGENT_MODULES`; no command special-cases any agent."""

from __future__ import annotations

import dataclasses
import importlib
from pathlib import Path
from typing import Callable

# name -> the module that defines its AGENT (imported on first use: the commands start fast)
AGENT_MODULES = {"ppo": "baselines.ppo", "drq": "baselines.drq"}
RANDOM = "random"  # the uniformly random policy: evaluated, never trained
# what the agents import beyond the library: pyproject.toml's "agents" extra
AGENT_PACKAGES = ("flax", "optax", "flashbax", "matplotlib")


@dataclasses.dataclass(frozen=True)
class Agent:
    """What the commands need of a trainable agent.

    ``config_class``: a frozen dataclass with fields ``game``, ``preset``, ``seed`` and
    ``total_steps`` (agent steps) beside its hyperparameters, and classmethods
    ``from_overrides(base, {field: text})`` and ``from_recorded(dict)``.
    ``train(config, out, *, resume=False, progress=True, stop_after=None) -> summary`` writes
    the run folder (config.json, log.csv, episodes.csv, checkpoint.pkl, summary.json); the
    summary has ``agent_steps``, ``iterations_now``, ``train_seconds``, ``train_sps``,
    ``finished``.  ``stop_after``: stop, with a checkpoint, after that many iterations.
    ``check_checkpoint(payload, path) -> payload``: a payload read from ``path`` (by
    :func:`baselines.runs.read_checkpoint`) with this agent's format, checked (a ValueError
    saying why it is not a usable checkpoint);
    ``policy_of(payload, mode) -> (config, act(obs, key))``, mode ``sampled`` or ``greedy``;
    ``training_progress(payload) -> dict`` (how far the run had trained, for the table);
    ``train_env_seeds(seed) -> tuple``: the env seeds training plays;
    ``steps_per_iteration(config) -> int``: a run trains whole iterations of this many agent
    steps (its ``total_steps`` rounded up to them); ``train``'s summary has
    ``agent_steps_now``, the agent steps this call trained."""

    name: str
    title: str
    config_class: type
    checkpoint_format: str
    train: Callable
    check_checkpoint: Callable
    policy_of: Callable
    training_progress: Callable
    train_env_seeds: Callable
    steps_per_iteration: Callable


def agent_names() -> list[str]:
    """The trainable agents' names."""
    return list(AGENT_MODULES)


def get_agent(name: str) -> Agent:
    """The :class:`Agent` called ``name``.

    Raises:
        ValueError: no such agent (the message lists them)."""
    if name not in AGENT_MODULES:
        raise ValueError(f"unknown agent {name!r}; one of {agent_names()}")
    try:
        return importlib.import_module(AGENT_MODULES[name]).AGENT
    except ModuleNotFoundError as error:
        missing = (error.name or "").split(".")[0]
        if missing not in AGENT_PACKAGES:
            raise
        raise ValueError(f"agent {name!r} needs {missing}, which is not installed: the agents "
                         "are an extra, pip install 'stori-jax[agents]' (or, in a checkout, "
                         "pip install -e '.[agents]')") from None


def load_checkpoint(path: Path) -> tuple[Agent, dict]:
    """(the agent, its loaded payload) of the checkpoint file at ``path``.

    Raises:
        ValueError: not a checkpoint of any agent here."""
    from baselines.runs import read_checkpoint

    payload = read_checkpoint(path)
    for name in AGENT_MODULES:
        agent = get_agent(name)
        if payload["format"] == agent.checkpoint_format:
            return agent, agent.check_checkpoint(payload, path)
    raise ValueError(f"not a stori-jax checkpoint: {path} (format {payload['format']!r} is "
                     f"none of the agents' {[get_agent(n).checkpoint_format for n in AGENT_MODULES]})")
