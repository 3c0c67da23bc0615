"""rollout() stacking and determinism; the command line's list/run and its errors."""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import stori_jax
from stori_jax.cli import main

from _env_support import binomial_ok, wait_gone


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


def test_a_rollout_is_what_the_env_gives_for_the_policy_s_actions():
    """Step by step, a twin env of the seed stepped with the trajectory's actions gives its
    observations (each the one its action was chosen from), rewards and end flags (episodes
    cut at 40 frames: truncations inside the rollout); each action is the policy's draw from
    step t's key of the documented chain (key, step key = split(key))."""
    params, key, steps = {"num_actions": 4}, jax.random.PRNGKey(3), 14
    kw = dict(num_envs=2, seed=5, obs="atari84", max_episode_frames=40)
    with stori_jax.make("Breakout", "1", **kw) as env:
        traj = stori_jax.rollout(env, random_policy, params, key, steps)
    with stori_jax.make("Breakout", "1", **kw) as twin:
        obs, _ = twin.reset()
        for t in range(steps):
            key, step_key = jax.random.split(key)
            np.testing.assert_array_equal(traj.action[t], random_policy(params, obs, step_key))
            np.testing.assert_array_equal(traj.obs[t], obs, err_msg=f"obs {t}")
            obs, reward, terminated, truncated, _ = twin.step(traj.action[t])
            np.testing.assert_array_equal(traj.reward[t], reward)
            np.testing.assert_array_equal(traj.terminated[t], terminated, err_msg=f"{t}")
            np.testing.assert_array_equal(traj.truncated[t], truncated, err_msg=f"{t}")
    np.testing.assert_array_equal(traj.last_obs, obs)
    np.testing.assert_array_equal(traj.last_key, key)
    assert np.asarray(traj.truncated).any()  # the flags were tested where they differ


def test_a_rollout_continued_from_its_last_key_and_obs_is_one_long_rollout():
    params = {"num_actions": 4}
    with stori_jax.make("Breakout", "1", num_envs=2, seed=4, obs="ram") as env:
        whole = stori_jax.rollout(env, random_policy, params, stori_jax.agent_key(4), 8)
    with stori_jax.make("Breakout", "1", num_envs=2, seed=4, obs="ram") as env:
        first = stori_jax.rollout(env, random_policy, params, stori_jax.agent_key(4), 5)
        rest = stori_jax.rollout(env, random_policy, params, first.last_key, 3,
                                 obs=first.last_obs)
    for name in ("obs", "action", "reward"):
        np.testing.assert_array_equal(getattr(whole, name),
                                      np.concatenate([getattr(first, name), getattr(rest, name)]))
    np.testing.assert_array_equal(whole.last_key, rest.last_key)


def test_a_rollout_with_a_seed_replays_that_seeds_run_on_a_used_env():
    """rollout(..., seed=s) resets the env with seed s first: the same trajectory each time,
    the one a new env of seed s gives.  Without it the env's streams go on (a plain reset), so
    a second rollout of one env plays other episodes."""
    params, key = {"num_actions": 4}, stori_jax.agent_key(3)
    with stori_jax.make("Breakout", "1", num_envs=2, seed=3, obs="ram") as env:
        fresh = stori_jax.rollout(env, random_policy, params, key, 6)
    with stori_jax.make("Breakout", "1", num_envs=2, seed=9, obs="ram") as env:
        seeded = [stori_jax.rollout(env, random_policy, params, key, 6, seed=3) for _ in range(2)]
        plain = stori_jax.rollout(env, random_policy, params, key, 6)
        with pytest.raises(ValueError, match="rollout takes obs .* or seed .*, not both"):
            stori_jax.rollout(env, random_policy, params, key, 1, obs=plain.last_obs, seed=3)
    for traj in seeded:
        for a, b in zip(jax.tree.leaves(fresh), jax.tree.leaves(traj)):
            np.testing.assert_array_equal(a, b)
    assert (np.asarray(plain.info["executed_action"]) != np.asarray(
        fresh.info["executed_action"])).any()


def _key_bytes(keys) -> set:
    return {bytes(np.asarray(k, np.uint32)) for k in keys}


def _chain(key, steps):
    """Every key an agent (rollout, the suite) or an env holds over ``steps`` steps: each step
    splits the key into the next one and the step's own."""
    keys = []
    for _ in range(steps):
        key, step_key = jax.random.split(key)
        keys += [key, step_key]
    return keys


