"""Env.snapshot / Env.restore: a restored env continues bit for bit as the original would."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import stori_jax
from stori_jax import Config, RandomEvent

from _env_support import breakout_tracker, to_numpy


def play(env, steps: int, seed: int) -> list:
    rng = np.random.default_rng(seed)
    record = []
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(
            rng.integers(0, env.num_actions, env.num_envs))
        record.append([np.asarray(x).copy() for x in (
            obs, reward, terminated, truncated, info["event_fired"], info["action_corrupted"],
            info["episode_return"])])
    return record


def fired(record) -> int:
    return int(sum(step[4].sum() for step in record))


@pytest.mark.parametrize("game,preset,kw", [
    ("Breakout", "2.1", dict(num_workers=1, inline_envs=1)),   # events, an inline share
    ("Boxing", "3.2C", dict(num_workers=2)),                   # RAM-obs renders
    ("Breakout", "1", dict(num_workers=1, granularity="frame")),  # sticky state in JAX
])
def test_restored_env_continues_exactly(game, preset, kw):
    with stori_jax.make(game, preset, num_envs=3, seed=5, **kw) as env:
        env.reset()
        play(env, 150, seed=0)
        snap = env.snapshot()
        expected = play(env, 120, seed=1)
    # a different seed: everything that matters comes from the snapshot
    with stori_jax.make(game, preset, num_envs=3, seed=77, **kw) as env:
        env.reset()
        env.restore(snap)
        got = play(env, 120, seed=1)
    assert_same(expected, got)


def assert_same(expected, got):
    for step, (a, b) in enumerate(zip(expected, got)):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y, err_msg=f"step {step}")


# events that fire, and the per-episode state the workers keep for them
EVENT_CASES = {
    # the colour flip toggles a per-episode 'flipped' flag before frames
    "boxing-colour-flip": ("Boxing", RandomEvent(1, 0.02), dict(num_workers=2)),
    # the fuel leak marks the cities that leaked this episode (episodes of 100 steps)
    "bankheist-fuel-leak": ("BankHeist", RandomEvent(2, 0.5),
                            dict(num_workers=1, inline_envs=1, max_episode_frames=400)),
    # a carrot dies once per episode: fired before the snapshot, never again after it
    "gopher-carrot-dies": ("Gopher", RandomEvent(3, 0.05), dict(num_workers=1)),
}


def rule_states(env) -> list:
    return [emulator["rule_state"] for emulator in env.snapshot()["emulators"]]


@pytest.mark.parametrize("name", EVENT_CASES)
def test_restored_env_continues_its_events_exactly(name):
    game, event, kw = EVENT_CASES[name]
    config = Config(event=event)
    with stori_jax.make(game, config=config, num_envs=3, seed=5, **kw) as env:
        env.reset()
        before = play(env, 150, seed=0)
        snap = env.snapshot()
        expected = play(env, 120, seed=1)
        expected_states = rule_states(env)
    with stori_jax.make(game, config=config, num_envs=3, seed=77, **kw) as env:
        env.reset()
        env.restore(snap)
        # the events' own state comes back whole (a BankHeist run whose robber never meets a
        # leaked maze again would not show a lost 'leaked' set in play)
        assert rule_states(env) == [e["rule_state"] for e in snap["emulators"]]
        got = play(env, 120, seed=1)
        assert rule_states(env) == expected_states
    assert fired(before) > 0, "the event's state should be engaged before the snapshot"
    if name == "gopher-carrot-dies":
        assert fired(expected) == 0  # once per episode: the restored env must remember it
    else:
        assert fired(expected) > 0
    assert_same(expected, got)


def test_restore_checks_the_env_is_alike():
    with stori_jax.make("Breakout", "3.1", num_envs=2, seed=0, num_workers=1) as env:
        env.reset()
        snap = env.snapshot()
    with stori_jax.make("Breakout", "1", num_envs=2, seed=0, num_workers=1) as other:
        other.reset()
        with pytest.raises(ValueError, match=r"different env .*: noise None there, \S+") as e:
            other.restore(snap)
        assert ";" not in str(e.value), "only the differing field is named"
        with pytest.raises(ValueError, match="Env.snapshot"):
            other.restore({"plan": None})
    # the frame limit is an emulator setting, not part of the plan: it diverged silently
    with stori_jax.make("Breakout", "3.1", num_envs=2, seed=0, num_workers=1,
                        max_episode_frames=40) as other:
        other.reset()
        with pytest.raises(ValueError, match="max_episode_frames 108000 there, 40 here"):
            other.restore(snap)
        other.step(np.zeros(2, np.int32))  # refused before anything changed: still usable
    with stori_jax.make("Breakout", "3.1", num_envs=3, seed=0, num_workers=1) as other:
        other.reset()
        with pytest.raises(ValueError, match="num_envs 2 there, 3 here"):
            other.restore(snap)
    with stori_jax.make("Breakout", "3.1", num_envs=2, seed=1, num_workers=1) as other:
        other.reset()
        other.restore(snap)  # another seed is alike: the run, and the seed, come from the snapshot
        assert other.seed == 0


def test_restore_checks_the_snapshots_parts_before_changing_anything():
    """An edited or damaged snapshot is a ValueError naming the part, and the env goes on as
    it was (a bad state or reset_pending used to fail inside JAX at the next step)."""
    with stori_jax.make("Breakout", "2.1", num_envs=2, seed=0, num_workers=1) as env:
        env.reset()
        snap = env.snapshot()
        expected = play(env, 3, seed=1)
        env.restore(snap)
        for part, value, message in [
                ("emulators", None, r"snapshot\['emulators'\] must be the list"),
                ("emulators", [None, None], r"snapshot\['emulators'\] must be the list"),
                ("state", None, r"snapshot\['state'\] must be the EnvState .*key uint32\[2\]"),
                ("state", tuple(np.zeros(3) for _ in snap["state"]), r"snapshot\['state'\]"),
                ("state", tuple(snap["state"])[:3], r"snapshot\['state'\]"),
                ("reset_pending", "abc", r"reset_pending'\] must be a bool array of shape \(2,\)"),
                ("reset_pending", np.array([True]), r"reset_pending'\] must be a bool array"),
                ("reset_pending", np.zeros(2, np.int64), r"reset_pending'\] must be a bool array"),
                ("seed", -5, r"snapshot\['seed'\] must be in \[0, 2147483647\], got -5"),
                ("seed", "abc", r"snapshot\['seed'\] must be an int")]:
            with pytest.raises(ValueError, match=message):
                env.restore(dict(snap, **{part: value}))
        assert env.seed == 0
        assert_same(expected, play(env, 3, seed=1))


def test_snapshot_needs_a_settled_env():
    with stori_jax.make("Breakout", num_envs=2, seed=0, num_workers=1) as env:
        with pytest.raises(RuntimeError, match="reset"):
            env.snapshot()
        env.reset()
        env.send(np.zeros(2, np.int32))
        with pytest.raises(RuntimeError, match="in flight"):
            env.snapshot()
        env.recv()
        assert len(env.snapshot()["emulators"]) == 2


def test_envpool_backend_cannot_snapshot():
    pytest.importorskip("envpool")
    with stori_jax.make("Breakout", num_envs=2, seed=0, backend="envpool", autoreset=False,
                        granularity="step") as env:
        env.reset()
        with pytest.raises(ValueError, match="backend='subproc'"):
            env.snapshot()


def track(env, ram, steps: int):
    """Step ``env`` ``steps`` times under the ball-tracking policy, starting from RAM ``ram``:
    (per step a dict of obs, reward, terminated, truncated and info as numpy, the last RAM)."""
    record = []
    for _ in range(steps):
        out = to_numpy(env.step(breakout_tracker(ram)))
        record.append(dict(zip(("obs", "reward", "terminated", "truncated", "info"), out)))
        ram = record[-1]["info"]["ram"]
    return record, ram


def test_restored_env_continues_a_block_hit_cancel_exactly():
    """Breakout's block-hit cancel (event mode 1, p = 0.5) compares each frame's blocks with the
    previous frame's RAM: a restored env must take that RAM from the snapshot.  Left at the
    fresh env's own first RAM (every block standing), the blocks hit before the snapshot look
    hit anew on the first frame after it, and the cancel rebuilds them."""
    config = Config(event=RandomEvent(1, 0.5))
    kw = dict(config=config, num_envs=2, num_workers=1, inline_envs=1)
    with stori_jax.make("Breakout", seed=5, **kw) as env:
        _, info = env.reset()
        before, ram = track(env, np.asarray(info["ram"]), 150)
        snap = env.snapshot()
        expected, _ = track(env, ram, 60)
    with stori_jax.make("Breakout", seed=77, **kw) as env:
        _, info = env.reset()
        fresh_ram = np.asarray(info["ram"])
        env.restore(snap)
        got, _ = track(env, ram, 60)
    # engaged: blocks were hit before the snapshot (so the previous RAM the rule reads differs
    # from a fresh episode's in the bytes it compares), and the event fires after it
    assert sum(step["reward"].sum() for step in before) > 0
    assert (ram[:, :36] != fresh_ram[:, :36]).any(axis=1).all()
    assert sum(step["info"]["event_fired"].sum() for step in expected) > 0
    for step, (a, b) in enumerate(zip(expected, got)):  # obs, reward, ends and every info key
        (paths, xs), ys = zip(*jax.tree_util.tree_flatten_with_path(a)[0]), jax.tree.leaves(b)
        assert len(xs) == len(ys)
        for path, x, y in zip(paths, xs, ys):
            np.testing.assert_array_equal(y, x, f"step {step} {jax.tree_util.keystr(path)}")
