"""The envpool backend: what it supports, clear errors for what it cannot, reproducibility."""

from pathlib import Path

import numpy as np
import pytest

import stori_jax
from _env_support import new_ale

envpool = pytest.importorskip("envpool")

EP = dict(backend="envpool", autoreset=False, granularity="step")


def on(backend):
    """make()'s keywords for ``backend`` with what the envpool backend needs, on both."""
    return EP if backend == "envpool" else dict(autoreset=False, granularity="step")


def run(game, preset, steps=40, seed=0, obs="raw", **kwargs):
    with stori_jax.make(game, preset, num_envs=3, seed=seed, obs=obs, **{**EP, **kwargs}) as env:
        return trace(env, steps)


def trace(env, steps, reset_seed=None):
    """(observations, rewards, RAMs, last info) of ``steps`` random steps after a reset."""
    obs_, info = env.reset(seed=reset_seed)
    observations = [np.asarray(obs_)]
    rewards, rams = [], []
    rng = np.random.default_rng(1)
    for _ in range(steps):
        obs_, reward, terminated, truncated, info = env.step(
            rng.integers(0, env.num_actions, env.num_envs))
        observations.append(np.asarray(obs_))
        rewards.append(np.asarray(reward))
        rams.append(np.asarray(info["ram"]))
    return np.stack(observations), np.stack(rewards), np.stack(rams), info


def test_reset_with_a_seed_restarts_the_run_as_a_fresh_env_of_that_seed():
    """envpool cannot reseed a pool: reset(seed=k) starts a new one, and the run is seed k's."""
    expected = run("Breakout", "1", seed=4)
    with stori_jax.make("Breakout", "1", num_envs=3, seed=9, obs="raw", **EP) as env:
        other = trace(env, 25)
        got = trace(env, 40, reset_seed=4)
        assert env.seed == 4
    for x, y in zip(expected[:3], got[:3]):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(other[2], got[2][:25])


@pytest.mark.parametrize("game, preset, random", [
    ("Breakout", "1", True), ("Breakout", "3.2A", False), ("Boxing", "3.2B", True),
    ("Gopher", "2.2", False)])
def test_supported_presets_run_and_reproduce(game, preset, random):
    a = run(game, preset)
    b = run(game, preset)
    for x, y in zip(a[:3], b[:3]):
        np.testing.assert_array_equal(x, y)
    other = run(game, preset, seed=1)
    # the emulators are deterministic: another seed changes the run only through the
    # perturbations' draws (action noise, mask probability)
    assert np.array_equal(a[0], other[0]) != random


def test_blackout_is_exact_on_envpool_frames():
    masked, _, _, info = run("Breakout", "3.2A", steps=10)
    plain, _, _, _ = run("Breakout", "3.1", steps=10)
    regions = stori_jax.get_game("Breakout").blackout_modes[10].regions
    hidden = np.zeros((210, 160), bool)
    for r in regions:
        hidden[r.y0:r.y1 + 1, r.x0:r.x1 + 1] = True
    assert (masked[:, :, hidden] == 0).all()
    np.testing.assert_array_equal(masked[:, :, ~hidden], plain[:, :, ~hidden])
    assert np.asarray(info["obs_masked"]).all()


def test_type0_ram_observation():
    cfg = stori_jax.Config(ram_observation=True)
    with stori_jax.make("Boxing", config=cfg, num_envs=2, seed=0, **EP) as env:
        obs, info = env.reset()
        obs, *_, info = env.step(np.zeros(2, np.int32))
        assert obs.shape == (2, 128)
        np.testing.assert_array_equal(np.asarray(obs), np.asarray(info["ram"]))
        assert set(info["labels"]) >= {"player_x", "enemy_x"}


def test_episode_statistics_and_next_step_reset():
    """Each episode's return and length are counted from the step envpool reset it on (its
    second episode too, not from the first one's start); the step after an episode's end is its
    reset step, with reward 0."""
    with stori_jax.make("Breakout", num_envs=2, seed=3, obs="ram", **EP) as env:
        env.reset()
        rng = np.random.default_rng(0)
        total, length, ended = np.zeros(2), np.zeros(2, int), np.zeros(2, int)
        done = np.zeros(2, bool)
        for _ in range(3000):
            _, reward, terminated, truncated, info = env.step(rng.integers(0, 4, 2))
            reset_step = np.asarray(info["reset_step"])
            np.testing.assert_array_equal(reset_step, done)
            np.testing.assert_array_equal(info["frames_played"], np.where(reset_step, 0, 4))
            assert not np.asarray(reward)[reset_step].any()
            total = np.where(reset_step, 0, total + np.asarray(reward))
            length = np.where(reset_step, 0, length + 1)
            done = np.asarray(terminated | truncated)
            np.testing.assert_array_equal(np.asarray(info["episode_return"]),
                                          np.where(done, total, 0))
            np.testing.assert_array_equal(np.asarray(info["episode_length"]),
                                          np.where(done, length, 0))
            ended += done
            if ended.min() >= 2 and not done.any():  # a reset step after each second end
                return
    pytest.fail(f"too few episodes ended: {ended}")


