"""rollout() stacking and determinism; the command line's list/run and its errors."""

import subprocess
import sys

import jax
import numpy as np
import pytest

import stori_jax
from stori_jax.cli import main


def random_policy(params, obs, key):
    return jax.random.randint(key, (obs.shape[0],), 0, params["num_actions"])


def test_rollout_stacks_time_major_and_is_deterministic():
    runs = []
    for _ in range(2):
        with stori_jax.make("Breakout", "1", num_envs=3, seed=4, obs="atari84") as env:
            traj = stori_jax.rollout(env, random_policy, {"num_actions": 4},
                                     jax.random.PRNGKey(9), num_steps=6)
        runs.append(traj)
    traj = runs[0]
    assert traj.obs.shape == (6, 3, 84, 84, 4) and traj.last_obs.shape == (3, 84, 84, 4)
    assert traj.action.shape == (6, 3) and traj.reward.shape == (6, 3)
    assert traj.info["executed_action"].shape == (6, 3, 4)
    # frame stacks shift by one frame per step (no episode ends this early in Breakout)
    np.testing.assert_array_equal(traj.obs[1:, ..., :3], traj.obs[:-1, ..., 1:])
    np.testing.assert_array_equal(traj.last_obs[..., :3], traj.obs[-1, ..., 1:])
    for a, b in zip(jax.tree.leaves(runs[0]), jax.tree.leaves(runs[1])):
        np.testing.assert_array_equal(a, b)


def test_rollout_rejects_bad_num_steps():
    with stori_jax.make("Breakout", num_envs=1, seed=0, obs="ram") as env:
        with pytest.raises(ValueError, match="num_steps must be >= 1, got 0"):
            stori_jax.rollout(env, random_policy, {"num_actions": 4}, jax.random.PRNGKey(0), 0)
        with pytest.raises(ValueError, match="num_steps must be an int >= 1, got True"):
            stori_jax.rollout(env, random_policy, {"num_actions": 4}, jax.random.PRNGKey(0), True)
        with pytest.raises(ValueError, match=r"key must be a JAX PRNG key .*got 0"):
            stori_jax.rollout(env, random_policy, {"num_actions": 4}, 0, 2)
        traj = stori_jax.rollout(env, random_policy, {"num_actions": 4}, jax.random.PRNGKey(0),
                                 np.int64(2))
        assert traj.action.shape == (2, 1)


def test_cli_list_prints_presets_and_modes(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "Breakout   3.2A  blackout mode 10, p = 1.0" in out
    assert "hide city blocks" in out and "torch" in out


def test_cli_run_prints_a_summary():
    result = subprocess.run([sys.executable, "-m", "stori_jax.cli", "run", "Boxing", "1",
                             "--steps", "20", "--num-envs", "2", "--quiet"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    for line in ("episodes finished", "mean return", "events fired", "corrupted actions",
                 "concept switches", "env steps / s"):
        assert line in result.stdout
    corrupted = int(result.stdout.split("corrupted actions :")[1].split()[0])
    assert 0 < corrupted < 20 * 2 * 4  # p = 0.3 per frame over 160 frames


@pytest.mark.parametrize("argv, message", [
    (["run", "Pacman-ish"], "unknown game 'Pacman-ish'"),
    (["run", "Breakout", "7"], "unknown preset '7' for Breakout: allowed"),
    (["run", "Breakout", "--steps", "0"], "--steps must be >= 1"),
])
def test_cli_bad_arguments_give_clear_errors(argv, message, capsys):
    assert main(argv) == 2
    assert message in capsys.readouterr().err
