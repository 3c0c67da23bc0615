"""The gymnasium adapter: registered ids, single-env and vector APIs, NEXT_STEP autoreset."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import stori_jax
from stori_jax.compat.gymnasium import StoriGymEnv, env_id


def test_every_preset_is_registered():
    for game, name in stori_jax.list_presets():
        assert env_id(game, name) in gym.registry


def test_single_env_follows_gymnasium_api():
    env = gym.make("stori_jax/Gopher-3.2-v0", num_workers=0)
    try:
        check_env(env.unwrapped, skip_render_check=True)
        obs, info = env.reset(seed=5)
        assert obs.shape == (84, 84, 4) and obs.dtype == np.uint8
        obs, reward, terminated, truncated, info = env.step(0)
        assert isinstance(reward, float) and isinstance(terminated, bool)
        assert env.observation_space.contains(obs)
        # the batched info, env 0's entry of every leaf (the type-0 labels too)
        assert info["labels"].keys() == set(stori_jax.get_game("Gopher").labels)
        assert all(np.shape(v) == () for v in info["labels"].values())
        assert info["ram"].shape == (128,) and np.shape(info["event_fired"]) == ()
        with pytest.raises(ValueError, match=r"render\(\) needs render_mode='rgb_array'.*"
                                             r"stori-jax record"):
            env.unwrapped.render()
        with pytest.raises(ValueError, match=r"action must be one int in \[0, 7\]"):
            env.step(8)
        with pytest.raises(ValueError, match="action must be one int"):
            env.step(0.5)
    finally:
        env.close()


def test_single_env_reset_seed_reproduces_the_run():
    env = gym.make("stori_jax/Breakout-1-v0", obs="ram", num_workers=0)
    try:
        runs = []
        for _ in range(2):
            obs, _ = env.reset(seed=11)
            trace = [obs]
            for t in range(30):
                obs, *_ = env.step(t % 4)
                trace.append(obs)
            runs.append(np.stack(trace))
        np.testing.assert_array_equal(runs[0], runs[1])
        env.reset(seed=12)
        other = np.stack([env.step(t % 4)[0] for t in range(30)])
        assert not np.array_equal(other, runs[0][1:])
    finally:
        env.close()


def test_reset_with_a_new_seed_keeps_the_worker_processes():
    """reset(seed=k) restarts from seed k in the same workers (it used to start new ones), and
    the run is a new env's of seed k."""
    actions = np.random.default_rng(0).integers(0, 4, (30, 2))
    runs = []
    for seed, reseed in ((5, None), (2, 5)):
        envs = gym.make_vec("stori_jax/Breakout-1-v0", num_envs=2, obs="ram", seed=seed)
        try:
            pids = envs._env.backend.pids
            if reseed is not None:
                envs.reset()
                for a in actions[:7]:
                    envs.step(a)
            obs, _ = envs.reset(seed=reseed)
            runs.append(np.stack([obs] + [envs.step(a)[0] for a in actions]))
            assert envs._env.backend.pids == pids
        finally:
            envs.close()
    np.testing.assert_array_equal(runs[0], runs[1])


def test_vector_env_next_step_autoreset():
    envs = gym.make_vec("stori_jax/Breakout-3.1-v0", num_envs=2, obs="ram", frame_skip=4,
                        num_workers=0)
    try:
        assert envs.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP
        obs, info = envs.reset(seed=0)
        assert obs.shape == (2, 128)
        first_ram = obs.copy()
        rng = np.random.default_rng(0)
        done_at = done_env = None
        for t in range(3000):
            obs, reward, terminated, truncated, info = envs.step(rng.integers(0, 4, 2))
            if done_at is not None:
                # the step after an episode end is the reset step: reward 0, not terminated
                assert reward[done_env] == 0 and not terminated[done_env]
                assert info["reset_step"][done_env]
                # a reset without no-ops starts from the same RAM as the first reset
                np.testing.assert_array_equal(obs[done_env], first_ram[done_env])
                break
            if (terminated | truncated).any():
                done_at, done_env = t, int(np.flatnonzero(terminated | truncated)[0])
        assert done_at is not None, "no Breakout episode ended under random play"
        with pytest.raises(ValueError, match="seed must be one int for all envs"):
            envs.reset(seed=[0, 1])
    finally:
        envs.close()


def test_a_spec_saved_as_json_makes_the_env_again_and_max_episode_steps_is_named():
    """A spec through JSON (an experiment's saved config) came back with its id's game and
    preset as a list and was refused as contradicting itself; max_episode_steps in make_vec's
    default mode was a TypeError from make, not a pointer to max_episode_frames."""
    spec = gym.envs.registration.EnvSpec.from_json(gym.spec("stori_jax/Breakout-3.1-v0").to_json())
    env = gym.make(spec, obs="ram", num_workers=0)
    try:
        assert env.reset(seed=1)[0].shape == (128,)
    finally:
        env.close()
    with pytest.raises(ValueError, match=r"max_episode_steps: .* pass max_episode_frames "
                                         r"\(steps x frame_skip\), got max_episode_steps=100"):
        gym.make_vec("stori_jax/Breakout-3.1-v0", num_envs=2, max_episode_steps=100)
    with pytest.raises(ValueError, match=r"max_episode_steps: stori_jax envs cap episodes"):
        StoriGymEnv("Breakout", "3.1", max_episode_steps=100)  # a single env is not a vector