@pytest.mark.parametrize("kwargs, message", [
    (dict(preset="2.1"), "2.1 random events write the RAM"),
    (dict(preset="3.2C", game="Boxing"), "RAM observation modes"),
    (dict(preset="1", granularity="frame"), "type 1 at 'frame' granularity"),
    (dict(preset="3.2B", granularity="frame"), "masks at 'frame' granularity"),
    (dict(preset="3.1", autoreset=True), "pass autoreset=False"),
    # every reason at once, not one fix at a time
    (dict(preset="1", granularity="frame", autoreset=True),
     r"'frame' granularity needs an action per emulator frame \(use granularity='step'\); "
     r"envpool autoresets on the next step: pass autoreset=False; use backend='subproc'"),
])
def test_unsupported_configs_name_the_subproc_backend(kwargs, message):
    args = {**EP, **kwargs}
    game = args.pop("game", "Breakout")
    preset = args.pop("preset")
    with pytest.raises(ValueError, match=message) as e:
        stori_jax.make(game, preset, num_envs=2, seed=0, **args)
    assert "backend='subproc'" in str(e.value)


def test_a_timeout_is_refused_before_anything_is_sent():
    with stori_jax.make("Breakout", num_envs=2, seed=0, obs="ram", **EP) as env:
        with pytest.raises(ValueError, match=r"reset\(timeout=...\) needs backend='subproc'"):
            env.reset(timeout=1.0)
        env.reset()
        with pytest.raises(ValueError, match=r"step\(timeout=...\) needs backend='subproc'"):
            env.step(np.zeros(2, np.int32), timeout=1.0)
        env.send(np.zeros(2, np.int32))  # step() sent nothing
        with pytest.raises(ValueError, match=r"recv\(timeout=...\) needs backend='subproc'"):
            env.recv(timeout=1.0)
        env.recv()  # the step was neither lost nor half-done


def test_snapshots_are_refused_naming_the_subproc_backend():
    """envpool cannot save or load its emulators: snapshot() and restore() say so (restore did
    first compare the snapshot with the env, and asked for an env made alike instead)."""
    with stori_jax.make("Breakout", num_envs=2, seed=0, obs="ram", num_workers=0,
                        **on("subproc")) as env:
        env.reset()
        snapshot = env.snapshot()
    with stori_jax.make("Breakout", num_envs=2, seed=0, obs="ram", **EP) as env:
        env.reset()
        with pytest.raises(ValueError, match=r"snapshot.*use backend='subproc'"):
            env.snapshot()
        with pytest.raises(ValueError, match=r"^backend EnvpoolBackend cannot restore emulators; "
                                             r"use backend='subproc'$"):
            env.restore(snapshot)


def _noop_frames_played(rams):
    """For each env's reset RAM, how many NOOP frames a bare ale-py Breakout played to reach it."""
    ale = new_ale("breakout")
    ale.reset_game()
    reference = []
    for _ in range(8):
        reference.append(ale.getRAM().copy())
        ale.act(0)
    return [[k for k, r in enumerate(reference) if np.array_equal(r, ram)] for ram in rams]


@pytest.mark.parametrize("backend, noop_max, starts", [
    ("subproc", 0, {0}), ("subproc", 2, {0, 1, 2}),
    ("envpool", 0, {1}), ("envpool", 2, {1, 2, 3}),  # envpool always plays at least one
])
def test_noop_starts_play_the_documented_number_of_frames(backend, noop_max, starts):
    cfg = stori_jax.Config(ram_observation=True)
    with stori_jax.make("Breakout", config=cfg, num_envs=16, seed=0, noop_max=noop_max,
                        **on(backend)) as env:
        obs, _ = env.reset()
        played = _noop_frames_played(np.asarray(obs))
    assert all(len(p) == 1 for p in played), played  # each start is one known frame
    # 16 envs over at most 3 starts: every start shows up (each is missed with prob <= (2/3)^16)
    assert {p[0] for p in played} == starts


def test_truncation_comes_at_the_same_step_as_on_subproc():
    """max_episode_frames 6 at frame skip 4: the second step (frames 5-8) reaches it."""
    for backend in ("envpool", "subproc"):
        with stori_jax.make("Breakout", num_envs=1, seed=0, obs="ram", max_episode_frames=6,
                            **on(backend)) as env:
            env.reset()
            truncated = [bool(env.step(np.zeros(1, np.int32))[3][0]) for _ in range(2)]
        assert truncated == [False, True], backend


