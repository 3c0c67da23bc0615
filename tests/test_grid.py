"""``stori-jax grid`` on a local Ray: a grid of tiny trials ends with the complete table, a
second run runs nothing again, a bad --set fails only its own trials, and a trial whose
process is killed mid-run resumes from its Tune checkpoint and ends bit-identical to the same
run made by ``stori-jax train`` + ``eval`` alone.  (The multi-node case: test_grid_cluster.py.)

One local Ray serves the module's process (starting one costs seconds on 2 cores)."""

from __future__ import annotations

import csv
import json
import os
import pickle
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from baselines.commands import run_dir
from baselines.grid import cluster
from baselines.grid.cli import report_outcome
from baselines.grid.spec import SPEC_FILE, grid_spec
from baselines.grid.trial import (archive_run, part_bounds, progress, restore_run,
                                  reusable_result, trained_iterations)
from stori_jax.cli import main

ray = pytest.importorskip("ray", reason="the grid runs on Ray Tune (pip install -e '.[ray]')")
tune = pytest.importorskip("ray.tune")
from baselines.grid.tuning import TUNE_DIR, run_grid  # noqa: E402 (imports Ray)

# the Mnih-2013 torso: its update is large enough for XLA's OpenMP-threaded kernels, whose
# rounding changes with OMP_NUM_THREADS (Ray sets it in its workers; the grid undoes that)
SMALL = ["network=nips", "num_envs=4", "num_steps=8", "num_minibatches=2", "update_epochs=1"]
STEPS = 64  # 2 iterations of 4 envs x 8 steps, trained in 2 parts
EVAL = ["--eval-episodes", "1", "--max-episode-frames", "400"]  # episodes cut at 100 steps


@pytest.fixture(scope="module")
def local_ray():
    """The grid's own local Ray (cluster.connect(None)), two CPUs, for the module."""
    assert cluster.connect(None), "a Ray was already running in this process"
    yield
    ray.shutdown()


def read_log(path: Path) -> list[dict]:
    from baselines.ppo import TIMING_FIELDS

    with open(path / "log.csv", newline="") as f:
        return [{k: v for k, v in r.items() if k not in TIMING_FIELDS} for r in csv.DictReader(f)]


def same_run(a: Path, b: Path) -> None:
    """Two run folders hold the same training and evaluation, bit for bit (timings apart)."""
    assert read_log(a) == read_log(b)
    assert (a / "episodes.csv").read_text() == (b / "episodes.csv").read_text()
    assert json.loads((a / "config.json").read_text()) == json.loads(
        (b / "config.json").read_text())
    ca, cb = (pickle.loads((p / "checkpoint.pkl").read_bytes()) for p in (a, b))
    import jax

    assert ca["iteration"] == cb["iteration"]
    for x, y in zip(*(jax.tree.leaves((c["params"], c["opt_state"], c["key"], c["obs"]))
                      for c in (ca, cb)), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    ea, eb = (json.loads((p / "eval-sampled.json").read_text()) for p in (a, b))
    for key in ("returns", "lengths", "mean_return", "std_return", "eval_seed", "episodes",
                "truncated", "agent_steps", "trained_agent_steps"):
        assert ea[key] == eb[key], key


# -- the random policy over presets x seeds ---------------------------------------------------
# (one test per grid: pytest-xdist hands tests to its processes one by one, and a grid shared
# by several tests through a fixture would be run again in each process that gets one)

def test_a_grid_ends_with_the_complete_table_and_running_it_again_runs_nothing(
        local_ray, tmp_path, capsys):
    out = tmp_path / "grid"
    argv = ["grid", "--agent", "random", "--games", "Breakout", "--presets", "1", "3.1",
            "--seeds", "0", "7", *EVAL, "--out", str(out), "--quiet"]
    handler = signal.getsignal(signal.SIGINT)
    assert main(argv) == 0
    # Tune's SIGINT handler does not outlive the grid (Ctrl-C after it stopped nothing)
    assert signal.getsignal(signal.SIGINT) is handler
    table = json.loads((out / "table.json").read_text())
    assert [(r["game"], r["preset"], r["Random"]["seeds"]) for r in table["rows"]] == [
        ("Breakout", "1", [0, 7]), ("Breakout", "3.1", [0, 7])]
    assert (out / "table.md").exists()
    assert json.loads((out / SPEC_FILE).read_text())["runs"] == [
        ["Breakout", "1", 0], ["Breakout", "1", 7], ["Breakout", "3.1", 0], ["Breakout", "3.1", 7]]
    # each trial's file is where `stori-jax eval --random` files it, and what eval gives alone
    from baselines.evaluate import evaluate

    alone = evaluate("Breakout", "3.1", policy="random", episodes=1, seed=7,
                     max_episode_frames=400, progress=False)
    ran = json.loads((run_dir(out, "Breakout", "3.1", "random", 7) / "eval-random.json")
                     .read_text())
    for key in ("returns", "lengths", "mean_return", "eval_seed", "train_seed", "truncated"):
        assert ran[key] == alone[key], key

    # the same command again: Tune restores the experiment, and no trial runs
    evals = sorted(out.rglob("eval-random.json"))
    before = {p: p.stat().st_mtime_ns for p in evals}
    results = sorted((out / TUNE_DIR).rglob("result.json"))
    reported = {p: p.read_text() for p in results}
    capsys.readouterr()
    assert main(argv) == 0
    assert "4 of 4 trials finished (resumed;" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in evals} == before
    assert {p: p.read_text() for p in results} == reported  # no trial reported anything

    # other settings into the same folder: refused
    assert main([a if a != "7" else "13" for a in argv]) == 2
    err = capsys.readouterr().err
    assert f"--out {out} holds a grid of other settings (runs" in err
    assert "run the same command to resume it, or give another --out" in err