def test_the_agent_key_stream_shares_no_key_with_the_envs():
    """An env of seed s draws from PRNGKey(s)'s chain (its step keys folded with each env's
    index); an agent keyed with PRNGKey(s) would sample with the env's very step keys, and
    agent_key(s) holds none of them.  The suite's random policy (stori-jax run, suite) gets
    its keys from agent_key."""
    from stori_jax.functional.keys import env_keys
    from stori_jax.suite import play

    seed, steps, b = 7, 12, 3
    env_chain = _chain(jax.random.PRNGKey(seed), steps)
    env_side = _key_bytes(env_chain) | _key_bytes(
        k for step_key in env_chain[1::2] for k in env_keys(step_key, b))
    assert _key_bytes(_chain(jax.random.PRNGKey(seed), steps)) & env_side  # the naive choice
    assert not _key_bytes(_chain(stori_jax.agent_key(seed), steps)) & env_side

    seen = []

    def policy(obs, key):
        seen.append((key, env._state.key))
        return jnp.zeros(obs.shape[0], jnp.int32)

    with stori_jax.make("Breakout", "1", num_envs=b, seed=seed, obs="ram") as env:
        obs, _ = env.reset()
        play(env, obs, seed, max_steps=steps, policy=policy)
    agent_keys = _key_bytes(key for key, _ in seen)
    assert len(agent_keys) == steps
    assert not agent_keys & (env_side | _key_bytes(state for _, state in seen))


def test_agent_key_takes_the_seeds_an_env_takes():
    """agent_key(2**32) was agent_key(0) (JAX keys are 32-bit) and agent_key(1.0) failed deep
    inside JAX; make refuses those seeds, and so does agent_key now."""
    assert (np.asarray(stori_jax.agent_key(np.int64(5)))
            == np.asarray(stori_jax.agent_key(5))).all()
    for bad, shown in ((2**32, "in [0, 2147483647], got 4294967296"),
                       (-1, "in [0, 2147483647], got -1"),
                       (1.0, "an int in [0, 2147483647], got 1.0"),
                       (True, "an int in [0, 2147483647], got True")):
        with pytest.raises(ValueError, match=re.escape(f"seed must be {shown}")):
            stori_jax.agent_key(bad)
    # a traced seed has no number to check yet: one key per seed, under vmap and jit
    many = jax.vmap(stori_jax.agent_key)(jnp.arange(3))
    assert (np.asarray(many[2]) == np.asarray(stori_jax.agent_key(2))).all()
    assert (np.asarray(jax.jit(stori_jax.agent_key)(2)) == np.asarray(many[2])).all()


def test_rollout_rejects_bad_arguments():
    with stori_jax.make("Breakout", num_envs=1, seed=0, obs="ram") as env:
        with pytest.raises(ValueError, match="num_steps must be >= 1, got 0"):
            stori_jax.rollout(env, random_policy, {"num_actions": 4}, jax.random.PRNGKey(0), 0)
        with pytest.raises(ValueError, match="num_steps must be an int >= 1, got True"):
            stori_jax.rollout(env, random_policy, {"num_actions": 4}, jax.random.PRNGKey(0), True)
        with pytest.raises(ValueError, match=r"key must be a JAX PRNG key .*got 0"):
            stori_jax.rollout(env, random_policy, {"num_actions": 4}, 0, 2)
        for bad, shown in ((jnp.zeros(3, jnp.uint32), r"shape \(3,\) and dtype uint32"),
                           (jax.random.split(jax.random.key(0)), r"shape \(2,\) and dtype key")):
            with pytest.raises(ValueError, match=r"key must be a JAX PRNG key .*got an array of "
                                                 + shown):
                stori_jax.rollout(env, random_policy, {"num_actions": 4}, bad, 2)
        assert stori_jax.rollout(env, random_policy, {"num_actions": 4}, jax.random.key(0),
                                 1).action.shape == (1, 1)  # typed keys too
        traj = stori_jax.rollout(env, random_policy, {"num_actions": 4}, jax.random.PRNGKey(0),
                                 np.int64(2))
        assert traj.action.shape == (2, 1)
        for bad, shown in ((np.zeros(128, np.uint8), r"shape \(128,\) and dtype uint8"),
                           (np.zeros((1, 128), np.float32), r"shape \(1, 128\) and dtype float32"),
                           ([[0] * 128], r"\[\[0, 0, 0, .*\(\d+ characters\)")):  # no dtype
            with pytest.raises(ValueError, match=r"obs must be the env's current observation, of "
                                                 r"shape \(1, 128\) and dtype uint8 \(the last "
                                                 rf"step's\), got {shown}"):
                stori_jax.rollout(env, random_policy, {"num_actions": 4},
                                  jax.random.PRNGKey(0), 2, obs=bad)
        more = stori_jax.rollout(env, random_policy, {"num_actions": 4}, jax.random.PRNGKey(1),
                                 1, obs=traj.last_obs)  # continuing a run
        assert more.obs.shape == (1, 1, 128)

    from stori_jax.compat.gymnasium import StoriGymEnv

    single = StoriGymEnv("Breakout")  # one numpy env: its (84, 84, 4) obs is no batch
    try:
        with pytest.raises(ValueError, match=r"env must be a batched stori_jax.Env .*got "
                                             r"StoriGymEnv"):
            stori_jax.rollout(single, random_policy, {"num_actions": 4}, jax.random.PRNGKey(0), 2)
    finally:
        single.close()


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
    assert binomial_ok(corrupted, 20 * 2 * 4, 0.3)  # p = 0.3 per frame over 160 frames


