"""Bad command-line input: a one-line error naming the argument (exit status 2), found before
any work starts; never a traceback, never silently ignored."""

import json
import pickle

import pytest

from baselines.agents import load_checkpoint
from stori_jax.cli import main

EVAL = dict(game="Breakout", preset="3.1", agent="random", policy="random", train_seed=0,
            mean_return=1.0, episodes=1)


@pytest.fixture
def files(tmp_path):
    """Bad inputs of every kind, by name, in ``tmp_path``."""
    (tmp_path / "afile").write_text("")
    (tmp_path / "adir").mkdir()
    (tmp_path / "bad.json").write_text("{not json")
    (tmp_path / "list.json").write_text("[1, 2]")
    (tmp_path / "twice.json").write_text(  # the second section replaced the first, prob too
        '{"stochasticity_type": "3.2", "partial_observation": {"type": "crop", "mode": "1", '
        '"prob": 1.0}, "partial_observation": {"type": "blackout", "mode": "10"}}')
    (tmp_path / "empty.pkl").write_bytes(b"")
    (tmp_path / "text.pkl").write_text("garbage\n")
    (tmp_path / "list.pkl").write_bytes(pickle.dumps([1, 2]))
    (tmp_path / "nocfg.pkl").write_bytes(pickle.dumps(dict(format="stori-jax-ppo-1",
                                                           params={})))
    (tmp_path / "badcfg.pkl").write_bytes(pickle.dumps(dict(
        format="stori-jax-ppo-1", params={}, config=dict(game="Breakout", gamma=2.0))))
    for name, content in (("num", 5), ("list", [1]), ("types", dict(EVAL, mean_return="abc")),
                          ("seed", dict(EVAL, train_seed=-1)), ("dqn", dict(EVAL, agent="dqn")),
                          ("mixed", dict(EVAL, policy="greedy")),
                          ("episodes", dict(EVAL, episodes=0))):
        (tmp_path / f"tb_{name}").mkdir()
        (tmp_path / f"tb_{name}" / "eval-x.json").write_text(json.dumps(content))
    run = tmp_path / "tb_curve" / "run"
    run.mkdir(parents=True)
    (tmp_path / "tb_curve" / "eval-random.json").write_text(json.dumps(EVAL))
    (run / "config.json").write_text(json.dumps(dict(game="Breakout", preset="3.1", seed=0)))
    (run / "episodes.csv").write_text("a,b\n1,2\n")
    return tmp_path


def run_main(argv, files, capsys):
    status = main([a.replace("D/", f"{files}/") for a in argv])
    err = capsys.readouterr().err.replace(f"{files}/", "D/")
    assert status == 2 and len(err.strip().splitlines()) == 1, err
    return err


@pytest.mark.parametrize("argv, message", [
    (["show", "Breakout", "3.1", "--config", "D/bad.json"], "not both"),
    (["show", "Breakout", "--config", "D/missing.json"], "--config D/missing.json: no such file"),
    (["record", "Breakout", "--config", "D/adir"], "--config D/adir: is a directory"),
    (["show", "Breakout", "--config", "D/bad.json"], "--config D/bad.json is not valid JSON"),
    (["show", "Breakout", "--config", "D/list.json"], "must hold a JSON object"),
    (["record", "Breakout", "--config", "D/twice.json"],
     "--config D/twice.json gives the key 'partial_observation' twice in one object"),
])
def test_config_file_errors_name_the_file(argv, message, files, capsys):
    assert message in run_main(argv, files, capsys)


@pytest.mark.parametrize("argv, message", [
    (["suite", "--out", "D/afile"], "--out D/afile exists and is not a directory"),
    (["show", "Breakout", "3.1", "--out", "D/afile/x.png"], "D/afile is a file, not a directory"),
    (["show", "Breakout", "3.1", "--out", "D/adir"], "--out D/adir exists and is not a file"),
    (["table", "D/tb_curve", "--out", "D/afile"], "--out D/afile exists and is not a directory"),
    (["eval", "--random", "--game", "Breakout", "--preset", "3.1", "--out", "D/afile/sub"],
     "D/afile is a file, not a directory"),
    (["train", "ppo", "--game", "Breakout", "--out", "D/afile"], "--out D/afile exists"),
    # a place nothing can be created in (it failed after the run, naming no flag)
    (["show", "Breakout", "3.1", "--out", "/proc/x.png"], "--out /proc/x.png: cannot write in /proc"),
    (["suite", "--out", "/proc/a/b"], "--out /proc/a/b: cannot write in /proc"),
    (["suite", "--out", "/proc"], "--out /proc: cannot write in /proc"),  # an existing folder
    (["show", "Breakout", "--out", "/proc/version.png"], "cannot write in /proc"),
])
def test_unusable_out_paths_are_refused_up_front(argv, message, files, capsys):
    assert message in run_main(argv, files, capsys)