@pytest.mark.parametrize("kwargs,pattern", [
    (dict(game="Boxing"), r"fixes game and preset, got game='Boxing' preset='2\.1'"),
    (dict(preset="1"), r"fixes game and preset, got game='Breakout' preset='1'"),
    (dict(num_envs=4), r"num_envs is set by the gymnasium adapter.*make_vec.*got num_envs=4"),
    (dict(autoreset=True), r"autoreset is set by the gymnasium adapter.*got autoreset=True"),
    (dict(render_mode="rgb_array"), r"render_mode='rgb_array' needs the screens: obs_type "
                                    r"'rgb' or 'grayscale' \(obs='raw' on a -v0 id\), got "
                                    r"obs='atari84'"),
    (dict(config=stori_jax.Config()), r"config: the id .*Breakout-2\.1-v0 fixes the preset.*"
                                      r"StoriGymEnv\(game, config=\.\.\.\)"),
])
def test_kwargs_that_would_contradict_the_id_are_refused(kwargs, pattern):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # gymnasium's own render_mode warning
        with pytest.raises(ValueError, match=pattern):
            gym.make("stori_jax/Breakout-2.1-v0", **kwargs)
    with pytest.raises(ValueError, match=r"fixes game and preset"):
        gym.make_vec("stori_jax/Breakout-2.1-v0", num_envs=2, game="Boxing")


def test_a_vector_env_s_fixed_autoreset_is_named_as_its_own():
    with pytest.raises(ValueError, match=r"autoreset is set by the gymnasium adapter \(gymnasium's "
                                         r"NEXT_STEP autoreset.*\), got autoreset=True"):
        gym.make_vec("stori_jax/Breakout-2.1-v0", num_envs=2, autoreset=True)


def test_the_ids_own_game_and_preset_in_another_case_are_not_a_contradiction():
    env = gym.make("stori_jax/Breakout-3.2A-v0", game="breakout", preset="3.2a", obs="raw",
                   num_workers=0)
    env.close()


@pytest.mark.parametrize("vector", [False, True])
def test_a_refused_seed_leaves_the_env_usable(vector):
    """With random no-ops at every reset (noop_max) the seed shows in the RAM: after a refused
    seed the env goes on as the env of seed 1 does."""
    def made():
        kw = dict(noop_max=30, obs="ram", num_workers=0)
        return (gym.make_vec("stori_jax/Breakout-3.1-v0", num_envs=2, **kw) if vector
                else gym.make("stori_jax/Breakout-3.1-v0", **kw))

    reference, env = made(), made()
    try:
        reference.reset(seed=1)
        expected = reference.reset()[1]["ram"]
        other_seed = reference.reset(seed=2)[1]["ram"]
        assert not np.array_equal(expected, other_seed), "seeds should show in the RAM"
        env.reset(seed=1)
        with pytest.raises(ValueError, match=r"seed must be in \[0, .* got 1099511627776"):
            env.reset(seed=2 ** 40)  # past gymnasium's own checks, refused by stori_jax
        again = env.reset()[1]["ram"]  # still the env of seed 1, as if nothing had been asked
        np.testing.assert_array_equal(again, expected)
        env.step(np.zeros(2, np.int64) if vector else 0)
    finally:
        reference.close()
        env.close()


@pytest.mark.parametrize("vector", [False, True])
def test_reset_options_are_refused_not_ignored(vector):
    kw = dict(obs="ram", num_workers=0)
    env = (gym.make_vec("stori_jax/Breakout-3.1-v0", num_envs=2, **kw) if vector
           else gym.make("stori_jax/Breakout-3.1-v0", **kw))
    try:
        env.reset(options={})  # nothing asked
        with pytest.raises(ValueError, match="reset options are not supported.*reset_mask"):
            env.reset(options={"reset_mask": np.array([True, False])})
        for falsy in ([], 0, "", False):  # not a dict: refused, even when it asks nothing
            with pytest.raises(ValueError, match=r"options must be a dict or None .*got "):
                env.reset(options=falsy)
    finally:
        env.close()


def test_a_config_of_ones_own_through_the_adapter_classes():
    from stori_jax.compat.gymnasium import StoriGymEnv, StoriVectorEnv

    env = StoriGymEnv("Breakout", config=stori_jax.Config(ram_observation=True), obs="ram",
                      num_workers=0)
    envs = StoriVectorEnv(2, "Breakout", config=stori_jax.Config(
        action_noise=stori_jax.ActionNoise(1.0)), obs="ram", num_workers=0)
    try:
        obs, info = env.reset(seed=0)
        assert obs.shape == (128,) and "labels" in info
        envs.reset(seed=0)
        *_, info = envs.step(np.zeros(2, np.int64))
        assert info["action_corrupted"].all()
    finally:
        env.close()
        envs.close()