# -- PPO: a bad --set, and a trial killed mid-run ---------------------------------------------

class KillOnce(tune.Callback):
    """Kills the process of a trial after it reported its first training part, and removes
    its run folder (as a node's own disk would be lost): the retry must come from Tune's
    checkpoint."""

    def __init__(self):
        self.killed, self.recovered = [], 0

    def on_trial_result(self, iteration, trials, trial, result, **info):
        if not self.killed and result.get("phase") == "train":
            os.kill(result["pid"], signal.SIGKILL)
            shutil.rmtree(result["run_dir"])
            self.killed.append((result["run_dir"], result["agent_steps"]))

    def on_trial_recover(self, iteration, trials, trial, **info):
        self.recovered += 1


@pytest.mark.slow  # Ray trial processes compiling PPO twice: ~70 s on 2 cores
def test_a_bad_set_fails_its_own_trials_and_a_killed_trial_resumes_bit_identical(
        local_ray, tmp_path, capsys):
    """PPO over Breakout 1 and Boxing 1 with action_head=factored, which only Boxing's 18
    actions allow: Breakout's trial fails once, with the agent's message, before Ray starts;
    Boxing's is killed after its first part, resumes from its Tune checkpoint, and ends with
    the files `stori-jax train` + `eval` give alone."""
    out = tmp_path / "grid"
    spec = grid_spec("ppo", games=["Breakout", "Boxing"], presets=["1"], seeds=[0],
                          steps=STEPS, eval_episodes=1, max_episode_frames=400,
                          overrides=SMALL + ["action_head=factored"], parts=2)
    killer = KillOnce()
    outcome = run_grid(spec, out, max_failures=2, progress_bar=False, callbacks=[killer])

    assert list(outcome.finished) == ["Boxing 1 seed 0"]
    assert outcome.failed == {
        "Breakout 1 seed 0": "ValueError: action_head='factored' needs a game that plays ALE's "
                             "full 18 actions (e.g. Boxing, BankHeist); Breakout has 4: use "
                             "action_head='joint'"}
    assert not run_dir(out, "Breakout", "1", "ppo", 0).exists()  # never started
    assert report_outcome(outcome, spec, out) == 1
    err = capsys.readouterr().err
    assert err.count("action_head='factored' needs a game") == 2  # before Ray, and the summary
    assert json.loads((out / "table.json").read_text())["rows"][0]["PPO"]["seeds"] == [0]

    run = run_dir(out, "Boxing", "1", "ppo", 0)
    assert killer.killed == [(str(run), 32)] and killer.recovered == 1
    alone = tmp_path / "alone"  # the same run by `stori-jax train` and `eval` alone
    assert main(["train", "ppo", "--game", "Boxing", "--preset", "1", "--seed", "0",
                 "--steps", str(STEPS), *[a for item in SMALL + ["action_head=factored"]
                                                for a in ("--set", item)],
                 "--out", str(alone), "--quiet"]) == 0
    assert main(["eval", "--checkpoint", str(alone / "checkpoint.pkl"), "--episodes", "1",
                 "--max-episode-frames", "400", "--quiet"]) == 0
    same_run(run, alone)
    summary = json.loads((run / "summary.json").read_text())
    assert summary["finished"] and summary["agent_steps"] == STEPS
    assert outcome.finished["Boxing 1 seed 0"]["eval_mean_return"] == json.loads(
        (alone / "eval-sampled.json").read_text())["mean_return"]


