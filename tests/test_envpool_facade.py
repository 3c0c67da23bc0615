"""envpool_bridge.make: envpool's Python and xla API over stori_jax, as CleanRL's and Cleanba's
JAX scripts drive it (``import envpool_bridge as envpool``, a STORI task id)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envpool_bridge as envpool
import stori_jax


def doc_recipe(name: str) -> str:
    """The python block after ``<!-- recipe: name -->`` in docs/drop-in.md."""
    from pathlib import Path

    text = (Path(__file__).parent.parent / "docs" / "drop-in.md").read_text()
    after = text.split(f"<!-- recipe: {name} -->", 1)[1]
    return after.split("```python\n", 1)[1].split("```", 1)[0]


def test_the_docs_envpool_recipe_runs_as_written_and_its_xla_loop_is_the_python_api():
    """docs/drop-in.md's envpool recipe (CleanRL's ppo_atari_envpool_xla_jax.py: its envpool.make
    call, the attribute writes, xla() before reset(), step_env_wrappeed's episode statistics, a
    jitted lax.scan rollout carrying (next_obs, next_done) across iterations) runs as written.
    Its actions replayed through the Python API of an env of the same seed give the same
    observations, rewards and done flags (lives lost on the way: episodic_life inside the
    scan).  A reset() after the handle stepped makes it stale; xla() again goes on."""
    ns = {}
    exec(compile(doc_recipe("envpool-xla"), "docs/drop-in.md", "exec"), ns)
    obs, actions, rewards, dones = (np.concatenate(part) for part in zip(*ns["trajectories"]))
    assert obs.shape == (96, 2, 4, 84, 84) and obs.dtype == np.uint8
    assert dones.any(), "a life should be lost within 96 steps"
    assert ns["envs"].closed

    twin = envpool.make("Breakout-2.1-v5", env_type="gym", num_envs=2, episodic_life=True,
                        reward_clip=True, seed=1, num_workers=0)
    try:
        observed, done = [twin.reset()], np.zeros(2, bool)
        flags, got = [done], []
        for action in actions[:-1]:
            ob, reward, done, info = twin.step(action)
            observed.append(ob)
            flags.append(done)
            got.append(reward)
        got.append(twin.step(actions[-1])[1])
        np.testing.assert_array_equal(np.stack(observed), obs)
        np.testing.assert_array_equal(np.stack(flags), dones)
        np.testing.assert_array_equal(np.stack(got), rewards)
        # after a reset() the handle of that xla() is stale (envpool's would not be)
        handle, _, _, step = twin.xla()
        handle, _ = step(handle, jnp.zeros(2, jnp.int32))
        twin.reset()
        with pytest.raises(Exception, match="stale xla handle"):
            jax.block_until_ready(step(handle, jnp.zeros(2, jnp.int32)))
        handle, recv, send, _ = twin.xla()
        assert twin.xla()[0] is handle  # not stepped yet: the same chain
        handle, (ob, reward, done, info) = recv(send(handle, jnp.zeros(2, jnp.int32)))
        assert ob.shape == (2, 4, 84, 84) and info["elapsed_step"].tolist() == [1, 1]
    finally:
        twin.close()


def test_episodic_life_and_reward_clip_have_envpools_meanings():
    """episodic_life: done exactly where lives drop (0 < lives < lives before) and at the game's
    end; the game goes on after a lost life (elapsed_step counts on), and resets only after its
    end (the next step: reward 0, elapsed_step 0, lives back).  reward_clip: the sign of
    info['reward'], the game's reward.  gymnasium: terminated = done & ~truncated."""
    envs = envpool.make("Breakout-v5", env_type="gymnasium", num_envs=2, seed=3,
                        episodic_life=True, reward_clip=True, num_workers=0)
    try:
        assert envs.config["episodic_life"] and envs.config["use_fire_reset"] is False
        obs, info = envs.reset()
        lives, elapsed = info["lives"], info["elapsed_step"]
        assert (lives == 5).all() and (elapsed == 0).all() and obs.shape == (2, 4, 84, 84)
        rng = np.random.default_rng(0)
        seen = {"life": 0, "game": 0, "scored": 0}
        game_over = np.zeros(2, bool)
        for _ in range(400):
            obs, reward, terminated, truncated, info = envs.step(rng.integers(0, 4, 2))
            lost = (info["lives"] > 0) & (info["lives"] < lives) & ~game_over
            over = info["terminated"] == 1
            np.testing.assert_array_equal(terminated | truncated, lost | over | truncated)
            np.testing.assert_array_equal(terminated, (lost | over) & ~truncated)
            np.testing.assert_array_equal(reward, np.sign(info["reward"]))
            # after a game's end the step resets it; after a lost life the game goes on
            np.testing.assert_array_equal(info["elapsed_step"],
                                          np.where(game_over, 0, elapsed + 1))
            np.testing.assert_array_equal(info["reset_step"], game_over)
            seen["life"] += lost.sum()
            seen["game"] += over.sum()
            seen["scored"] += (info["reward"] != 0).sum()
            lives, elapsed, game_over = info["lives"], info["elapsed_step"], over
            if seen["game"] and seen["life"] > 2:
                break
        assert seen["game"] and seen["life"] > 2 and seen["scored"], seen
    finally:
        envs.close()


