"""Reproducibility through ``stori_jax.make`` on real emulators: the same seed gives bit-identical
observations, rewards and infos across runs and across the number of workers; another seed does
not."""

from __future__ import annotations

import functools

import numpy as np
import pytest

import stori_jax
from stori_jax import ActionNoise, Config, ObservationMask, RandomEvent, get_game

from _env_support import emulator_states, make, random_actions, run_env

NUM_ENVS, NUM_STEPS = 4, 24

CASES = {
    # a paper preset (type 1, p = 0.3, per frame), 84x84 stacked observations
    "breakout-preset-1": dict(game="Breakout", preset="1", obs="atari84",
                              max_episode_frames=40),
    # action noise + an event + a RAM-obs mask (rendered through cloneState/restoreState),
    # every draw per frame, random no-ops after each reset, 64x64 RGB observations
    "bankheist-mixed": dict(
        game="BankHeist", obs="dreamer64", noop_max=20, max_episode_frames=40,
        config=Config(action_noise=ActionNoise(0.3), event=RandomEvent(3, 0.05),
                      observation=ObservationMask("ram", 3, 0.5))),
}


def _run(name, seed, num_workers, num_envs=NUM_ENVS, inline_envs=0):
    case = dict(CASES[name])
    game = case.pop("game")
    env = make(game, num_envs=num_envs, seed=seed, num_workers=num_workers,
               inline_envs=inline_envs, **case)
    try:
        actions = random_actions(get_game(game).num_actions, NUM_STEPS, NUM_ENVS, seed=123)
        return run_env(env, actions[:, :num_envs])
    finally:
        env.close()


@functools.lru_cache(maxsize=None)
def _reference_run(name):
    """seed 7, every env in this process: the run every other one is compared with (made once
    per module)."""
    return _run(name, seed=7, num_workers=0, inline_envs=None)


def _assert_identical(a, b, what):
    np.testing.assert_array_equal(a.reset_obs, b.reset_obs, err_msg=f"{what}: reset obs")
    _assert_tree_equal(a.reset_info, b.reset_info, f"{what}: reset info")
    for name in ("obs", "reward", "terminated", "truncated"):
        np.testing.assert_array_equal(a.stacked(name), b.stacked(name), err_msg=f"{what}: {name}")
    for k, (ia, ib) in enumerate(zip(a.info, b.info)):
        _assert_tree_equal(ia, ib, f"{what}: info of step {k}")


def _assert_tree_equal(a, b, what):
    assert isinstance(a, dict) and set(a) == set(b), what
    for key in a:
        if isinstance(a[key], dict):
            _assert_tree_equal(a[key], b[key], f"{what}[{key}]")
        else:
            assert a[key].dtype == b[key].dtype, (what, key)
            np.testing.assert_array_equal(a[key], b[key], err_msg=f"{what}[{key}]")


@pytest.mark.slow
@pytest.mark.parametrize("name", CASES)
def test_same_seed_is_bit_identical_across_runs_and_worker_counts(name):
    """Every split of the batch (no worker, one worker with all envs, one worker per env, one
    worker beside two envs in this process) plays seed 7's run bit for bit."""
    first = _reference_run(name)
    for workers, inline in ((1, 0), (NUM_ENVS, 0), (1, 2)):
        _assert_identical(first, _run(name, seed=7, num_workers=workers, inline_envs=inline),
                          f"{name}: no worker vs {workers} worker(s) + {inline} inline envs")
    # the run is genuinely random: every case corrupts actions, and some did in these steps
    assert first.stacked("action_corrupted").any(), name
    # and it crosses episode ends (truncated at 40 frames): autoresets, their no-ops and draws
    assert first.done.sum() >= 2 * NUM_ENVS, name


@pytest.mark.parametrize("name", CASES)
def test_different_seed_gives_a_different_run(name):
    a = _reference_run(name)
    b = _run(name, seed=8, num_workers=0, inline_envs=None)
    assert not np.array_equal(a.stacked("executed_action"), b.stacked("executed_action")), name
    assert not np.array_equal(a.stacked("obs"), b.stacked("obs")), f"{name}: same observations"
    assert not np.array_equal(a.ram, b.ram), f"{name}: same RAM"


