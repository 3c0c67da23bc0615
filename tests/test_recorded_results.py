"""The recorded evidence is part of the checkout (a fresh clone has it), each PPO run was made
with the hyperparameters the evidence script names, and the committed table is exactly what the
recorded evaluations give."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from baselines.run_evidence import RESULTS as BASELINE_RESULTS

ROOT = Path(__file__).resolve().parents[1]
BENCHMARK_RESULTS = ROOT / "benchmarks" / "results"
PPO_FILES = ("config.json", "log.csv", "episodes.csv", "summary.json", "eval-sampled.json")


def evidence_runs():
    from baselines.run_evidence import RUNS, SEEDS

    return [(game, preset, seed) for game, preset in RUNS for seed in SEEDS]


@pytest.mark.parametrize("game, preset, seed", evidence_runs())
def test_every_evidence_run_is_recorded(game, preset, seed):
    from baselines.run_evidence import run_dir

    ppo = run_dir(game, preset, "ppo", seed)
    missing = [name for name in PPO_FILES if not (ppo / name).is_file()]
    assert not missing, f"{ppo} lacks {missing}"
    assert (run_dir(game, preset, "random", seed) / "eval-random.json").is_file()


@pytest.mark.parametrize("game, preset, seed", evidence_runs())
def test_every_evidence_run_used_the_recorded_hyperparameters(game, preset, seed):
    from baselines.ppo import PPOConfig
    from baselines.run_evidence import EVAL_EPISODES, GAME_HYPERPARAMETERS, run_dir

    recorded = json.loads((run_dir(game, preset, "ppo", seed) / "config.json").read_text())
    expected = PPOConfig(game=game, preset=preset, seed=seed, **GAME_HYPERPARAMETERS[game])
    assert set(recorded) <= set(dataclasses.asdict(expected))
    assert dataclasses.asdict(PPOConfig.from_recorded(recorded)) == dataclasses.asdict(expected)
    evaluation = json.loads((run_dir(game, preset, "ppo", seed) / "eval-sampled.json").read_text())
    assert (evaluation["game"], evaluation["preset"], evaluation["train_seed"],
            evaluation["episodes"]) == (game, preset, seed, EVAL_EPISODES)


def test_the_committed_table_is_what_the_recorded_evaluations_give():
    from baselines.table import aggregate, load_evaluations, markdown

    rebuilt = markdown(aggregate(load_evaluations(BASELINE_RESULTS / "runs")))
    assert rebuilt == (BASELINE_RESULTS / "table.md").read_text()


def test_a_recorded_random_evaluation_replays_from_its_seed():
    """The recorded random-policy evaluations are this code's: the first episode of each of the
    20 envs of Breakout 1 (type-1 action corruption), seed 0, replays exactly, which pins the
    env's random streams, the agent's key and the emulator to the published numbers. Only with
    the jax and ale-py versions that recorded it (other versions may draw or emulate otherwise:
    docs/reproducibility.md)."""
    from importlib.metadata import version

    from baselines.evaluate import evaluate
    from stori_jax.suite import episode_quotas

    from baselines.run_evidence import run_dir

    recorded = json.loads((run_dir("Breakout", "1", "random", 0) / "eval-random.json")
                          .read_text())
    made_with = recorded["software"]["packages"]
    for package in ("jax", "jaxlib", "ale-py"):
        if version(package) != made_with[package]:
            pytest.skip(f"recorded with {package} {made_with[package]}, {version(package)} is "
                        "installed")
    num_envs = recorded["num_envs"]
    replay = evaluate("Breakout", "1", policy="random", episodes=num_envs, num_envs=num_envs,
                      seed=0, progress=False)
    quotas = episode_quotas(recorded["episodes"], num_envs)
    firsts = np.cumsum(quotas) - quotas  # where each env's episodes start in the flat list
    assert replay["eval_seed"] == recorded["eval_seed"]
    assert replay["lengths"] == [recorded["lengths"][i] for i in firsts]
    assert replay["returns"] == [recorded["returns"][i] for i in firsts]


def test_the_readme_shows_the_committed_table():
    readme = (ROOT / "README.md").read_text()
    rows = [line for line in (BASELINE_RESULTS / "table.md").read_text().splitlines()
            if line.startswith("| ") and "---" not in line]
    assert rows and [row for row in rows if row not in readme] == []


@pytest.mark.parametrize("pattern", ["*-vm.json", "*-vm.md", "*-vm*.png", "jax-stages-*.json",
                                     "ppo-rollout-*.json", "ppo-rollout-*.png"])
def test_benchmark_results_are_in_the_checkout(pattern):
    assert list(BENCHMARK_RESULTS.glob(pattern)), f"no {pattern} in {BENCHMARK_RESULTS}"