def test_reward_clip_gives_the_sign_of_rewards_above_one():
    """Gopher scores 20 a filled hole (100 a bonked gopher): clipped, each is 1, its sign;
    info['reward'] stays the game's."""
    envs = envpool.make("Gopher-v5", num_envs=2, seed=0, reward_clip=True, num_workers=0)
    try:
        envs.reset()
        rng = np.random.default_rng(0)
        above_one = 0
        for _ in range(300):
            _, reward, _, info = envs.step(rng.integers(0, 8, 2))
            np.testing.assert_array_equal(reward, np.sign(info["reward"]))
            above_one += int((np.abs(info["reward"]) > 1).sum())
            if above_one >= 3:
                break
        assert above_one >= 3, "Gopher scores more than 1 in a step within 300 steps"
    finally:
        envs.close()


def test_python_api_reset_send_recv_async_and_env_ids():
    """gym's reset() returns the observations alone (gym_reset_return_info adds the info);
    async_reset() then recv() returns the reset as a step; send() takes env_id in any order;
    envpool's info keys and dtypes; the stack_num newest frames of the atari84 stack."""
    kw = dict(num_envs=2, seed=0, num_workers=0)
    envs = envpool.make("Breakout-v5", **kw)
    with_info = envpool.make("Breakout-v5", gym_reset_return_info=True, stack_num=2, **kw)
    capped = envpool.make("Breakout-v5", max_episode_steps=4, **kw)
    try:
        obs = envs.reset()
        obs2, info = with_info.reset()
        assert obs.shape == (2, 4, 84, 84) and obs2.shape == (2, 2, 84, 84)
        np.testing.assert_array_equal(obs2, obs[:, 2:])
        assert with_info.observation_space.shape == (2, 84, 84)
        actions = np.array([1, 3])
        for _ in range(3):
            obs, reward, done, info = envs.step(actions)
        order = np.array([1, 0])
        for _ in range(3):
            with_info.send(actions[order], env_id=order)
            obs2, reward2, done2, info2 = with_info.recv()
        np.testing.assert_array_equal(obs2, obs[:, 2:])
        for key, dtype in (("env_id", np.int32), ("lives", np.int32), ("reward", np.float32),
                           ("terminated", np.int32), ("elapsed_step", np.int32),
                           ("TimeLimit.truncated", np.bool_)):
            assert info[key].dtype == dtype and info[key].shape == (2,), key
        np.testing.assert_array_equal(info["env_id"], [0, 1])
        assert {"executed_action", "obs_masked", "ram", "labels"} <= set(info)  # STORI's own
        # max_episode_steps=4 (a frame cap of 16 frames, the reset's no-ops included)
        capped.reset()
        truncated = False
        for _ in range(4):
            _, _, done3, info3 = capped.step(actions)
            np.testing.assert_array_equal(done3, info3["TimeLimit.truncated"])
            truncated |= done3.any()
        assert truncated
        envs.async_reset()
        obs, reward, done, info = envs.recv()
        assert not reward.any() and not done.any() and (info["elapsed_step"] == 0).all()
        with pytest.raises(ValueError, match="env_id must name every env once"):
            envs.send(actions[:1], env_id=[0])
    finally:
        envs.close()
        with_info.close()
        capped.close()