def test_vector_env_close_seeding_and_writable_outputs():
    """closed is True after close() and no reset brings the env back (reset(seed=k) used to
    start new workers); reset(seed=k) seeds np_random as gymnasium's vector envs do; outputs
    are writable numpy arrays (in-place edits of rewards or obs raised 'read-only')."""
    envs = gym.make_vec("stori_jax/Breakout-3.1-v0", num_envs=2, obs="ram", num_workers=0)
    obs, info = envs.reset(seed=3)
    assert envs.np_random_seed == 3
    obs, reward, terminated, truncated, info = envs.step(np.zeros(2, np.int64))
    for array in (obs, reward, terminated, truncated, info["ram"], info["labels"]["score"]):
        assert array.flags.writeable
    reward[0] = 1.0
    envs.close()
    assert envs.closed
    for seed in (None, 4):
        with pytest.raises(stori_jax.EnvClosedError):
            envs.reset(seed=seed)
    with pytest.raises(stori_jax.EnvClosedError, match="gymnasium.make"):
        envs.step(np.zeros(2, np.int64))  # named stori_jax.make, the wrong way back
    single = gym.make("stori_jax/Breakout-3.1-v0", obs="ram", num_workers=0)
    obs, info = single.reset(seed=1)
    assert obs.flags.writeable and info["ram"].flags.writeable
    single.close()
    with pytest.raises(stori_jax.EnvClosedError):
        single.reset(seed=2)
    with pytest.raises(stori_jax.EnvClosedError, match="gymnasium.make"):
        single.step(0)


def _info_layout(info):
    """Each key's shape and dtype, nested dicts as dicts: what gymnasium code indexes."""
    return {key: _info_layout(value) if isinstance(value, dict) else (value.shape, value.dtype)
            for key, value in info.items()}


def test_the_default_modes_infos_carry_gymnasiums_masks_as_the_sync_mode_does():
    """Every info key, nested ones too, comes with its ``_key`` mask (all True: every env
    reports every key), in the layout and dtypes gymnasium's own sync mode builds from
    one-env infos. The default mode gave the keys without their masks."""
    made = [gym.make_vec("stori_jax/Gopher-2.1-v0", num_envs=2, obs="ram", num_workers=0, **mode)
            for mode in ({}, {"vectorization_mode": "sync"})]
    try:
        for step in (False, True):
            default, sync = (envs.step(np.array([1, 2]))[4] if step else envs.reset(seed=0)[1]
                             for envs in made)
            assert _info_layout(default) == _info_layout(sync)
            assert default["_labels"].all() and default["labels"]["_score"].all()
            assert all(default[key].all() for key in default if key.startswith("_"))
            assert len(default) == 2 * len([key for key in default if not key.startswith("_")])
    finally:
        for envs in made:
            envs.close()


@pytest.mark.parametrize("vector", [False, True])
def test_np_random_seed_is_the_seed_the_env_plays(vector):
    """A first reset without a seed plays the env's seed (0, or make's seed=), and gymnasium's
    np_random_seed says so (it was a random 128-bit number); a later plain reset keeps it, a
    reset(seed=k) makes it k."""
    for made_with, played in (({}, 0), ({"seed": 5}, 5), ({"seed": np.int64(5)}, 5)):
        kw = dict(obs="ram", num_workers=0, **made_with)
        env = (gym.make_vec("stori_jax/Breakout-3.1-v0", num_envs=2, **kw) if vector
               else gym.make("stori_jax/Breakout-3.1-v0", **kw))
        try:
            env.np_random  # read before the first reset (a wrapper may): gymnasium seeds it
            env.reset()    # at random, and the first reset still seeds it with the env's seed
            assert env.np_random_seed == played
            env.reset()
            assert env.np_random_seed == played
            env.reset(seed=np.int64(2))  # gymnasium itself takes Python ints only
            assert env.np_random_seed == 2
        finally:
            env.close()


def _ram_digest(**kw) -> str:
    import hashlib

    h = hashlib.sha256()
    with stori_jax.make("Breakout", "1", num_envs=2, seed=3, obs="ram", **kw) as env:
        env.reset()
        for t in range(12):
            obs, reward, *_ = env.step(np.array([t % 4, 1]))
            h.update(np.asarray(obs).tobytes() + np.asarray(reward).tobytes())
    return h.hexdigest()


def _make_in_daemon(queue, num_workers):
    try:
        queue.put(_ram_digest(num_workers=num_workers))
    except Exception as error:
        queue.put(f"{type(error).__name__}: {error}")


def _in_a_daemonic_process(num_workers) -> str:
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    process = ctx.Process(target=_make_in_daemon, args=(queue, num_workers), daemon=True)
    process.start()
    message = queue.get(timeout=120)
    process.join(30)
    return message


def test_inside_a_daemonic_process_every_env_is_emulated_in_that_process():
    """gymnasium's async vector mode (and a DataLoader worker) runs each env in a daemonic
    process, which Python forbids to start processes: by default the env then starts no worker
    and gives the same run; asked for workers, it says why it cannot and what works."""
    assert _in_a_daemonic_process(None) == _ram_digest(num_workers=0)
    message = _in_a_daemonic_process(1)
    assert message.startswith("RuntimeError: stori_jax.make cannot start its 1 emulator worker "
                              "process(es) inside a daemonic process"), message
    assert "set it to 0 to emulate every env in this process" in message


def _make_in_fork(queue):
    try:
        stori_jax.make("Breakout", num_envs=1, seed=0, obs="ram", num_workers=0)
        queue.put("made")
    except Exception as error:
        queue.put(f"{type(error).__name__}: {error}")


def test_making_an_env_in_a_process_forked_after_jax_started_says_spawn():
    """JAX's threads do not survive fork: an env made there hung at its first compilation."""
    import multiprocessing as mp
    import warnings

    import jax.numpy as jnp

    jnp.zeros(2).block_until_ready()  # JAX has started here
    ctx = mp.get_context("fork")
    queue = ctx.Queue()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # JAX's own warning about the fork
        process = ctx.Process(target=_make_in_fork, args=(queue,), daemon=True)
        process.start()
    try:
        message = queue.get(timeout=60)
    finally:
        process.join(10)
        if process.is_alive():  # the hang this test is about: do not leave it behind
            process.kill()
    assert message.startswith("RuntimeError: stori_jax.make cannot run in a process forked "
                              "from one that had started JAX"), message
    assert "vector_kwargs={'context': 'spawn'}" in message


