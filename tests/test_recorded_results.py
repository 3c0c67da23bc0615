"""The recorded evidence is part of the checkout (a fresh clone has it), each PPO run was made
with the hyperparameters the evidence script names, and the committed table is exactly what the
recorded evaluations give."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from baselines.evidence.run_evidence import RESULTS as BASELINE_RESULTS

ROOT = Path(__file__).resolve().parents[1]
BENCHMARK_RESULTS = ROOT / "benchmarks" / "results"
PPO_FILES = ("config.json", "log.csv", "episodes.csv", "summary.json", "eval-sampled.json")


def evidence_runs():
    from baselines.evidence.run_evidence import RUNS, SEEDS

    return [(game, preset, seed) for game, preset in RUNS for seed in SEEDS]


@pytest.mark.parametrize("game, preset, seed", evidence_runs())
def test_every_evidence_run_is_recorded(game, preset, seed):
    from baselines.evidence.run_evidence import run_dir

    ppo = run_dir(game, preset, "ppo", seed)
    missing = [name for name in PPO_FILES if not (ppo / name).is_file()]
    assert not missing, f"{ppo} lacks {missing}"
    assert (run_dir(game, preset, "random", seed) / "eval-random.json").is_file()


@pytest.mark.parametrize("game, preset, seed", evidence_runs())
def test_every_evidence_run_used_the_recorded_hyperparameters(game, preset, seed):
    from baselines.ppo import PPOConfig
    from baselines.evidence.run_evidence import EVAL_EPISODES, GAME_HYPERPARAMETERS, run_dir

    recorded = json.loads((run_dir(game, preset, "ppo", seed) / "config.json").read_text())
    expected = PPOConfig(game=game, preset=preset, seed=seed, **GAME_HYPERPARAMETERS[game])
    assert set(recorded) <= set(dataclasses.asdict(expected))
    assert dataclasses.asdict(PPOConfig.from_recorded(recorded)) == dataclasses.asdict(expected)
    evaluation = json.loads((run_dir(game, preset, "ppo", seed) / "eval-sampled.json").read_text())
    assert (evaluation["game"], evaluation["preset"], evaluation["train_seed"],
            evaluation["episodes"]) == (game, preset, seed, EVAL_EPISODES)


def test_the_committed_table_is_what_the_recorded_evaluations_give():
    from baselines.table import STD_OVER_SEEDS, aggregate, load_evaluations, markdown

    rebuilt = markdown(aggregate(load_evaluations(BASELINE_RESULTS / "runs")))
    assert (BASELINE_RESULTS / "table.md").read_text() == f"{rebuilt}\n{STD_OVER_SEEDS}\n"


def test_the_million_step_runs_used_run_longs_config_and_every_stage_is_evaluated():
    from baselines.ppo import PPOConfig
    from baselines.evidence.run_long import OUT, SEEDS, STAGES, long_config

    runs = {int(run.name.removeprefix("seed")): run for run in (OUT / "runs").glob("seed*")}
    assert sorted(runs) == sorted(SEEDS)
    for seed, run in runs.items():
        missing = [name for name in PPO_FILES if not (run / name).is_file()]
        assert not missing, f"{run} lacks {missing}"
        recorded = PPOConfig.from_recorded(json.loads((run / "config.json").read_text()))
        assert dataclasses.asdict(recorded) == dataclasses.asdict(long_config(seed))
        assert json.loads((run / "summary.json").read_text())["finished"]
        for stage in STAGES:
            steps = stage * recorded.batch_size
            assert (OUT / "by-step" / str(steps) / f"seed{seed}" / "eval-sampled.json").is_file()


def test_the_committed_onset_and_table_of_the_million_step_runs_are_what_they_give():
    from baselines.evidence.run_long import (OUT, SEEDS, evaluations_by_step, onset_table,
                                    random_evaluations)
    from baselines.table import STD_OVER_SEEDS, aggregate, load_evaluations, markdown

    assert (OUT / "onset.md").read_text() == onset_table(evaluations_by_step(OUT),
                                                         random_evaluations(SEEDS))
    table = markdown(aggregate(load_evaluations(OUT / "runs")))
    assert (OUT / "table.md").read_text().startswith(f"{table}\n{STD_OVER_SEEDS}\n")


def _skip_unless_made_with(made_with: dict, packages=("jax", "jaxlib", "ale-py")) -> None:
    from importlib.metadata import version

    for package in packages:
        if version(package) != made_with[package]:
            pytest.skip(f"recorded with {package} {made_with[package]}, {version(package)} is "
                        "installed")


def test_a_recorded_random_evaluation_replays_from_its_seed():
    """The recorded random-policy evaluations are this code's: the first episode of each of the
    20 envs of Breakout 1 (type-1 action corruption), seed 0, replays exactly, which pins the
    env's random streams, the agent's key and the emulator to the published numbers. Only with
    the jax and ale-py versions that recorded it (other versions may draw or emulate otherwise:
    docs/reproducibility.md)."""
    from baselines.evaluate import evaluate
    from baselines.evidence.run_evidence import run_dir
    from stori_jax.suite import episode_quotas

    recorded = json.loads((run_dir("Breakout", "1", "random", 0) / "eval-random.json")
                          .read_text())
    _skip_unless_made_with(recorded["software"]["packages"])
    num_envs = recorded["num_envs"]
    replay = evaluate("Breakout", "1", policy="random", episodes=num_envs, num_envs=num_envs,
                      seed=0, progress=False)
    quotas = episode_quotas(recorded["episodes"], num_envs)
    firsts = np.cumsum(quotas) - quotas  # where each env's episodes start in the flat list
    assert replay["eval_seed"] == recorded["eval_seed"]
    assert replay["lengths"] == [recorded["lengths"][i] for i in firsts]
    assert replay["returns"] == [recorded["returns"][i] for i in firsts]


def _replay_first_iterations(recorded_run: Path, iterations: int, out: Path) -> list[dict]:
    """Train the recorded run's config again for ``iterations`` into ``out`` and check its log
    against the recorded one: the same episodes, the same losses (each later rollout acts with
    the updated policy, so this pins the update too).  Losses to a relative 1e-3 (atol 1e-6),
    the clip fraction to 4 samples of the update's batch x epochs: another CPU rounds floats
    otherwise (an AMD EPYC, against the CPU that recorded the runs: up to 4e-5 relative in
    Breakout's first four iterations, 7e-4 in the approx_kl of Boxing's first Nature-CNN
    update, where one sample of 4096 also crossed the clip); an update written otherwise moves
    them by more (the advantages' ddof alone, by 2e-3).  Only with the jax, flax, optax and
    ale-py versions that recorded it.  Returns the recorded episodes it replayed."""
    import csv

    from baselines.ppo import TIMING_FIELDS, PPOConfig, train

    summary = json.loads((recorded_run / "summary.json").read_text())
    _skip_unless_made_with(summary["software"]["packages"],
                           ("jax", "jaxlib", "ale-py", "flax", "optax"))
    config = PPOConfig.from_recorded(json.loads((recorded_run / "config.json").read_text()))
    train(config, out, progress=False, stop_after=iterations)
    one_sample = 1 / (config.batch_size * config.update_epochs)  # of the clip fraction

    def rows(path, keep):
        with open(path, newline="") as f:
            return [row for row in csv.DictReader(f) if keep(row)]

    def learning(row):
        return {k: v for k, v in row.items() if k not in TIMING_FIELDS}

    logged = rows(recorded_run / "log.csv", lambda r: int(r["iteration"]) <= iterations)
    replayed = rows(out / "log.csv", lambda r: True)
    assert len(logged) == iterations
    assert [r.keys() for r in replayed] == [r.keys() for r in logged]
    for got, want in zip(replayed, logged, strict=True):
        for field, value in learning(want).items():
            if value and got[field]:
                rtol, atol = (0, 4 * one_sample) if field == "clipfrac" else (1e-3, 1e-6)
                np.testing.assert_allclose(float(got[field]), float(value), rtol=rtol,
                                           atol=atol, err_msg=field)
            else:
                assert got[field] == value, field
    last_step = int(logged[-1]["global_step"])
    recorded_episodes = rows(recorded_run / "episodes.csv",
                             lambda r: int(r["global_step"]) <= last_step)
    assert rows(out / "episodes.csv", lambda r: True) == recorded_episodes
    return recorded_episodes


def test_a_recorded_ppo_run_replays_its_first_iterations_from_its_seed(tmp_path):
    """The recorded PPO runs are this code's: Breakout 3.1 seed 0, trained again for three
    iterations from its recorded config, logs the same 11 episodes (the first ones end in the
    third) and the same losses."""
    from baselines.evidence.run_evidence import run_dir

    episodes = _replay_first_iterations(run_dir("Breakout", "3.1", "ppo", 0), 3, tmp_path)
    assert len(episodes) == 11
    assert sum(float(r["return"]) > 0 for r in episodes) >= 6  # a test of the returns


@pytest.mark.slow  # the Nature CNN's update at 8 x 128: ~50 s on 2 cores
def test_a_recorded_million_step_run_replays_its_first_iteration_from_its_seed(tmp_path):
    """The 1M-step Boxing runs (run_long.py) are this code's too: seed 0's first iteration of
    CleanRL's defaults (the Nature CNN, 4 epochs of 4 minibatches) logs the same losses (no
    Boxing episode ends in its 128 steps per env).  One iteration: on another CPU the second
    already drifts by percents (its rollout acts with a policy whose update's clipping the
    first one's rounding moved: clipfrac 0.0154 against 0.0183 on an AMD EPYC)."""
    from baselines.evidence.run_long import OUT

    assert _replay_first_iterations(OUT / "runs" / "seed0", 1, tmp_path) == []


def _rows_missing_from(readme: Path, table: Path) -> list[str]:
    """The markdown ``table``'s rows (header included) that ``readme`` does not show; the
    table must have some."""
    rows = [line for line in table.read_text().splitlines()
            if line.startswith("| ") and "---" not in line]
    assert rows, f"{table} has no rows"
    return [row for row in rows if row not in readme.read_text()]


def test_the_readme_shows_the_committed_table():
    assert _rows_missing_from(ROOT / "README.md", BASELINE_RESULTS / "table.md") == []


def test_the_million_step_readme_shows_the_committed_onset():
    from baselines.evidence.run_long import OUT

    assert _rows_missing_from(OUT / "README.md", OUT / "onset.md") == []


RECORDED_EVALUATIONS = sorted((ROOT / "baselines" / "results").rglob("eval-*.json"))


@pytest.mark.parametrize("path", RECORDED_EVALUATIONS, ids=lambda p: str(p.relative_to(ROOT)))
def test_a_recorded_evaluations_numbers_are_its_own_episodes(path):
    """The table reads each evaluation's mean_return, the replays check only each env's first
    episode: an episode's return edited in the file would pass both unless its mean and std
    are what the file's own returns give."""
    e = json.loads(path.read_text())
    returns = np.asarray(e["returns"], np.float64)
    assert len(e["returns"]) == len(e["lengths"]) == e["episodes"]
    assert e["mean_return"] == float(np.mean(returns))
    assert e["std_return"] == pytest.approx(float(np.std(returns)), rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("where", ["", "boxing-1M"])
def test_the_committed_table_json_is_what_the_recorded_evaluations_give(where):
    from baselines.table import STD_OVER_SEEDS, aggregate, load_evaluations

    out = BASELINE_RESULTS / where
    recorded = json.loads((out / "table.json").read_text())
    rebuilt = json.loads(json.dumps(aggregate(load_evaluations(out / "runs"))))  # as written
    assert recorded["rows"] == rebuilt and recorded["std"] == STD_OVER_SEEDS


def markdown_tables(text: str) -> list[list[dict]]:
    """Every markdown table of ``text``, each as its rows keyed by the header."""
    tables, block = [], []
    for line in text.splitlines() + [""]:
        if line.startswith("|"):
            block.append([cell.strip() for cell in line.strip().strip("|").split("|")])
        elif block:
            tables.append([dict(zip(block[0], row)) for row in block[2:]])
            block = []
    return tables


SWEEP_ROWS = {  # a row of benchmarks/README.md's Breakout 3.1 table -> (run, obs, ratio)
    "`atari84` / best peer (84x84 gray x4), two chunks": ("2026-11-29-vm-chunks2-no-naive",
                                                        "atari84", "vs_best_peer"),
    "`atari84` / best peer, one chunk (before)": ("2026-11-29-vm-before-Breakout-3.1-no-naive",
                                                 "atari84", "vs_best_peer"),
    "`raw` / emulator limit, two chunks": ("2026-11-29-vm-chunks2-no-naive", "raw", "vs_limit"),
    "`raw` / emulator limit, one chunk (before)": ("2026-11-29-vm-before-Breakout-3.1-no-naive",
                                                  "raw", "vs_limit"),
}


def test_the_breakout_sweep_the_benchmarks_readme_shows_is_the_recorded_one():
    """Every ratio of the batch-size sweep benchmarks/README.md quotes is its recorded run's."""
    (rows,) = [table for table in markdown_tables((ROOT / "benchmarks/README.md").read_text())
               if table and "Breakout 3.1" in table[0]]
    assert {row["Breakout 3.1"] for row in rows} == set(SWEEP_ROWS)
    for row in rows:
        stem, obs, ratio = SWEEP_ROWS[row["Breakout 3.1"]]
        recorded = json.loads((BENCHMARK_RESULTS / f"{stem}.json").read_text())["results"]
        for b in (8, 32, 64):
            (r,) = [r for r in recorded if (r["kind"], r["game"], r["preset"], r["backend"],
                                            r["obs"], r["B"]) == ("stori-jax", "Breakout", "3.1",
                                                                  "subproc", obs, b)]
            assert row[f"B = {b}"] == f"{r[ratio]:.2f}", (row["Breakout 3.1"], b)


@pytest.mark.parametrize("stem", ["2026-11-22-vm", "2026-11-24-vm-3.1-2.2",
                                  "2026-11-29-vm-chunks2-no-naive",
                                  "2026-11-29-vm-before-Breakout-3.1-no-naive",
                                  "2026-12-02-vm-quick-no-naive"])
def test_a_committed_throughput_table_is_its_json(stem):
    """The .md beside a throughput run's JSON shows its numbers, row for row (the older file
    has fewer columns: each column it has is checked)."""
    recorded = json.loads((BENCHMARK_RESULTS / f"{stem}.json").read_text())["results"]
    (rows,) = [table for table in markdown_tables((BENCHMARK_RESULTS / f"{stem}.md").read_text())
               if table and "kind" in table[0]]
    assert len(rows) == len(recorded)
    for row, r in zip(rows, recorded):
        assert (row["kind"], row["game"], row["preset"], row["backend"], row["obs"],
                int(row["B"])) == (r["kind"], r["game"], r["preset"], r["backend"], r["obs"],
                                   r["B"])
        assert row["steps/s"] == f"{r['steps_per_s']:.0f}", (stem, row)
        assert row["vs limit"] == (f"{r['vs_limit']:.2f}" if "vs_limit" in r else "-"), row


def test_the_committed_xla_rollout_table_is_its_json(monkeypatch):
    from test_benchmarks import script

    xla_rollout = script(monkeypatch, "xla_rollout")
    stem = BENCHMARK_RESULTS / "xla-rollout-2026-11-23-Breakout-3.1"
    recorded = json.loads(stem.with_name(stem.name + ".json").read_text())
    c = recorded["config"]
    assert xla_rollout.markdown(c["game"], c["preset"], c["steps"], recorded["results"]) == \
        stem.with_name(stem.name + ".md").read_text()


@pytest.mark.parametrize("pattern", ["*-vm.json", "*-vm.md", "*-vm*.png", "jax-stages-*.json",
                                     "ppo-rollout-*.json", "ppo-rollout-*.png"])
def test_benchmark_results_are_in_the_checkout(pattern):
    assert list(BENCHMARK_RESULTS.glob(pattern)), f"no {pattern} in {BENCHMARK_RESULTS}"
