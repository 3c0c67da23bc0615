"""Every paper preset's observations and info, pinned (tests/fixtures/preset_digests.json).  A
change that alters one bit of any preset's run fails here.  Regenerate only for a change of semantics:
``python tests/test_pinned_digests.py --record``."""

from __future__ import annotations

import hashlib
import json
import pathlib
import sys

import jax
import numpy as np
import pytest

import stori_jax

FIXTURE = pathlib.Path(__file__).parent / "fixtures" / "preset_digests.json"
NUM_STEPS = 14  # with the episode cap below, every env's episode ends (autoreset, final_obs)
MAX_EPISODE_FRAMES = 40


def preset_names() -> list[tuple[str, str]]:
    return list(stori_jax.list_presets())


def run_digest(game: str, preset: str, **make_kw) -> str:
    """sha256 over the reset's and every step's obs, reward, flags and info of a short run
    (2 envs, one emulated here and one in a worker, random actions of seed 0)."""
    digest = hashlib.sha256()

    def add(tree) -> None:
        for path, value in sorted(jax.tree_util.tree_leaves_with_path(tree),
                                  key=lambda leaf: jax.tree_util.keystr(leaf[0])):
            value = np.asarray(value)
            digest.update(f"{jax.tree_util.keystr(path)} {value.dtype} {value.shape}".encode()
                          + value.tobytes())

    kw = dict(num_envs=2, seed=3, num_workers=1, inline_envs=1,
              max_episode_frames=MAX_EPISODE_FRAMES)
    kw.update(make_kw)
    with stori_jax.make(game, preset, **kw) as env:
        obs, info = env.reset()
        add({"obs": obs, **info})
        rng = np.random.default_rng(0)
        for _ in range(NUM_STEPS):
            actions = rng.integers(0, env.num_actions, env.num_envs)
            obs, reward, terminated, truncated, info = env.step(actions)
            add({"obs": obs, "reward": reward, "terminated": terminated,
                 "truncated": truncated, **info})
    return digest.hexdigest()


# beside each preset's default observation: the other screen observations, whose frame work
# takes other paths
VARIANTS = [("Breakout", "3.1", "raw"), ("Breakout", "3.1", "dreamer64"), ("Gopher", "2.1", "raw"),
            ("BankHeist", "2.2", "dreamer64"), ("Boxing", "1", "raw"),
            ("Breakout", "3.1", "objects")]


def recorded() -> dict:
    return json.loads(FIXTURE.read_text())


@pytest.mark.parametrize("game,preset", preset_names())
def test_every_preset_reproduces_its_pinned_digest(game, preset):
    # recorded with a worker and this process emulating an env each; here both in this process
    # (no worker to start): a seed's run does not depend on the split
    assert run_digest(game, preset, num_workers=0, inline_envs=None) == \
        recorded()[f"{game} {preset}"]


@pytest.mark.parametrize("game,preset,obs", VARIANTS)
def test_other_observations_reproduce_their_pinned_digests(game, preset, obs):
    assert run_digest(game, preset, obs=obs) == recorded()[f"{game} {preset} {obs}"]


if __name__ == "__main__" and sys.argv[1:] == ["--record"]:
    digests = {f"{g} {p}": run_digest(g, p) for g, p in preset_names()}
    digests.update({f"{g} {p} {o}": run_digest(g, p, obs=o) for g, p, o in VARIANTS})
    FIXTURE.write_text(json.dumps(digests, indent=1) + "\n")


@pytest.mark.parametrize("obs", ["atari84", "dreamer64"])
def test_the_frame_work_gives_the_same_bits_in_the_workers_and_in_the_caller(obs):
    """make(frame_work=...): the observation made by the emulating processes (numpy) or by
    JAX in the calling process (the accelerator's placement) is the same, bit for bit."""
    layouts = {}
    for frame_work in ("workers", "caller"):
        with stori_jax.make("Breakout", "3.1", num_envs=1, seed=0, obs=obs,
                            frame_work=frame_work) as env:
            layouts[frame_work] = env.plan.frames_layout
    assert layouts == {"workers": obs, "caller": "pooled"}
    key = "Breakout 3.1" + ("" if obs == "atari84" else f" {obs}")
    assert run_digest("Breakout", "3.1", obs=obs, frame_work="caller") == recorded()[key]