def test_reset_after_a_worker_died_makes_the_env_again_from_its_seed():
    """The step reports the death; reset() (gymnasium's way on) then starts from the seed, as a
    fresh env does, instead of pointing to stori_jax.make."""
    import os
    import signal

    env = gym.make("stori_jax/Breakout-2.1-v0", num_workers=1)
    fresh = gym.make("stori_jax/Breakout-2.1-v0", num_workers=0)
    try:
        env.reset()
        os.kill(env.unwrapped._env.backend.pids[0], signal.SIGKILL)
        with pytest.raises(stori_jax.WorkerError, match="died"):
            for _ in range(50):  # the death is noticed at the next command
                env.step(0)
        # a step after it says what to do here (not stori_jax.make's advice)
        with pytest.raises(stori_jax.EnvClosedError, match=r"worker of this environment died.*"
                                                           r"reset\(\) makes the env again"):
            env.step(0)
        obs, _ = env.reset()
        np.testing.assert_array_equal(obs, fresh.reset()[0])
        assert env.step(1)[0].shape == obs.shape
    finally:
        env.close()
        fresh.close()


def test_a_reset_with_a_seed_that_a_dead_worker_stopped_keeps_the_seed():
    """reset(seed=5) that fails (its worker died) leaves the env on seed 5: the reset() after it
    makes the env again from 5, not from the seed before."""
    import os
    import signal

    kw = dict(num_envs=2, obs="ram", noop_max=30)  # the first obs depends on the seed
    envs = gym.make_vec("stori_jax/Breakout-3.1-v0", num_workers=1, **kw)
    fresh = gym.make_vec("stori_jax/Breakout-3.1-v0", num_workers=0, **kw)
    try:
        envs.reset()
        os.kill(envs._env.backend.pids[0], signal.SIGKILL)
        envs._env.backend.processes[0].join(5)
        with pytest.raises(stori_jax.WorkerError, match="died"):
            envs.reset(seed=5)
        obs, _ = envs.reset()
        assert envs._env.seed == 5
        np.testing.assert_array_equal(obs, fresh.reset(seed=5)[0])
    finally:
        envs.close()
        fresh.close()


FORK_WHILE_JAX_IS_BUSY = """
import os, threading, time, warnings
warnings.simplefilter("ignore")  # JAX's warning about the fork
import jax.numpy as jnp
import stori_jax
from jax._src import xla_bridge

jnp.zeros(2).block_until_ready()
held, release = threading.Event(), threading.Event()

def busy():  # another thread inside JAX (jax.devices() from a loader thread) at the fork
    with xla_bridge._backend_lock:
        held.set()
        release.wait()

threading.Thread(target=busy, daemon=True).start()
held.wait()
pid = os.fork()
if pid == 0:
    os._exit(0)  # a child that never touches JAX
release.set()
for _ in range(100):
    if os.waitpid(pid, os.WNOHANG)[0]:
        print("child exited")
        break
    time.sleep(0.1)
else:
    os.kill(pid, 9)
    print("child stuck at the fork")
"""


def test_the_fork_guard_takes_no_lock_in_the_child():
    """stori_jax's at-fork hook runs in every child forked after it was imported: it must not
    take JAX's lock (or import anything), which another thread may hold at the fork.  (It did,
    and a child that never used JAX hung for ever.)"""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", FORK_WHILE_JAX_IS_BUSY], capture_output=True,
                         text=True, timeout=120)
    assert out.stdout.strip() == "child exited", out.stdout + out.stderr


@pytest.mark.parametrize("vector", [False, True])
def test_an_episode_cut_by_the_frame_cap_is_truncated_not_terminated(vector):
    """max_episode_frames=8 at frame_skip 4: the second step hits the cap, which gymnasium
    calls truncation (the game did not end: bootstrapping agents must tell the two apart)."""
    kw = dict(obs="ram", max_episode_frames=8, num_workers=0)
    env = (gym.make_vec("stori_jax/Breakout-3.1-v0", num_envs=2, **kw) if vector
           else gym.make("stori_jax/Breakout-3.1-v0", **kw))
    try:
        env.reset(seed=0)
        action = np.zeros(2, np.int64) if vector else 0
        _, _, terminated, truncated, _ = env.step(action)
        assert not np.any(terminated) and not np.any(truncated)
        _, _, terminated, truncated, info = env.step(action)
        assert np.all(truncated) and not np.any(terminated)
        assert np.all(info["episode_length"] == 2)
    finally:
        env.close()


@pytest.mark.parametrize("vector", [False, True])
def test_a_plain_reset_goes_on_with_np_random_and_a_seed_restarts_it(vector):
    """As gymnasium's envs: reset(seed=k) reseeds np_random, a later reset() leaves it going on
    (np_random_seed still k), so an agent drawing from it does not replay its draws."""
    kw = dict(obs="ram", num_workers=0)
    env = (gym.make_vec("stori_jax/Breakout-3.1-v0", num_envs=2, **kw) if vector
           else gym.make("stori_jax/Breakout-3.1-v0", **kw))
    try:
        env.reset(seed=3)
        first = env.np_random.random(4)
        env.reset()
        assert env.np_random_seed == 3
        assert not np.array_equal(env.np_random.random(4), first)
        env.reset(seed=3)
        np.testing.assert_array_equal(env.np_random.random(4), first)
    finally:
        env.close()