# -- without Ray, and what is checked before Ray starts ---------------------------------

def test_without_ray_the_command_says_how_to_install_it(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    monkeypatch.setitem(sys.modules, "ray.tune", None)
    assert main(["grid", "--agent", "random", "--out", str(tmp_path / "g")]) == 2
    err = capsys.readouterr().err
    assert 'pip install -e ".[ray]"' in err and "Ray Tune" in err
    assert not (tmp_path / "g").exists()


@pytest.mark.parametrize("argv, message", [
    (["--agent", "ppo", "--set", "nonsense=1"], "no trial of the grid can run: unknown PPO "
                                                "hyperparameter 'nonsense'"),
    (["--agent", "random", "--steps", "10"], "--steps: the random policy is not trained"),
    (["--agent", "random", "--set", "network=tiny"], "--set: the random policy has no "
                                                     "hyperparameters"),
    (["--agent", "random", "--seeds", "0", "0"], "--seeds gives [0] more than once"),
    (["--agent", "random", "--presets", "9.9"], "--presets: unknown ['9.9']"),
    (["--agent", "random", "--eval-episodes", "0"], "--eval-episodes must be >= 1"),
    (["--agent", "random", "--cpus-per-run", "0"], "--cpus-per-run must be > 0"),
])
def test_what_cannot_run_is_refused_before_ray_starts(argv, message, tmp_path, capsys,
                                                      monkeypatch):
    monkeypatch.setattr(cluster, "connect", lambda address: pytest.fail("Ray started"))
    assert main(["grid", *argv, "--out", str(tmp_path / "g"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("stori-jax: error") == 1


def test_a_folder_that_is_no_grid_is_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(cluster, "connect", lambda address: pytest.fail("Ray started"))
    (tmp_path / "Breakout-1").mkdir()
    assert main(["grid", "--agent", "random", "--out", str(tmp_path), "--quiet"]) == 2
    assert "holds files but no grid.json: not a grid's folder" in capsys.readouterr().err


# -- the pieces -------------------------------------------------------------------------------

def test_parts_are_whole_iterations_as_even_as_they_go():
    assert part_bounds(98, 4) == [25, 49, 74, 98]
    assert part_bounds(3, 3) == [1, 2, 3]
    assert part_bounds(2, 4) == [1, 2]  # no more parts than iterations
    assert progress(49, [25, 49, 74, 98]) == 2 / 5


def test_a_run_folder_behind_its_tune_checkpoint_is_restored_from_it(tmp_path):
    """The archive replaces a folder that lost its files, is behind it (a file the archive
    lacks does not survive), or holds a damaged checkpoint; a folder as far as the archive
    (shared storage) is kept as it is."""
    from types import SimpleNamespace

    from baselines.runs import save_checkpoint

    agent = SimpleNamespace(check_checkpoint=lambda payload, path: payload,
                            training_progress=lambda p: dict(trained_agent_steps=p["steps"]))
    run = tmp_path / "run"
    save_checkpoint(run / "checkpoint.pkl", dict(format="fake", steps=64))
    (run / "log.csv").write_text("global_step\n32\n64\n")
    saved = tmp_path / "ckpt"
    saved.mkdir()
    archive_run(run, saved, agent_steps=64, per_iteration=32)
    files = {p.name: p.read_bytes() for p in run.iterdir()}
    assert not restore_run(run, saved, agent)  # as far: kept
    shutil.rmtree(run)  # the folder is lost: rebuilt from the archive
    assert restore_run(run, saved, agent)
    assert {p.name: p.read_bytes() for p in run.iterdir()} == files
    save_checkpoint(run / "checkpoint.pkl", dict(format="fake", steps=32))  # behind
    (run / "eval-sampled.json").write_text("{}")  # stale: not in the archive
    assert trained_iterations(run, agent, 32) == 1
    assert restore_run(run, saved, agent)
    assert trained_iterations(run, agent, 32) == 2
    assert {p.name: p.read_bytes() for p in run.iterdir()} == files
    (run / "checkpoint.pkl").write_bytes(b"junk")  # a damaged checkpoint is replaced too
    assert trained_iterations(run, agent, 32) == -1
    assert restore_run(run, saved, agent)
    assert {p.name: p.read_bytes() for p in run.iterdir()} == files


def test_the_cores_of_a_trial_cap_its_emulator_workers(monkeypatch):
    from baselines import ppo, runs

    monkeypatch.delenv(runs.CORES_VARIABLE, raising=False)
    assert runs.workers_within_cores(20) == {}  # make's own default
    monkeypatch.setenv(runs.CORES_VARIABLE, "1")
    assert runs.cores() == 1
    assert runs.workers_within_cores(20) == dict(num_workers=1, inline_envs=0)
    assert ppo.workers_per_half(8) == 1
    monkeypatch.setenv(runs.CORES_VARIABLE, "10000")  # never more than the affinity allows
    assert runs.cores() == len(os.sched_getaffinity(0))
    monkeypatch.setenv(runs.CORES_VARIABLE, "two")
    with pytest.raises(ValueError, match="STORI_JAX_CORES must be a whole number of cores"):
        runs.cores()


def test_an_evaluation_already_there_is_reused_only_if_it_is_the_one_asked_for(tmp_path):
    path = tmp_path / "eval-random.json"
    wanted = dict(game="Breakout", preset="1", policy="random", train_seed=0, episodes=2,
                  max_episode_frames=400)
    assert reusable_result(path, wanted, None) is None
    path.write_text(json.dumps(dict(wanted, mean_return=1.0)))
    assert reusable_result(path, wanted, None)["mean_return"] == 1.0
    with pytest.raises(ValueError, match=r"holds another evaluation \(episodes 2 there, 5 "
                                         r"here\): move it away"):
        reusable_result(path, dict(wanted, episodes=5), None)


# -- the recorded evidence (baselines/evidence/run_grid_evidence.py) -----------------------------------

RECORDED = sorted((Path(__file__).resolve().parents[1] / "baselines" / "results").glob("grid-*"))


@pytest.mark.parametrize("folder", RECORDED, ids=lambda p: p.name)
def test_a_recorded_grid_is_complete_its_own_table_and_the_serial_runs_twin(folder):
    """Each recorded grid holds an evaluation of every run its grid.json lists (made with the
    evidence script's settings), its table is what they give, and the timing file says every
    run came out identical to the same run made serially."""
    from baselines.evidence.run_grid_evidence import GRIDS
    from baselines.table import aggregate, load_evaluations

    timing = json.loads((folder / "timing.json").read_text())
    assert set(timing) == set(GRIDS)
    for name, record in timing.items():
        out = folder / name
        spec = json.loads((out / SPEC_FILE).read_text())
        settings = GRIDS[name]
        assert (spec["agent"], spec["steps"], spec["eval_episodes"], spec["overrides"]) == (
            settings["agent"], settings["steps"], settings["eval_episodes"],
            list(settings["overrides"]))
        evaluations = load_evaluations(out)
        assert sorted((e["game"], e["preset"], e["train_seed"]) for e in evaluations) == sorted(
            tuple(run) for run in spec["runs"])
        assert json.loads((out / "table.json").read_text())["rows"] == json.loads(
            json.dumps(aggregate(evaluations)))
        runs = len(spec["runs"])
        assert record["grid_equals_serial"] == dict(runs=runs, identical=runs, differ=[])
        assert record["speedup"] == pytest.approx(record["serial"]["seconds"]
                                                  / record["grid"]["seconds"])


def test_an_address_where_nothing_listens_is_an_error_that_names_it(tmp_path):
    """--address 127.0.0.1:1 (nothing there) printed Ray's 'Failed to connect to GCS' for
    minutes; now the command stops at once, naming the address, and writes nothing."""
    out = tmp_path / "g"
    argv = [sys.executable, "-m", "stori_jax.cli", "grid", "--agent", "random", "--games",
            "Breakout", "--presets", "1", "--seeds", "0", "--eval-episodes", "1",
            "--address", "127.0.0.1:1", "--out", str(out), "--quiet"]
    started = time.monotonic()
    done = subprocess.run(argv, capture_output=True, text=True, timeout=120)
    assert time.monotonic() - started < 30
    assert done.returncode == 2
    assert "--address 127.0.0.1:1: nothing accepts connections at 127.0.0.1:1" in done.stderr
    assert "Failed to connect to GCS" not in done.stderr and not out.exists()