@pytest.mark.parametrize("argv, message", [
    (["run", "Pacman-ish"], "unknown game 'Pacman-ish'"),
    (["run", "Breakout", "7"], "unknown preset '7' for Breakout: allowed"),
    (["run", "Breakout", "--steps", "0"], "--steps must be >= 1"),
])
def test_cli_bad_arguments_give_clear_errors(argv, message, capsys):
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def children(pid: int) -> list[int]:
    """The process's direct children (Linux /proc)."""
    kids = []
    for task in os.listdir(f"/proc/{pid}/task"):
        with open(f"/proc/{pid}/task/{task}/children") as f:
            kids += [int(k) for k in f.read().split()]
    return kids


# the console script's function, started as a terminal would (default SIGINT handling)
ENTRY = ("import signal; signal.signal(signal.SIGINT, signal.default_int_handler); "
         "from stori_jax.cli import entry; entry()")


@pytest.mark.timeout(90)
def test_ctrl_c_stops_the_command_with_130_and_no_worker_left():
    child = subprocess.Popen([sys.executable, "-c", ENTRY, "run", "Breakout", "--steps", "100000",
                              "--num-envs", "2", "--num-workers", "2", "--quiet"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().startswith("Env(Breakout")  # made: workers started
        time.sleep(1.0)
        workers = children(child.pid)
        assert len(workers) >= 2
        child.send_signal(signal.SIGINT)
        _, err = child.communicate(timeout=60)
    finally:
        child.kill()
    assert child.returncode == 130, err
    assert err.strip().endswith("stori-jax: interrupted")
    assert wait_gone(workers, 5.0)


def test_a_closed_pipe_ends_the_command_quietly():
    """`stori-jax list | head -1`: the reader goes away; no error message, exit code 1."""
    child = subprocess.Popen([sys.executable, "-c", ENTRY, "list"], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    child.stdout.close()  # before the command writes
    err = child.stderr.read()
    assert child.wait(timeout=60) == 1 and err == ""


def test_every_default_the_help_states_is_the_default_used():
    """'(default N)' in a flag's help is what the command uses without the flag."""
    from stori_jax.cli import build_parser

    checked = 0
    commands = build_parser()._subparsers._group_actions[0].choices
    for command, parser in commands.items():
        for action in parser._actions:
            stated = re.search(r"\(default (-?[\d.]+)\)", action.help or "")
            if stated:
                assert action.default == type(action.default)(stated.group(1)), \
                    (command, action.dest)
                checked += 1
    assert checked >= 8


def test_cli_run_plays_the_observation_granularity_and_seed_asked_for(capsys, monkeypatch):
    """--obs and --granularity reach the env (one action draw per agent step at 'step'), and
    --seed is the env's seed and the random policy's key stream."""
    import stori_jax.suite

    seeds, real_play = [], stori_jax.suite.play

    def play(env, obs, seed, **kwargs):
        seeds.append((env.seed, seed))
        return real_play(env, obs, seed, **kwargs)

    monkeypatch.setattr(stori_jax.suite, "play", play)
    assert main(["run", "Breakout", "1", "--steps", "3", "--num-envs", "2", "--seed", "3",
                 "--obs", "ram", "--granularity", "step", "--num-workers", "1",
                 "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "obs='ram', granularity='step')" in out.splitlines()[0]
    assert re.search(r"corrupted actions : \d+ of 6 ", out)  # 3 steps x 2 envs x 1 draw
    assert seeds == [(3, 3)]


def test_show_and_record_play_the_asked_config_into_a_file_named_after_it(tmp_path,
                                                                        monkeypatch):
    """Without --out the picture is <game>-<preset>.<ext> (the preset as the paper spells it),
    or <game>-<config file name>.<ext>; the preset's or the file's config is the one played."""
    import json

    import stori_jax.visual

    written = []
    for name in ("contact_sheet", "record_episode"):
        monkeypatch.setattr(stori_jax.visual, name,
                            lambda game, preset, config, path, **kw: written.append(
                                (game, preset, config, path)) or path)
    monkeypatch.chdir(tmp_path)
    reference = {"stochasticity_type": "1", "intrinsic_stochasticity.action_dependent."
                                            "stochastic_action_prob": 0.45}
    (tmp_path / "mine.json").write_text(json.dumps(reference))
    assert main(["show", "Breakout", "3.2a"]) == 0
    assert main(["record", "Boxing"]) == 0
    assert main(["show", "Gopher", "--config", "mine.json"]) == 0
    assert written == [
        ("Breakout", "3.2A", stori_jax.preset("Breakout", "3.2A"), Path("Breakout-3.2A.png")),
        ("Boxing", "3.1", stori_jax.Config(), Path("Boxing-3.1.gif")),
        ("Gopher", "mine", stori_jax.config_from_reference(reference, game="Gopher"),
         Path("Gopher-mine.png"))]
    assert written[2][2].action_noise.prob == 0.45