def test_the_step_that_resets_a_single_env_reports_reward_0():
    """An episode truncated on a step that scored: the next step() resets the env and reports
    reward 0 and the new episode's first observation, not the scoring step's reward again."""
    from _env_support import breakout_tracker

    def scoring_actions():  # follow the ball until a brick is hit
        with gym.make("stori_jax/Breakout-3.1-v0", obs="ram", num_workers=0) as env:
            _, info = env.reset(seed=0)
            actions = []
            for _ in range(400):
                actions.append(int(breakout_tracker(info["ram"][None])[0]))
                _, reward, _, _, info = env.step(actions[-1])
                if reward > 0:
                    return actions, reward
        raise AssertionError("the tracker should score within 400 steps")

    actions, scored = scoring_actions()
    # the same game, cut by the frame cap on its scoring step
    env = gym.make("stori_jax/Breakout-3.1-v0", obs="ram", max_episode_frames=4 * len(actions),
                   num_workers=0)
    try:
        first, _ = env.reset(seed=0)
        for a in actions:
            obs, reward, terminated, truncated, info = env.step(a)
        assert truncated and not terminated and reward == scored
        assert info["episode_return"] == scored
        obs, reward, terminated, truncated, info = env.step(0)
        assert info["reset_step"] and reward == 0.0 and not (terminated or truncated)
        assert info["episode_return"] == 0.0
        np.testing.assert_array_equal(obs, first)
    finally:
        env.close()


@pytest.mark.parametrize("vector", [False, True])
def test_close_stops_the_worker_processes(vector):
    """close() closes the stori_jax env inside, whose workers stop then (not when the garbage
    collector finds it)."""
    from _env_support import wait_gone

    env = (gym.make_vec("stori_jax/Breakout-3.1-v0", num_envs=2, obs="ram", num_workers=1)
           if vector else gym.make("stori_jax/Breakout-3.1-v0", obs="ram", num_workers=1))
    inner = env._env if vector else env.unwrapped._env
    pids = list(inner.backend.pids)
    assert len(pids) == 1
    try:
        env.reset(seed=0)
        env.close()
        assert inner.closed
        assert wait_gone(pids, 3.0)
    finally:
        inner.close()


FORK_BEFORE_JAX_STARTED = """
import os, sys
import jax, stori_jax  # imported: JAX's modules are loaded, but none of its backends is made

pid = os.fork()
if pid == 0:
    try:
        env = stori_jax.make("Breakout", num_envs=1, seed=0, obs="ram", num_workers=0)
        env.reset()
        env.close()
    except BaseException as error:
        print("child:", type(error).__name__, error, flush=True)
        os._exit(1)
    print("child made and reset an env", flush=True)
    os._exit(0)
_, status = os.waitpid(pid, 0)
sys.exit(os.waitstatus_to_exitcode(status))
"""


def test_a_process_forked_before_jax_started_may_make_an_env():
    """Importing JAX starts none of its threads: a child forked after the import alone is
    free to make an env (only a fork after JAX started is refused)."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", FORK_BEFORE_JAX_STARTED], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr[-3000:]
    assert out.stdout.strip() == "child made and reset an env", out.stdout + out.stderr[-3000:]


def test_a_vector_env_whose_worker_died_steps_only_after_a_reset_from_its_seed():
    """test_reset_after_a_worker_died_makes_the_env_again_from_its_seed, of a vector env: the
    step after the death names reset(), which makes the env again, as a fresh one starts."""
    import os
    import signal

    kw = dict(num_envs=2, obs="ram")
    envs = gym.make_vec("stori_jax/Breakout-2.1-v0", num_workers=1, **kw)
    fresh = gym.make_vec("stori_jax/Breakout-2.1-v0", num_workers=0, **kw)
    actions = np.zeros(2, np.int64)
    try:
        envs.reset()
        os.kill(envs._env.backend.pids[0], signal.SIGKILL)
        with pytest.raises(stori_jax.WorkerError, match="died"):
            for _ in range(50):  # the death is noticed at the next command
                envs.step(actions)
        with pytest.raises(stori_jax.EnvClosedError, match=r"worker of this environment died.*"
                                                           r"reset\(\) makes the env again"):
            envs.step(actions)
        obs, _ = envs.reset()
        np.testing.assert_array_equal(obs, fresh.reset()[0])
        np.testing.assert_array_equal(envs.step(actions)[0], fresh.step(actions)[0])
    finally:
        envs.close()
        fresh.close()


# -- ale-py's AtariEnv surface: keywords, ids, env.unwrapped.ale, the wrapper stacks -------------

class NoopResetEnv(gym.Wrapper):
    """SB3's (stable_baselines3.common.atari_wrappers, which CleanRL imports), on gymnasium."""

    def __init__(self, env, noop_max=30):
        super().__init__(env)
        self.noop_max = noop_max
        assert env.unwrapped.get_action_meanings()[0] == "NOOP"

    def reset(self, **kwargs):
        self.env.reset(**kwargs)
        noops = self.unwrapped.np_random.integers(1, self.noop_max + 1)
        obs, info = np.zeros(0), {}
        for _ in range(noops):
            obs, _, terminated, truncated, info = self.env.step(0)
            if terminated or truncated:
                obs, info = self.env.reset(**kwargs)
        return obs, info