def test_a_game_over_on_the_step_that_reaches_the_cap_is_terminated_too():
    """envpool's own ``terminated`` is "done and not truncated": the bridge reports ALE's game
    over (as subproc does), so a learner does not bootstrap from a lost game."""
    def first_end(max_episode_frames):
        with stori_jax.make("Breakout", num_envs=1, seed=0, obs="ram",
                            max_episode_frames=max_episode_frames, **EP) as env:
            env.reset()
            rng = np.random.default_rng(0)
            for k in range(5000):
                action = 1 if k < 3 else rng.integers(0, 4)  # FIRE launches the ball
                _, _, terminated, truncated, info = env.step(np.array([action], np.int32))
                if terminated[0] or truncated[0]:
                    return k, bool(terminated[0]), bool(truncated[0]), int(info["lives"][0])
        raise AssertionError("no episode end in 5000 steps")

    k, *outcome = first_end(10**6)
    assert outcome == [True, False, 0]  # the game is lost at step k
    assert first_end((k + 1) * 4) == (k, True, True, 0)  # ... which now reaches the cap too


@pytest.mark.parametrize("name, value", [("noop_max", 2**31 - 1),  # envpool is given noop_max + 1
                                         ("max_episode_frames", 2**31)])
def test_int32_overflow_is_named_before_any_backend_starts(name, value):
    for backend in ("envpool", "subproc"):
        with pytest.raises(ValueError, match=rf"{name} must be in \[\d+, 2147483\d+\]"):
            stori_jax.make("Breakout", num_envs=1, seed=0, **{name: value}, **on(backend))


def test_a_game_envpool_lacks_is_named(monkeypatch):
    monkeypatch.setattr(envpool, "list_all_envs", lambda: [])
    with pytest.raises(ValueError, match="envpool has no Atari task 'Breakout-v5' for game "
                                         "'Breakout'; use backend='subproc'"):
        stori_jax.make("Breakout", num_envs=1, seed=0, **EP)