def test_task_ids_config_and_keyword_mappings():
    with envpool.make("Breakout-v5", num_workers=0) as plain:
        assert plain._env.config == stori_jax.Config()  # 3.1
        config = plain.config
        assert config["seed"] == 42 and config["noop_max"] == 30  # envpool's defaults
        assert config["stori_noop_max"] == 29  # 0..29 NOOP frames: envpool's 1..30, one earlier
        assert config["stori_max_episode_frames"] == 27000 * 4
    with envpool.make("Gopher-2.2-v5", num_workers=0) as preset:
        assert preset._env.config == stori_jax.preset("Gopher", "2.2")
    cfg = stori_jax.Config(observation=stori_jax.ObservationMask("crop", 5))
    with envpool.make("Breakout-v5", config=cfg, repeat_action_probability=0.25, noop_max=1,
                      max_episode_steps=100, frame_skip=2, num_workers=0) as custom:
        assert custom._env.config.action_noise == stori_jax.ActionNoise(0.25, sticky=True)
        assert custom._env.plan.noop_max == 0 and custom._env.plan.frame_skip == 2
    with envpool.make("Breakout-v5", img_height=210, img_width=160, gray_scale=False,
                      stack_num=1, num_workers=0) as raw:
        assert raw.observation_space.shape == (3, 210, 160)
    with envpool.make("Breakout-v5", config=stori_jax.Config(ram_observation=True),
                      num_workers=0) as ram:
        assert ram.observation_space.shape == (128,)


@pytest.mark.parametrize("task_id, kwargs, pattern", [
    ("Breakout-v5", dict(use_fire_reset=True), r"use_fire_reset=True is not supported: defaults"),
    ("Breakout-v5", dict(full_action_space=True), r"full_action_space=True is not supported"),
    ("Breakout-v5", dict(zero_discount_on_life_loss=True),
     r"zero_discount_on_life_loss=True is not supported"),
    ("Breakout-v5", dict(use_inter_area_resize=False), r"use_inter_area_resize=False is not"),
    ("Breakout-v5", dict(img_height=96, img_width=96),
     r"img_height=96, img_width=96, gray_scale=True, stack_num=4 cannot be honoured exactly"),
    ("Breakout-v5", dict(stack_num=8), r"stack_num=8 cannot be honoured"),
    ("Breakout-v5", dict(num_envs=4, batch_size=2), r"batch_size=2: 0 or num_envs only"),
    ("Breakout-v5", dict(noop_max=0), r"noop_max must be"),
    ("Breakout-v5", dict(seed=[1, 2]), r"per-env seed lists are not supported"),
    ("Breakout-v5", dict(mode=2), r"mode=2 is not supported"),
    ("Breakout-v5", dict(from_pixels=True, render_mode="rgb_array"),
     r"unsupported keyword\(s\) \['from_pixels', 'render_mode'\]"),
    ("Breakout-1-v5", dict(repeat_action_probability=0.25),
     r"this preset already corrupts actions"),
    ("Breakout-2.1-v5", dict(config=stori_jax.Config()), r"config: the task id names preset"),
    ("BreakoutNoFrameskip-v4", {}, r"task_id must be envpool's Atari id '<Game>-v5'"),
    ("Breakout-9.9-v5", {}, r"preset"),
])
def test_keywords_and_ids_it_cannot_honour_are_refused_by_name(task_id, kwargs, pattern):
    with pytest.raises(ValueError, match=pattern):
        envpool.make(task_id, **kwargs)


def test_env_type_dm_is_refused():
    with pytest.raises(ValueError, match=r"env_type must be one of \['gym', 'gymnasium'\], got "
                                         r"'dm' \(dm_env's API is not offered\)"):
        envpool.make("Breakout-v5", env_type="dm")