def test_the_suites_default_out_is_checked_as_a_given_one(files, capsys, monkeypatch):
    """With ./results a file, the default --out failed with a bare "[Errno 20] Not a
    directory" that named no flag."""
    monkeypatch.chdir(files)
    (files / "results").write_text("a file")
    err = run_main(["suite", "--games", "Breakout", "--presets", "3.1", "--quiet"], files, capsys)
    assert "--out (default) results/suite-" in err and "results is a file, not a directory" in err


@pytest.mark.parametrize("name, why", [
    ("empty.pkl", "not a stori-jax checkpoint: D/empty.pkl (unreadable: EOFError"),
    ("bad.json", "not a stori-jax checkpoint: D/bad.json (unreadable: UnpicklingError"),
    ("text.pkl", "not a stori-jax checkpoint: D/text.pkl (unreadable: ValueError"),
    ("list.pkl", "not a stori-jax checkpoint: D/list.pkl (no format marker"),
    ("nocfg.pkl", "not a stori-jax PPO checkpoint: D/nocfg.pkl (lacks ['config']"),
    ("badcfg.pkl", "not a stori-jax PPO checkpoint: D/badcfg.pkl (bad config: gamma must be "
                   "in [0, 1]"),
    ("adir", "not a stori-jax checkpoint: D/adir (a directory; give the checkpoint.pkl in it"),
])
def test_corrupt_checkpoints_say_why(name, why, files, capsys):
    err = run_main(["eval", "--checkpoint", f"D/{name}"], files, capsys)
    assert why in err
    with pytest.raises(ValueError, match="not a stori-jax"):
        load_checkpoint(files / name)


@pytest.mark.parametrize("tree, message", [
    ("tb_num", "eval-x.json must hold a JSON object (a stori-jax evaluation), got int"),
    ("tb_list", "got list"),
    ("tb_types", "eval-x.json: mean_return must be a finite number, got 'abc'"),
    ("tb_seed", "train_seed must be >= 0, got -1"),
    ("tb_dqn", "agent must be one of ['ppo', 'drq', 'random'], got 'dqn'"),
    ("tb_mixed", "policy 'greedy' does not go with agent 'random'"),
    ("tb_episodes", "eval-x.json: episodes must be >= 1, got 0"),
    ("tb_curve", "run/episodes.csv lacks the columns ['global_step', 'return']"),
])
def test_malformed_results_are_named(tree, message, files, capsys):
    err = run_main(["table", f"D/{tree}", "--out", "D/tables"], files, capsys)
    assert f"D/{tree}/" in err and message in err
    assert not (files / "tables" / "table.md").exists(), "found before anything is written"


def test_a_negative_eval_episodes_is_refused_before_training(files, capsys, monkeypatch):
    import baselines.ppo

    monkeypatch.chdir(files)  # nothing is written elsewhere
    monkeypatch.setattr(baselines.ppo, "train", lambda *a, **k: pytest.fail("trained"))
    err = run_main(["train", "ppo", "--game", "Breakout", "--eval-episodes", "-1", "--out",
                    "D/run", "--quiet"], files, capsys)
    assert "--eval-episodes must be >= 0, got -1" in err
    assert not (files / "run").exists()