class FireResetEnv(gym.Wrapper):
    def __init__(self, env):
        super().__init__(env)
        assert env.unwrapped.get_action_meanings()[1] == "FIRE"
        assert len(env.unwrapped.get_action_meanings()) >= 3

    def reset(self, **kwargs):
        self.env.reset(**kwargs)
        obs, _, terminated, truncated, _ = self.env.step(1)
        if terminated or truncated:
            self.env.reset(**kwargs)
        obs, _, terminated, truncated, _ = self.env.step(2)
        if terminated or truncated:
            self.env.reset(**kwargs)
        return obs, {}


class EpisodicLifeEnv(gym.Wrapper):
    def __init__(self, env):
        super().__init__(env)
        self.lives, self.was_real_done = 0, True

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.was_real_done = terminated or truncated
        lives = self.env.unwrapped.ale.lives()
        if 0 < lives < self.lives:
            terminated = True
        self.lives = lives
        return obs, reward, terminated, truncated, info

    def reset(self, **kwargs):
        if self.was_real_done:
            obs, info = self.env.reset(**kwargs)
        else:
            obs, _, terminated, truncated, info = self.env.step(0)
            if terminated or truncated:
                obs, info = self.env.reset(**kwargs)
        self.lives = self.env.unwrapped.ale.lives()
        return obs, info


class MaxAndSkipEnv(gym.Wrapper):
    def __init__(self, env, skip=4):
        super().__init__(env)
        self._obs_buffer = np.zeros((2,) + env.observation_space.shape, env.observation_space.dtype)
        self._skip = skip

    def step(self, action):
        total_reward, terminated, truncated, info = 0.0, False, False, {}
        for i in range(self._skip):
            obs, reward, terminated, truncated, info = self.env.step(action)
            if i == self._skip - 2:
                self._obs_buffer[0] = obs
            if i == self._skip - 1:
                self._obs_buffer[1] = obs
            total_reward += float(reward)
            if terminated or truncated:
                break
        return self._obs_buffer.max(axis=0), total_reward, terminated, truncated, info


class ClipRewardEnv(gym.RewardWrapper):
    def reward(self, reward):
        return np.sign(reward)


def cleanrl_env(env_id, **kwargs):
    """CleanRL's ppo_atari.py make_env stack (its SB3 wrappers, then gymnasium's)."""
    env = gym.make(env_id, **kwargs)
    env = gym.wrappers.RecordEpisodeStatistics(env)
    env = NoopResetEnv(env, noop_max=30)
    env = MaxAndSkipEnv(env, skip=4)
    env = EpisodicLifeEnv(env)
    if "FIRE" in env.unwrapped.get_action_meanings():
        env = FireResetEnv(env)
    env = ClipRewardEnv(env)
    env = gym.wrappers.ResizeObservation(env, (84, 84))
    env = gym.wrappers.GrayscaleObservation(env)
    return gym.wrappers.FrameStackObservation(env, 4)


def test_ale_grayscale_is_ales_own_luminance():
    """getScreenGrayscale of the stand-in is ALE's: compared pixel for pixel with ale-py's."""
    import ale_py
    from ale_py import roms

    from stori_jax.compat.ale import ale_grayscale

    ale_py.ALEInterface.setLoggerMode(ale_py.LoggerMode.Error)
    rng = np.random.default_rng(0)
    for rom in ("breakout", "boxing", "gopher", "bank_heist"):
        ale = ale_py.ALEInterface()
        ale.loadROM(roms.get_rom_path(rom))
        actions = ale.getMinimalActionSet()
        for t in range(120):
            ale.act(actions[rng.integers(len(actions))])
            if t % 40 == 39:
                np.testing.assert_array_equal(ale_grayscale(ale.getScreenRGB()),
                                              ale.getScreenGrayscale())


def test_atari_preprocessing_over_a_noframeskip_id_plays_ale_pys_frames():
    """gymnasium's AtariPreprocessing (frame skip, max-pool, resize, terminal_on_life_loss
    through ale.lives(), ale.getScreenGrayscale into its buffers) and FrameStackObservation
    run unchanged over stori_ALE/...NoFrameskip-v4; over preset 3.1 (nothing random) they see
    exactly what they see over ale-py's own env, frame for frame."""
    import ale_py

    gym.register_envs(ale_py)

    def run(env):
        env = gym.wrappers.FrameStackObservation(
            gym.wrappers.AtariPreprocessing(env, noop_max=0, terminal_on_life_loss=True), 4)
        try:
            obs, _ = env.reset(seed=0)
            frames, flags = [obs], []
            rng = np.random.default_rng(0)
            for _ in range(40):  # a life is lost at step 28
                obs, reward, terminated, truncated, info = env.step(int(rng.integers(4)))
                frames.append(obs)
                flags.append((reward, terminated, truncated, info["lives"]))
                if terminated or truncated:
                    frames.append(env.reset()[0])
            return env.observation_space, np.stack(frames), flags
        finally:
            env.close()

    ours = run(gym.make("stori_jax:stori_ALE/BreakoutNoFrameskip-3.1-v4", num_workers=0))
    theirs = run(gym.make("ALE/Breakout-v5", frameskip=1, repeat_action_probability=0.0))
    assert ours[0] == theirs[0] == gym.spaces.Box(0, 255, (4, 84, 84), np.uint8)
    np.testing.assert_array_equal(ours[1], theirs[1])
    assert ours[2] == theirs[2]
    assert sum(terminated for _, terminated, _, _ in ours[2]) >= 1  # a life lost on the way


