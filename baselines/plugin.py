"""The baselines as a stori-jax plugin (entry point ``stori_jax.plugins``, see
:mod:`stori_jax.plugins`): the ``train``, ``eval`` and ``table`` commands, and the policy of
any agent's checkpoint for ``stori-jax suite --checkpoint``; ``grid`` runs ``train`` and ``eval``
over the paper's grid on Ray Tune."""

from __future__ import annotations

from pathlib import Path


def add_commands(subparsers) -> None:
    from baselines.commands import add_parsers
    from baselines.grid.cli import add_parser as add_grid_parser

    add_parsers(subparsers)
    add_grid_parser(subparsers)  # grid: train + eval over games x presets x seeds on Ray Tune


def trained_policy(path: Path):
    """The sampled policy of a checkpoint of any agent here; None for a file that is none."""
    from baselines.agents import load_checkpoint
    from baselines.evaluate import EVAL_SEED_OFFSET
    from baselines.runs import read_checkpoint
    from stori_jax.plugins import TrainedPolicy

    try:
        read_checkpoint(path)
    except ValueError:  # not a checkpoint of the baselines': another plugin's, perhaps
        return None
    agent, payload = load_checkpoint(path)  # one of ours: a damaged one is an error
    config, act = agent.policy_of(payload, "sampled")
    return TrainedPolicy(agent=agent.name, game=config.game, seed=config.seed,
                         eval_seed=config.seed + EVAL_SEED_OFFSET,
                         train_env_seeds=tuple(agent.train_env_seeds(config.seed)), act=act)