def test_an_envpool_without_the_ram_in_its_info_is_named(monkeypatch):
    import tomllib

    from stori_jax.backends.envpool import MIN_ENVPOOL_MAJOR

    root = Path(__file__).resolve().parent.parent
    project = tomllib.loads((root / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]
    assert extras["envpool"] == [f"envpool>={MIN_ENVPOOL_MAJOR}.0"]  # the pin says the same
    monkeypatch.setattr(envpool, "__version__", "0.8.4")
    with pytest.raises(ValueError, match=r"needs envpool>=1\.0 .* found envpool 0\.8\.4: pip "
                                         r"install 'stori-jax\[envpool\]'"):
        stori_jax.make("Breakout", num_envs=1, seed=0, **EP)


def test_consecutive_seeds_share_no_emulator_stream():
    """envpool seeds env i with base + i: with base = seed, env i + 1 of seed s replayed env i
    of seed s + 1 (the same no-op starts). The base is now hashed from the seed."""
    pytest.importorskip("envpool")

    def reset_rams(seed):
        with stori_jax.make("Breakout", config=stori_jax.Config(ram_observation=True),
                            num_envs=4, seed=seed, noop_max=30, **EP) as env:
            return np.asarray(env.reset()[0])

    a, b = reset_rams(0), reset_rams(1)
    assert not any(np.array_equal(a[i + 1], b[i]) for i in range(3))
    assert not np.array_equal(a, b)  # nor are both seeds' envs one run (a base ignoring seed)
    np.testing.assert_array_equal(reset_rams(0), a)  # still the same run for the same seed


def test_every_seed_has_its_own_envpool_base():
    """envpool_seed hashes the whole seed: 1000 seeds give 1000 bases, each in envpool's range
    and the same on every call (a base from part of the seed, or none of it, repeats)."""
    from stori_jax.backends.envpool import MAX_BASE_SEED, envpool_seed

    bases = [envpool_seed(s) for s in range(1000)]
    assert len(set(bases)) == 1000
    assert all(0 <= b <= MAX_BASE_SEED for b in bases)
    assert envpool_seed(999) == bases[999]


def test_envpool_rewards_are_the_games_own_score_unclipped():
    """The bridge turns envpool's Atari reward clipping off: Gopher's rewards over 300 random
    steps add up to its score's gain (a filled hole is worth 20; clipped it would be 1)."""
    from stori_jax.games.gopher import score

    with stori_jax.make("Gopher", num_envs=2, seed=0, obs="ram", **EP) as env:
        _, info = env.reset()
        start = score(np.asarray(info["ram"]).astype(int))
        rng, total = np.random.default_rng(0), np.zeros(2)
        for _ in range(300):
            _, reward, terminated, truncated, info = env.step(rng.integers(0, 8, 2))
            assert not (np.asarray(terminated) | np.asarray(truncated)).any()
            total += np.asarray(reward)
    np.testing.assert_array_equal(total, score(np.asarray(info["ram"]).astype(int)) - start)
    assert total.max() >= 20


def test_an_envpool_episode_is_the_whole_game_not_one_life():
    """The bridge turns envpool's episodic life off: Breakout under FIRE alone (the paddle
    never moves) terminates when the last life is lost, not the first."""
    with stori_jax.make("Breakout", num_envs=1, seed=0, obs="ram", **EP) as env:
        env.reset()
        for _ in range(1000):
            _, _, terminated, truncated, info = env.step(np.ones(1, np.int32))
            if terminated[0] or truncated[0]:
                break
    assert terminated[0] and int(info["lives"][0]) == 0


def test_the_pool_gets_the_options_the_bridge_documents():
    """Every option a make() argument maps to, as envpool sees it: the frame skip, no-op starts
    plus one, the hashed seed, the step cap rounded up, and no Atari preprocessing of envpool's
    own (episodic life, reward clipping, fire reset, sticky actions, the full action set)."""
    from stori_jax.backends.envpool import envpool_seed

    with stori_jax.make("Breakout", "3.1", num_envs=2, seed=3, frame_skip=2, noop_max=5,
                        max_episode_frames=1001, **EP) as env:
        config = env.backend.pool.config
        env.reset(seed=7)
        reseeded = env.backend.pool.config["seed"]
    assert {k: config[k] for k in (
        "num_envs", "batch_size", "frame_skip", "noop_max", "seed", "max_episode_steps",
        "stack_num", "img_height", "img_width", "gray_scale", "episodic_life", "reward_clip",
        "use_fire_reset", "repeat_action_probability", "full_action_space")} == dict(
        num_envs=2, batch_size=2, frame_skip=2, noop_max=6, seed=envpool_seed(3),
        max_episode_steps=501, stack_num=1, img_height=210, img_width=160, gray_scale=False,
        episodic_life=False, reward_clip=False, use_fire_reset=False,
        repeat_action_probability=0.0, full_action_space=False)
    assert reseeded == envpool_seed(7)



@pytest.mark.parametrize("call", ["_reset", "_send", "_recv"])
def test_a_ctrl_c_as_a_pool_call_returns_leaves_a_run_that_goes_on_as_asked(call, monkeypatch):
    """A Ctrl-C lands where Python next runs: right after one of the pool's C++ calls.  After
    _reset (inside envpool's reset(), before its recv) it left a reset queued behind the env's
    back, and the env's next reset drove the emulators twice at once (a segfault, or a run
    one command behind).  Now the interrupt comes after the backend's record of the call: the
    env goes on as one whose call was interrupted (recv() for a step in flight, reset()
    otherwise), and its run is that of a twin stepped the same way without interruption."""
    import os
    import signal

    actions = np.random.default_rng(1).integers(0, 4, (12, 3))
    with stori_jax.make("Breakout", "1", num_envs=3, seed=0, obs="raw", **EP) as env, \
            stori_jax.make("Breakout", "1", num_envs=3, seed=0, obs="raw", **EP) as twin:
        env.reset(), twin.reset()
        for a in actions[:4]:
            env.step(a), twin.step(a)
        pool, fired = env.backend.pool, []
        original = getattr(pool, call)

        def interrupted(*args, **kwargs):
            result = original(*args, **kwargs)
            if not fired:
                fired.append(True)
                os.kill(os.getpid(), signal.SIGINT)
            return result

        monkeypatch.setattr(pool, call, interrupted)
        with pytest.raises(KeyboardInterrupt):
            env.reset() if call == "_reset" else env.step(actions[4])
        assert fired
        if env._in_flight is not None:  # the step stayed in flight: recv() takes it
            got, expected = env.recv(), twin.step(actions[4])
        else:  # the env says it needs reset(): a run reset at this point
            with pytest.raises(RuntimeError, match="reset"):
                env.step(actions[4])
            got, expected = env.reset(), twin.reset()
        np.testing.assert_array_equal(np.asarray(got[0]), np.asarray(expected[0]))
        for a in actions[5:]:
            got, expected = env.step(a), twin.step(a)
            for x, y in zip(got[:4], expected[:4]):
                np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
            np.testing.assert_array_equal(np.asarray(got[4]["ram"]),
                                          np.asarray(expected[4]["ram"]))