@pytest.mark.parametrize("name", CASES)
def test_reset_with_a_seed_restarts_the_run_as_a_fresh_env_of_that_seed(name):
    """``reset(seed=7)`` in an env of another seed, deep in its episodes, gives seed 7's run bit
    for bit (emulators, no-op starts, every draw) in the same worker processes, for the
    workers' envs and the inline ones alike; a plain ``reset()`` then goes on with seed 7's
    streams instead of starting them over."""
    case = dict(CASES[name])
    game = case.pop("game")
    actions = random_actions(get_game(game).num_actions, NUM_STEPS, NUM_ENVS, seed=123)
    reference = _reference_run(name)
    kw = dict(num_envs=NUM_ENVS, num_workers=1, inline_envs=2, **case)
    with make(game, seed=7, **kw) as fresh:
        fresh.reset()
        fresh_states = emulator_states(fresh)
    with make(game, seed=3, **kw) as env:
        pids = env.backend.pids
        run_env(env, actions[:17])
        env.reset(seed=7)  # the emulators, their random generators included, start afresh
        assert emulator_states(env) == fresh_states
        _assert_identical(reference, run_env(env, actions, reset_seed=7),
                          f"{name}: reset(seed=7) vs a new env of seed 7")
        assert env.seed == 7 and env.backend.pids == pids
        assert all(p.is_alive() for p in env.backend.processes)
        _assert_identical(reference, run_env(env, actions, reset_seed=7),
                          f"{name}: reset(seed=7) twice")
        after = run_env(env, actions)
    assert not np.array_equal(after.stacked("executed_action"),
                              reference.stacked("executed_action")), name


def test_a_refused_reset_seed_names_the_field_and_changes_nothing():
    actions = random_actions(get_game("Breakout").num_actions, 6, 2, seed=1)
    with make("Breakout", preset="1", seed=4) as env, \
            make("Breakout", preset="1", seed=4) as twin:
        env.reset(), twin.reset()
        env.step(actions[0]), twin.step(actions[0])
        for seed, a in zip([-1, 2 ** 31, 1.5, "7", True], actions[1:]):
            with pytest.raises(ValueError, match="seed"):
                env.reset(seed=seed)
            assert env.seed == 4
            # the run goes on where it was, as the twin's
            np.testing.assert_array_equal(np.asarray(env.step(a)[4]["ram"]),
                                          np.asarray(twin.step(a)[4]["ram"]), err_msg=repr(seed))


@pytest.mark.parametrize("name", ["bankheist-mixed"])
def test_envs_of_a_batch_are_independent_of_the_batch_size(name):
    """Env i's trajectory is a function of (seed, i) only: the first two envs of the batch of 4
    equal a batch of 2 with the same seed (keys are folded with the env index)."""
    four = _reference_run(name)
    two = _run(name, seed=7, num_workers=0, num_envs=2, inline_envs=None)
    np.testing.assert_array_equal(four.reset_obs[:2], two.reset_obs)
    for key in ("obs", "reward", "terminated", "executed_action", "event_fired", "obs_masked"):
        np.testing.assert_array_equal(four.stacked(key)[:, :2], two.stacked(key), err_msg=key)
    np.testing.assert_array_equal(four.ram[:, :2], two.ram)