def test_cleanrls_wrapper_stack_runs_over_a_preset_and_a_seed_repeats_the_run():
    """CleanRL's ppo_atari.py stack (NoopReset, MaxAndSkip, EpisodicLife, FireReset, ClipReward,
    resize, gray, stack) over a 2.1 preset: EpisodicLifeEnv ends the agent's episode exactly
    where the game's lives drop, and seed 5's run is the same twice (and not seed 6's)."""
    def run(seed, steps=30):
        env = cleanrl_env("stori_jax:stori_ALE/BreakoutNoFrameskip-2.1-v4", num_workers=0)
        try:
            obs, _ = env.reset(seed=seed)
            assert obs.shape == (4, 84, 84) and obs.dtype == np.uint8
            trace, lives = [obs], env.unwrapped.ale.lives()
            rng = np.random.default_rng(1)
            lost = 0
            for _ in range(steps):
                obs, reward, terminated, truncated, info = env.step(int(rng.integers(4)))
                assert reward in (-1.0, 0.0, 1.0)
                lost += terminated
                assert terminated == (info["lives"] < lives or bool(info["lives"] == 0))
                lives = info["lives"]
                trace.append(obs)
                if terminated or truncated:
                    obs, _ = env.reset()
                    lives = env.unwrapped.ale.lives()
                    trace.append(obs)
            assert lost or steps < 30, "a life should be lost within 30 steps"
            return np.stack(trace)
        finally:
            env.close()

    first = run(5)
    np.testing.assert_array_equal(first, run(5))
    assert not np.array_equal(first[:11], run(6, steps=10))


@pytest.mark.parametrize("game", stori_jax.STORI_GAMES)
def test_the_ale_stand_in_before_the_first_reset_answers_as_ale_pys(game):
    """ale.lives() before the first reset raised; ale-py's answers the game's lives at power-on
    (Breakout 5, Boxing 0, Gopher 3, BankHeist 4) and game_over() False, as the stand-in now
    does, without a step.  What needs no emulator answers as ale-py's; the screen and the RAM
    say to call reset()."""
    import ale_py

    gym.register_envs(ale_py)
    theirs = gym.make(f"ALE/{game}-v5").unwrapped
    env = gym.make(f"stori_ALE/{game}-2.1-v5", num_workers=0)
    try:
        ale, their_ale = env.unwrapped.ale, theirs.ale
        assert ale.lives() == their_ale.lives() == stori_jax.get_game(game).start_lives
        assert ale.game_over() is their_ale.game_over() is False
        assert ale.game_over(with_truncation=False) is False
        assert ale.getScreenDims() == tuple(their_ale.getScreenDims())
        assert ale.getRAMSize() == their_ale.getRAMSize()
        assert ale.getMinimalActionSet() == list(their_ale.getMinimalActionSet())
        assert ale.getLegalActionSet() == list(their_ale.getLegalActionSet())
        assert env.unwrapped.get_action_meanings() == theirs.get_action_meanings()
        for name in ("getScreenRGB", "getScreenGrayscale", "getRAM"):
            with pytest.raises(RuntimeError, match=rf"ale\.{name}\(\): call reset\(\) first"):
                getattr(ale, name)()
        assert env.unwrapped._env.phase is stori_jax.Phase.NEEDS_RESET  # no reset, no step
        _, info = env.reset(seed=0)
        theirs.reset(seed=0)
        assert ale.lives() == int(info["lives"]) == their_ale.lives()
    finally:
        env.close()
        theirs.close()


def test_a_game_outside_stori_counts_its_power_on_lives_as_ale_does():
    import ale_py

    gym.register_envs(ale_py)
    for game in ("Pong", "MontezumaRevenge"):
        theirs = gym.make(f"ALE/{game}-v5")
        try:
            assert stori_jax.get_game(game).start_lives == theirs.unwrapped.ale.lives()
        finally:
            theirs.close()


def test_ale_keywords_have_ale_pys_meanings():
    """obs_type (rgb / grayscale / ram), max_num_frames_per_episode, render('rgb_array'),
    ale.lives() / getRAM / get_action_meanings, and repeat_action_probability as STORI's
    sticky type 1."""
    import ale_py

    from stori_jax.compat.ale import ale_grayscale

    gym.register_envs(ale_py)
    env = gym.make("stori_jax:stori_ALE/Breakout-3.1-v5", render_mode="rgb_array", num_workers=0,
                   max_num_frames_per_episode=8)
    try:
        assert env.unwrapped._frameskip == 4 and env.observation_space.shape == (210, 160, 3)
        assert env.unwrapped.get_action_meanings() == \
            gym.make("ALE/Breakout-v5").unwrapped.get_action_meanings()
        obs, info = env.reset(seed=0)
        np.testing.assert_array_equal(env.render(), obs)
        np.testing.assert_array_equal(env.unwrapped.ale.getScreenGrayscale(), ale_grayscale(obs))
        assert env.unwrapped.ale.lives() == info["lives"] == 5
        np.testing.assert_array_equal(env.unwrapped.ale.getRAM(), info["ram"])
        assert env.step(1)[3] is False and env.step(1)[3] is True  # truncated at frame 8
        with pytest.raises(AttributeError, match=r"ale\.act: stori_jax's stand-in .* lives"):
            env.unwrapped.ale.act(1)
    finally:
        env.close()
    gray = gym.make("stori_ALE/Breakout-3.1-v5", obs_type="grayscale", num_workers=0)
    try:
        assert gray.observation_space.shape == (210, 160)
        assert gray.reset(seed=0)[0].shape == (210, 160)
    finally:
        gray.close()
    sticky = gym.make("stori_ALE/Breakout-3.1-v5", repeat_action_probability=0.25, obs_type="ram",
                      num_workers=0)
    try:
        assert sticky.unwrapped._env.config.action_noise == stori_jax.ActionNoise(0.25,
                                                                                  sticky=True)
        assert sticky.observation_space.shape == (128,)
        obs, info = sticky.reset(seed=0)
        np.testing.assert_array_equal(obs, info["ram"])
        with pytest.raises(RuntimeError, match=r"getScreenRGB\(\): this env observes 'ram'"):
            sticky.unwrapped.ale.getScreenRGB()
        corrupted = [sticky.step(t % 4)[4]["action_corrupted"] for t in range(20)]
        assert np.any(corrupted)  # repeats of the previous action, per emulator frame
    finally:
        sticky.close()