def test_resume_from_a_checkpoint_without_its_run_state_says_what_is_missing(files, capsys):
    import dataclasses

    from baselines.ppo import PPOConfig

    config = PPOConfig(network="tiny", num_envs=2, num_steps=8, num_minibatches=2,
                       total_steps=16)
    run = files / "run"
    run.mkdir()
    (run / "checkpoint.pkl").write_bytes(pickle.dumps(dict(
        format="stori-jax-ppo-1", config=dataclasses.asdict(config), params={})))
    argv = ["train", "ppo", "--game", "Breakout", "--preset", "3.1", "--steps", "16",
            "--resume", "--out", "D/run"] + [
        a for name in ("network", "num_envs", "num_steps", "num_minibatches")
        for a in ("--set", f"{name}={getattr(config, name)}")]
    err = run_main(argv, files, capsys)
    assert "cannot resume from D/run/checkpoint.pkl: it lacks ['iteration', 'opt_state', " \
           "'key', 'obs', 'envs', 'elapsed_s']" in err


@pytest.mark.parametrize("argv, message", [
    (["suite", "--presets", "3.1", "9"], "--presets: unknown ['9']; allowed: ['1', '2.1'"),
    (["suite", "--games", "gopher", "--presets", "3.2A"],
     "--presets: unknown ['3.2A']; allowed for Gopher: ['1', '2.1', '2.2', '3.1', '3.2']"),
    (["suite", "--seed", "-1"], "--seed must be in [0, 2147483647], got -1"),
    # an absurd batch, refused before any preset runs; train names the whole batch it was set
    (["suite", "--num-envs", "100000000"], "--num-envs 100000000 with frame_skip=4 needs"),
    (["train", "ppo", "--game", "Breakout", "--set", "num_envs=100000000", "--set",
      "num_steps=1", "--steps", "100000000", "--out", "D/big"],
     "num_envs=100000000 with frame_skip=4 needs"),
    (["eval", "--random", "--game", "Breakout", "--preset", "3.1", "--policy", "greedy"],
     "--policy applies to checkpoints only"),
    (["eval", "--random", "--game", "Breakout", "--preset", "3.1", "--seed", "-1"],
     "--seed must be in [0, 2147483647], got -1"),
    (["eval", "--random", "--game", "Breakout", "--preset", "3.1", "--eval-seed", "-2"],
     "--eval-seed must be in [0, 2147483647], got -2"),
    (["show", "Breakout", "3.1", "--steps", "-5"], "--steps must be >= 1, got -5"),
    # flags named as the user typed them (it said seed / total_steps)
    (["suite", "--seed", "3000000000"], "--seed must be in [0, 2147483647], got 3000000000"),
    (["run", "Breakout", "--seed", "3000000000"], "--seed must be in [0, 2147483647]"),
    (["run", "Breakout", "2.1", "--num-envs", "0"], "--num-envs must be >= 1, got 0"),
    (["run", "Breakout", "--num-workers", "-3"], "--num-workers must be >= 0, got -3"),
    (["run", "Breakout", "--num-workers", "5", "--num-envs", "2"],
     "--num-workers must be <= --num-envs (2), got 5"),
    (["run", "Breakout", "--steps", "0"], "--steps must be >= 1, got 0"),
    (["record", "Breakout", "--seed", "2147483648"], "--seed must be in [0, 2147483647]"),
    (["eval", "--random", "--game", "Breakout", "--preset", "3.1", "--eval-seed", "2147483648"],
     "--eval-seed must be in [0, 2147483647], got 2147483648"),
    (["train", "ppo", "--game", "Breakout", "--steps", "0"], "--steps must be >= 1, got 0"),
    (["train", "ppo", "--game", "Breakout", "--seed", "2000000000"],
     "--seed must be in [0, 1073741823], got 2000000000"),
    (["show", "Breakout", "3.1", "--seed", "-1"], "--seed must be in [0, 2147483647], got -1"),
    (["record", "Breakout", "3.1", "--max-steps", "0"], "--max-steps must be >= 1, got 0"),
    (["train", "ppo", "--game", "Breakout", "--set", "learning_rate=inf"],
     "learning_rate must be a finite number >= 0, got inf"),
    (["train", "ppo", "--game", "Breakout", "--set", "ent_coef=nan"],
     "ent_coef must be a finite number >= 0, got nan"),
    (["train", "ppo", "--game", "Breakout", "--set", "network=tiny", "--set", "network=nips"],
     "--set network given twice ('tiny' and 'nips')"),
])
def test_out_of_range_and_ignored_flags_are_refused(argv, message, files, capsys):
    assert message in run_main(argv, files, capsys)