def draws_digest() -> str:
    """sha256 of short runs whose every draw kind is on: type-1 replacement per frame, event
    uniforms, gradual drift to torch centres, no-op starts, atari84 resizing (BankHeist); an
    event and gradual drift to sticky actions (Boxing) (obs, RAM, rewards and infos)."""
    import hashlib

    from stori_jax import ConceptDrift

    cases = [
        dict(game="BankHeist", obs="atari84", noop_max=30, max_episode_frames=40, config=Config(
            action_noise=ActionNoise(0.3), event=RandomEvent(3, 0.3), drift=ConceptDrift(
                "gradual", 2, Config(observation=ObservationMask("crop", 5, 0.5))))),
        dict(game="Boxing", obs="ram", config=Config(event=RandomEvent(3, 0.3), drift=ConceptDrift(
            "gradual", 2, Config(action_noise=ActionNoise(0.5, sticky=True))))),
    ]
    digest = hashlib.sha256()
    for case in cases:
        game = case.pop("game")
        with make(game, seed=3, **case) as env:
            run = run_env(env, random_actions(env.num_actions, 8, 2, seed=1))
        assert run.stacked("action_corrupted").any() and run.stacked("event_fired").any()
        for name in ("obs", "reward", "executed_action", "action_corrupted", "obs_masked",
                     "concept", "event_fired"):
            values = run.stacked(name)
            digest.update(f"{name} {values.dtype}".encode() + values.tobytes())
    assert run.stacked("concept").any()  # Boxing's drift reached its sticky actions
    return digest.hexdigest()