@pytest.mark.parametrize("env_id, kwargs, pattern", [
    ("stori_ALE/Breakout-1-v5", dict(repeat_action_probability=0.25),
     r"repeat_action_probability=0\.25 .*: this preset already corrupts actions"),
    ("stori_ALE/Breakout-3.1-v5", dict(repeat_action_probability=0.25, granularity="step"),
     r"ALE repeats actions per emulator frame.*granularity 'step'"),
    ("stori_ALE/Breakout-3.1-v5", dict(full_action_space=True),
     r"full_action_space=True is not supported: stori_jax plays the game's minimal action set"),
    ("stori_ALE/Breakout-3.1-v5", dict(mode=1), r"mode=1 is not supported"),
    ("stori_ALE/Breakout-3.1-v5", dict(difficulty=1), r"difficulty=1 is not supported"),
    ("stori_ALE/Breakout-3.1-v5", dict(continuous=True), r"continuous=True is not supported"),
    ("stori_ALE/Breakout-3.1-v5", dict(sound_obs=True), r"sound_obs=True is not supported"),
    ("stori_ALE/Breakout-3.1-v5", dict(frameskip=(2, 5)), r"frameskip: ale-py's stochastic"),
    ("stori_ALE/Breakout-3.1-v5", dict(obs_type="rgbd"), r"obs_type must be one of"),
    ("stori_ALE/Breakout-3.1-v5", dict(obs="raw"),
     r"obs and ale-py's obs_type name the same setting of the ale-py-style id "
     r"stori_ALE/Breakout-3\.1-v5: pass obs_type only"),
    ("stori_jax/Breakout-3.1-v0", dict(frame_skip=1, frameskip=1),
     r"frame_skip and ale-py's frameskip name the same setting of this env"),
    ("stori_ALE/BreakoutNoFrameskip-3.1-v4", dict(obs_type="ram", render_mode="rgb_array"),
     r"render_mode='rgb_array' needs the screens.*got obs_type='ram'"),
])
def test_ale_keywords_it_cannot_honour_are_refused_by_name(env_id, kwargs, pattern):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # gymnasium's own warnings about render modes
        with pytest.raises(ValueError, match=pattern):
            gym.make(env_id, **kwargs)
    with pytest.raises(ValueError, match="render_mode must be None or one of"):
        StoriGymEnv("Breakout", "3.1", render_mode="human", obs="raw")


def test_the_ale_style_ids_are_registered_beside_the_v0_ones():
    from stori_jax.compat.ale import ale_env_id

    for game, name in stori_jax.list_presets():
        for frameskip in (4, 1):
            spec = gym.spec(ale_env_id(game, name, frameskip))
            assert spec.kwargs["frameskip"] == frameskip and spec.kwargs["obs_type"] == "rgb"
            assert spec.kwargs["repeat_action_probability"] == 0.0
    assert gym.spec("stori_jax/Breakout-2.1-v0").kwargs.get("ale_style") is None


def test_the_docs_gymnasium_recipes_run_as_written(monkeypatch):
    """docs/drop-in.md's gymnasium recipes, as written: AtariPreprocessing over a NoFrameskip
    id, and CleanRL's make_env over SB3's wrappers (the classes above stand in for
    stable_baselines3, which is no dependency) in a SyncVectorEnv."""
    import sys
    import types
    from pathlib import Path

    text = (Path(__file__).parent.parent / "docs" / "drop-in.md").read_text()

    def recipe(name):
        after = text.split(f"<!-- recipe: {name} -->", 1)[1]
        return after.split("```python\n", 1)[1].split("```", 1)[0]

    wrappers = types.ModuleType("stable_baselines3.common.atari_wrappers")
    for cls in (ClipRewardEnv, EpisodicLifeEnv, FireResetEnv, MaxAndSkipEnv, NoopResetEnv):
        setattr(wrappers, cls.__name__, cls)
    for name in ("stable_baselines3", "stable_baselines3.common"):
        monkeypatch.setitem(sys.modules, name, types.ModuleType(name))
    monkeypatch.setitem(sys.modules, "stable_baselines3.common.atari_wrappers", wrappers)
    for name in ("gymnasium-atari-preprocessing", "gymnasium-cleanrl"):
        ns = {}
        exec(compile(recipe(name), "docs/drop-in.md", "exec"), ns)
    assert ns["next_obs"].shape == (2, 4, 84, 84) and ns["envs"].closed
