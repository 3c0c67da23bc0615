"""What other packages plug into stori-jax: commands for ``stori-jax`` and trained policies.

The library knows no agent.  A plugin is any object (usually a module) that a package names
under the entry-point group ``stori_jax.plugins`` in its metadata, e.g. in pyproject.toml::

    [project.entry-points."stori_jax.plugins"]
    baselines = "baselines.plugin"

It may define either or both of:

- ``add_commands(subparsers)``: add sub-commands to ``stori-jax``; each sets its handler with
  ``parser.set_defaults(handler=fn)``, ``fn(args) -> exit code``.
- ``trained_policy(path) -> TrainedPolicy | None``: the policy of a checkpoint file it
  recognises (None for a file that is not one of its own), for ``stori-jax suite
  --checkpoint``.
"""

from __future__ import annotations

import dataclasses
from importlib.metadata import entry_points
from pathlib import Path
from typing import Callable

GROUP = "stori_jax.plugins"


@dataclasses.dataclass(frozen=True)
class TrainedPolicy:
    """A trained agent's policy, as a checkpoint gives it.

    ``act(obs, key) -> (B,) int32`` actions for a batch of observations (``obs`` is what
    ``stori_jax.make(game, preset, obs=self.obs)`` returns).  ``train_env_seeds``: the env seeds
    training played, which an evaluation must not replay; ``eval_seed``: the env seed the
    agent's own evaluation uses by default."""

    agent: str
    game: str
    seed: int
    eval_seed: int
    train_env_seeds: tuple[int, ...]
    act: Callable
    obs: str = "atari84"


def plugins() -> list:
    """Every installed plugin (loaded), in the order of their names."""
    found = sorted(entry_points(group=GROUP), key=lambda ep: ep.name)
    return [ep.load() for ep in found]


def add_commands(subparsers) -> None:
    """Let every plugin add its sub-commands to the ``stori-jax`` parser."""
    for plugin in plugins():
        if hasattr(plugin, "add_commands"):
            plugin.add_commands(subparsers)


def trained_policy(path: Path) -> TrainedPolicy:
    """The policy of the checkpoint at ``path``, from the first plugin that recognises it.

    Raises:
        ValueError: no file there, or no installed plugin recognises it."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"checkpoint {path} " + ("is a directory, not a checkpoint file"
                                                  if path.is_dir() else "does not exist"))
    loaders = [p for p in plugins() if hasattr(p, "trained_policy")]
    for plugin in loaders:
        policy = plugin.trained_policy(path)
        if policy is not None:
            return policy
    raise ValueError(f"{path} is not a checkpoint of any installed agent plugin "
                     f"({len(loaders)} installed; see stori_jax.plugins)")