def test_a_seed_gives_the_same_run_with_jax_x64_enabled():
    """Research code often turns on ``jax_enable_x64``: the environment's draws must not change
    with it (they did: uniform/randint without a dtype draw 64-bit numbers then)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    tests = Path(__file__).resolve().parent
    code = ("import sys; sys.path.insert(0, sys.argv[1]); import jax; "
            "assert jax.config.jax_enable_x64; "
            "from test_env_repro import draws_digest; print(draws_digest())")
    x64 = subprocess.run([sys.executable, "-c", code, str(tests)], capture_output=True,
                         text=True, env={**os.environ, "JAX_ENABLE_X64": "1"}, timeout=300)
    assert x64.returncode == 0, x64.stderr[-2000:]
    assert x64.stdout.split()[-1] == draws_digest()


@pytest.mark.parametrize("game, name, deterministic", [
    ("Gopher", "3.2", True), ("Boxing", "3.2A", True), ("Breakout", "3.2B", False)])
def test_a_preset_without_a_random_draw_plays_the_same_from_every_seed(game, name,
                                                                       deterministic):
    """Config.is_deterministic (eval's note that a greedy policy plays one episode): under the
    same actions, seeds 0 and 123 give the same observations and rewards, masks included; a
    preset that draws (a crop at p = 0.75) does not."""
    assert stori_jax.preset(game, name).is_deterministic() == deterministic
    runs = []
    for seed in (0, 123):
        with make(game, stori_jax.preset(game, name), seed=seed, obs="raw") as env:
            runs.append(run_env(env, random_actions(env.num_actions, 25, 2, seed=2)))
    same = all(np.array_equal(runs[0].stacked(k), runs[1].stacked(k))
               for k in ("obs", "reward", "obs_masked"))
    assert same == deterministic


def test_each_draw_of_a_step_comes_from_its_own_purpose_stream(monkeypatch):
    """core.before_step with every draw on (action noise, an event, a mask, drift, no-op
    starts) takes each Purpose's keys exactly once: no two kinds of draw share a stream (the
    no-op counts drawn from the action-noise keys would be correlated with the corruptions)."""
    import jax
    import jax.numpy as jnp

    from stori_jax import ConceptDrift, functional as F
    from stori_jax.core import before_step, initial_state
    from stori_jax.plan import compile_plan

    config = Config(action_noise=ActionNoise(0.3), event=RandomEvent(3, 0.05),
                    drift=ConceptDrift("gradual", 2, Config(
                        observation=ObservationMask("crop", 5, 0.5))))
    plan = compile_plan(config, get_game("BankHeist"), num_envs=2, frame_skip=4, obs="raw",
                        noop_max=5)
    assert plan.noise and plan.event and plan.mask and plan.drift_schedule and plan.noop_max
    used, real = [], F.purpose_keys
    monkeypatch.setattr(F, "purpose_keys", lambda keys, purpose: (
        used.append(F.Purpose(purpose)), real(keys, purpose))[1])
    # trace the body (no cached trace, nothing compiled): every call is seen
    jax.eval_shape(lambda state, actions: before_step.__wrapped__(plan, state, actions),
                   initial_state(plan, 0), jnp.zeros((2,), jnp.int32))
    assert sorted(used) == sorted(F.Purpose), used


def test_the_purposes_streams_are_distinct_keys():
    """Each purpose's key differs from every other's for every env (two purposes sharing a
    stream would correlate, e.g., an action corruption with a mask decision)."""
    import jax

    from stori_jax import functional as F

    keys = F.env_keys(jax.random.PRNGKey(0), 3)
    data = {p: np.asarray(jax.random.key_data(F.purpose_keys(keys, p))) for p in F.Purpose}
    for a in F.Purpose:
        for b in F.Purpose:
            if a < b:
                assert not (data[a] == data[b]).all(axis=-1).any(), (a, b)


def test_configs_differing_only_in_numbers_share_every_compilation():
    """A Config's numbers (probabilities, the drift period) are traced, not static: a sweep
    over ``prob`` or ``period`` compiles nothing after its first config, and the numbers still
    take effect (0 and 1 corrupt no action and every action)."""
    from stori_jax import core
    from stori_jax.config import ActionNoise, ConceptDrift, Config, ObservationMask

    def config(prob, period):
        return Config(drift=ConceptDrift("gradual", period, Config(action_noise=ActionNoise(prob))),
                      observation=ObservationMask("crop", 5, prob))

    def compiled():
        return (core.before_step._cache_size(), core.after_step._cache_size(),
                core.push_frames._cache_size())

    corrupted = []
    for i, (prob, period) in enumerate([(0.0, 1), (1.0, 1), (0.25, 3)]):
        with stori_jax.make("Breakout", config=config(prob, period), num_envs=2, seed=0,
                            max_episode_frames=40) as env:
            env.reset()
            seen = 0
            for _ in range(8):
                seen += int(np.asarray(env.step([1, 1])[4]["action_corrupted"]).sum())
            corrupted.append(seen)
            if i == 0:
                first = compiled()
            else:
                assert compiled() == first, f"prob {prob}, period {period} compiled again"
    assert corrupted[0] == 0 and corrupted[1] > 0


def test_a_reused_emulator_plays_as_a_freshly_loaded_one():
    """An emulator given back by a closed env and taken again for another seed (or put back to
    a seed by a reseeding reset) is, frame for frame over two episodes' starts, ALE freshly
    loaded with that seed: RAM, screen, reward, lives, the episode's end."""
    from ale_py import ALEInterface, roms

    from stori_jax.backends import ale_cache

    rom, frames = roms.get_rom_path("breakout"), 2000
    used = ale_cache.acquire(rom, frames, seed=7)
    for _ in range(300):
        used.act(used.getMinimalActionSet()[1])
    ale_cache.release(used, rom, frames)
    reused = ale_cache.acquire(rom, frames, seed=3)
    assert reused is used  # (the test is of reuse)
    for _ in range(100):
        reused.act(reused.getMinimalActionSet()[2])
    ale_cache.reload(reused, rom, frames, seed=3)  # a reseeding reset: restored, not reloaded
    fresh = ALEInterface()
    fresh.setInt("random_seed", 3)
    fresh.setFloat("repeat_action_probability", 0.0)
    fresh.setInt("max_num_frames_per_episode", frames)
    fresh.loadROM(rom)
    rng = np.random.default_rng(0)
    actions = fresh.getMinimalActionSet()
    for episode in range(2):
        fresh.reset_game(), reused.reset_game()
        for frame in range(400):
            action = actions[rng.integers(len(actions))]
            assert fresh.act(action) == reused.act(action)
            assert np.array_equal(fresh.getRAM(), reused.getRAM()), (episode, frame)
            assert np.array_equal(fresh.getScreenRGB(), reused.getScreenRGB()), (episode, frame)
            assert (fresh.lives(), fresh.game_over()) == (reused.lives(), reused.game_over())
    ale_cache.release(reused, rom, frames)
