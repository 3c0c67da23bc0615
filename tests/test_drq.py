"""The DrQ(ε) baseline on tiny networks and budgets: its n-step returns, double-DQN targets,
augmentation and replay against hand computations, an update, save/resume, and the commands
(train drq -> eval -> table)."""

from __future__ import annotations

import csv
import json
import pickle

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import stori_jax
from baselines import drq
from baselines.table import build_table
from stori_jax.cli import main

transitions = jax.jit(drq.n_step_transitions, static_argnums=(1, 2))  # one compilation
TINY = dict(game="Breakout", preset="1", network="tiny", num_envs=2, total_steps=120,
            learning_starts=40, batch_size=8, n_step=3, buffer_size=400, log_every=30,
            checkpoint_every=40)


def tiny(**kw) -> drq.DrQConfig:
    return drq.DrQConfig(**{**TINY, **kw})


def sequences(reward, done, cut, first=None):
    """Sampled sequences (B, n + 4) of the given rows 3.. (the history rows are zeros)."""
    reward, done, cut = (np.asarray(x) for x in (reward, done, cut))
    b, n = reward.shape
    pad = lambda x, fill=0: np.concatenate([np.full((b, 3), fill, x.dtype), x,
                                            np.full((b, 1), fill, x.dtype)], axis=1)
    rows = n + 4
    frames = np.zeros((b, rows, 84, 84), np.uint8)
    frames[:, :, 0, 0] = np.arange(rows)
    return dict(frame=jnp.asarray(frames), action=jnp.zeros((b, rows), jnp.int32),
                reward=jnp.asarray(pad(reward.astype(np.float32))),
                done=jnp.asarray(pad(done.astype(bool))), cut=jnp.asarray(pad(cut.astype(bool))),
                first=jnp.asarray(np.zeros((b, rows), bool) if first is None else first))


# -- returns, targets, augmentation ---------------------------------------------------------------

def test_n_step_returns_stop_at_the_learners_terminal_by_hand():
    g = 0.9
    reward = [[1, 2, 3], [1, 2, 3], [1, 2, 3], [5, 0, 0], [1, 1, 1]]
    done = [[0, 0, 0], [0, 1, 0], [1, 0, 1], [0, 0, 0], [0, 0, 1]]
    cut = [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 1, 0], [0, 0, 0]]
    t = transitions(sequences(reward, done, cut), 3, g)
    np.testing.assert_allclose(t.ret, [1 + g * 2 + g * g * 3, 1 + g * 2, 1, 5 + 0, 1 + g + g * g],
                               rtol=1e-6)
    np.testing.assert_allclose(t.discount, [g ** 3, 0, 0, 0, 0], rtol=1e-6)
    # a return that reaches a frame-cap cut would need the episode's final observation
    np.testing.assert_array_equal(t.valid, [True, True, True, False, True])
    # the transition's row is 3 and its bootstrap state's row 3 + n
    np.testing.assert_array_equal(t.obs[:, 0, 0, -1], [3] * 5)
    np.testing.assert_array_equal(t.next_obs[:, 0, 0, -1], [6] * 5)


def test_a_stack_repeats_its_episodes_first_frame_as_the_env_fills_it():
    first = np.zeros((3, 7), bool)  # (and two rows without a start, as the test above)
    first[1, 2] = True   # the episode began one row before the transition's
    first[2, 3] = True   # ... on the transition's row
    t = transitions(sequences(np.zeros((5, 3)), np.zeros((5, 3)), np.zeros((5, 3)),
                              np.pad(first, ((0, 2), (0, 0)))), 3, 0.9)
    np.testing.assert_array_equal(t.obs[:3, 0, 0], [[0, 1, 2, 3], [2, 2, 2, 3], [3, 3, 3, 3]])


def table_q(params, obs):
    """A stand-in network: the Q-values of state obs[:, 0, 0, -1] in the table params."""
    return params[obs[:, 0, 0, -1].astype(jnp.int32)]


def test_double_dqn_targets_and_the_huber_loss_by_hand():
    rng = np.random.default_rng(0)
    online = jnp.asarray(rng.normal(size=(6, 3)).astype(np.float32))
    target = jnp.asarray(rng.normal(size=(6, 3)).astype(np.float32))
    obs = jnp.zeros((4, 84, 84, 4)).at[:, 0, 0, -1].set(jnp.array([0, 1, 2, 0]))
    next_obs = jnp.zeros((4, 84, 84, 4)).at[:, 0, 0, -1].set(jnp.array([3, 4, 5, 5]))
    batch = drq.Transitions(obs=obs, action=jnp.array([0, 2, 1, 1]),
                            ret=jnp.array([1.0, -0.5, 0.0, 3.0]),
                            discount=jnp.array([0.9, 0.9, 0.0, 0.9]), next_obs=next_obs,
                            valid=jnp.array([True, True, True, False]))
    on, tg = np.asarray(online, np.float64), np.asarray(target, np.float64)
    expected_targets = [r + d * tg[s, np.argmax(on[s])]  # the online argmax, the target's value
                        for r, d, s in zip([1.0, -0.5, 0.0], [0.9, 0.9, 0.0], [3, 4, 5])]
    errors = np.array([on[s, a] for s, a in zip([0, 1, 2], [0, 2, 1])]) - expected_targets
    huber = np.where(np.abs(errors) <= 1, 0.5 * errors ** 2, np.abs(errors) - 0.5)
    loss = jax.jit(lambda p, t, shared: drq.td_loss(table_q, p, t, batch, shared)[0],
                   static_argnums=2)
    np.testing.assert_allclose(loss(online, target, False), huber.mean(), rtol=1e-5)  # the
    #                                                            invalid one left out
    grads = jax.jit(jax.grad(lambda p: drq.td_loss(table_q, p, target, batch, False)[0]))(online)
    assert np.count_nonzero(np.asarray(grads)) == 3, "only the taken Q-values of valid rows"
    np.testing.assert_allclose(loss(online, online, True), loss(online, online, False))


def test_augmentation_keeps_shapes_and_dtypes_and_is_the_identity_at_pad_0():
    obs = jax.random.randint(jax.random.PRNGKey(0), (16, 84, 84, 4), 1, 256).astype(jnp.float32)
    key = jax.random.PRNGKey(1)
    augment = jax.jit(drq.augment, static_argnums=(2, 3))
    out = augment(obs, key, 4, 0.05)
    assert out.shape == obs.shape and out.dtype == obs.dtype
    np.testing.assert_array_equal(drq.augment(obs, key, 0, 0.0), obs)
    # the shift alone: each sample a crop of its own edge-padded stack
    shifted = np.asarray(augment(obs, key, 4, 0.0))
    padded = np.pad(np.asarray(obs), ((0, 0), (4, 4), (4, 4), (0, 0)), mode="edge")
    for frame, crop in zip(padded, shifted):
        assert any(np.array_equal(frame[i:i + 84, j:j + 84], crop)
                   for i in range(9) for j in range(9))
    # then the intensity: one factor per sample in [1 - 2 scale, 1 + 2 scale]
    factor = (np.asarray(out) / shifted).reshape(16, -1)
    np.testing.assert_allclose(factor, factor[:, :1] * np.ones_like(factor), rtol=1e-6)
    assert np.all(np.abs(factor[:, 0] - 1) <= 0.1 + 1e-6) and np.ptp(factor[:, 0]) > 0


# -- replay ---------------------------------------------------------------------------------------

def test_the_replays_stacks_are_the_envs_observations():
    """Rows written as training writes them, through episodes that end (a tiny frame cap cuts
    them off), rebuild every frame stack the env returned."""
    config = tiny(buffer_size=200)
    m = drq.machinery(config, 4)
    state = m.buffer.init(drq.empty_row())
    seen = []
    rng = np.random.default_rng(0)
    with stori_jax.make("Breakout", "1", num_envs=2, seed=3, obs="atari84",
                        max_episode_frames=24, num_workers=0) as env:
        obs, _ = env.reset()
        first = np.ones(2, bool)
        for _ in range(20):
            actions = rng.integers(0, 4, 2).astype(np.int32)
            next_obs, reward, terminated, truncated, _ = env.step(actions)
            state = m.add(state, obs, jnp.asarray(actions), reward, first,
                          np.asarray(terminated), np.asarray(truncated & ~terminated))
            seen.append(np.asarray(obs))
            obs, first = next_obs, np.asarray(terminated | truncated)
    experience = state.experience
    assert np.asarray(experience["first"])[:, :20].sum() >= 4, "episodes began in the rows"
    assert np.asarray(experience["cut"])[:, :20].any()
    for j in range(3, 20):
        rows = jax.tree.map(lambda x: x[:, j - 3:j + 1], experience)
        np.testing.assert_array_equal(drq.stack_at(rows["frame"], rows["first"], 3), seen[j])


def test_sampled_returns_never_cross_an_episode_end():
    """Uniform samples of a wrapped-around replay whose episodes end (learner's terminals and
    frame-cap cuts) at random: each sample's return, discount, validity and stacks are its own
    episode's, as computed from the rows by hand."""
    config = tiny(num_envs=2, buffer_size=2 * 40, n_step=3, batch_size=64)
    rows, n, g = 70, 3, config.gamma
    rng = np.random.default_rng(1)
    done = rng.random((2, rows)) < 0.15
    cut = ~done & (rng.random((2, rows)) < 0.08)
    first = np.zeros((2, rows), bool)
    first[:, 0] = True
    # a done that is a lost life does not begin a new episode; a game's end or a cut does
    life = done & (rng.random((2, rows)) < 0.5)
    first[:, 1:] = (done & ~life | cut)[:, :-1]
    reward = rng.integers(-1, 2, (2, rows)).astype(np.float32)
    frames = np.zeros((2, rows, 84, 84), np.uint8)
    frames[:, :, 0, 0] = np.arange(rows)
    frames[:, :, 0, 1] = np.arange(2)[:, None]
    m = drq.machinery(config, 4)
    written = dict(frame=frames, action=np.zeros((2, rows), np.int32), reward=reward,
                   first=first, done=done, cut=cut)
    state = m.buffer.init(drq.empty_row())
    for part in (slice(0, 35), slice(35, rows)):  # 70 rows into 40: the replay wraps around
        state = m.buffer.add(state, {k: jnp.asarray(v[:, part]) for k, v in written.items()})
    sample = jax.jit(lambda s, k: drq.n_step_transitions(m.buffer.sample(s, k).experience, n,
                                                          g))
    checked = set()
    for k in range(12):
        t = jax.device_get(sample(state, jax.random.PRNGKey(k)))
        for i in range(config.batch_size):
            row, e = int(t.obs[i, 0, 0, -1]), int(t.obs[i, 0, 1, -1])
            assert rows - 40 + 3 <= row <= rows - 1 - n, "rows overwritten or not complete"
            start = max(r for r in range(row + 1) if first[e, r])
            np.testing.assert_array_equal(t.obs[i, 0, 0], [max(row - 3 + q, start)
                                                           for q in range(4)])
            ret, m_ = 0.0, 0
            while True:
                ret += g ** m_ * reward[e, row + m_]
                if done[e, row + m_] or cut[e, row + m_] or m_ + 1 == n:
                    break
                m_ += 1
            stopped = done[e, row + m_] or cut[e, row + m_]
            assert t.valid[i] == (not cut[e, row + m_])  # a cut return is left out
            np.testing.assert_allclose(t.ret[i], ret, rtol=1e-5, atol=1e-6)
            np.testing.assert_allclose(t.discount[i], 0.0 if stopped else g ** n, rtol=1e-6)
            if not stopped:  # the bootstrap state is n rows on, in the same episode
                assert int(t.next_obs[i, 0, 0, -1]) == row + n
                assert not first[e, row + 1:row + n + 1].any()
            checked.add((e, row))
    assert len(checked) > 40


# -- the update -----------------------------------------------------------------------------------

def random_batch(b=16, seed=0):
    k = jax.random.split(jax.random.PRNGKey(seed), 5)
    return drq.Transitions(
        obs=jax.random.randint(k[0], (b, 84, 84, 4), 0, 256).astype(jnp.uint8),
        action=jax.random.randint(k[1], (b,), 0, 4),
        ret=jax.random.normal(k[2], (b,)), discount=jnp.full((b,), 0.99 ** 3),
        next_obs=jax.random.randint(k[3], (b, 84, 84, 4), 0, 256).astype(jnp.uint8),
        valid=jnp.ones((b,), bool))


def test_an_update_lowers_the_td_loss_on_a_fixed_batch_and_copies_the_target():
    config = tiny(learning_rate=1e-3, augment_pad=0, intensity_scale=0.0,
                  target_update_period=3)  # the target stays for two updates, then is copied
    network, optimizer = drq.make_network(config, 4), drq.make_optimizer(config)
    params = network.init(jax.random.PRNGKey(0), jnp.zeros((1, 84, 84, 4), jnp.uint8))
    state = drq.TrainState(params, params, optimizer.init(params), jnp.int32(0))
    step = jax.jit(drq.make_train_step(network.apply, optimizer, config))
    batch = random_batch()
    td = jax.jit(lambda p, t: drq.td_loss(network.apply, p, t, batch, False)[0])
    before = float(td(params, params))
    for i in range(2):
        state, metrics = step(state, batch, jax.random.PRNGKey(i))
    assert float(td(state.params, params)) < before - 1e-3, (before, td(state.params, params))
    assert int(state.updates) == 2 and np.isfinite(float(metrics["q_mean"]))
    same = lambda a, b: all(np.array_equal(x, y) for x, y in zip(jax.tree.leaves(a),
                                                                  jax.tree.leaves(b)))
    assert same(state.target_params, params) and not same(state.params, params)
    state, _ = step(state, batch, jax.random.PRNGKey(2))
    assert same(state.target_params, state.params)


def test_a_lost_life_ends_the_learners_episode_and_the_game_goes_on():
    terminated = np.array([False, False, True, False, False])
    truncated = np.array([False, False, False, True, False])
    before, now = np.array([5, 5, 1, 3, 0]), np.array([5, 4, 5, 5, 0])  # an end: the next's
    done, cut = drq.learner_ends(terminated, truncated, before, now, True)
    np.testing.assert_array_equal(done, [False, True, True, False, False])
    np.testing.assert_array_equal(cut, [False, False, False, True, False])
    done, _ = drq.learner_ends(terminated, truncated, before, now, False)
    np.testing.assert_array_equal(done, [False, False, True, False, False])


def test_epsilon_and_the_updates_follow_the_step_count():
    config = drq.DrQConfig()
    assert [drq.epsilon_at(config, s) for s in (0, 1600)] == [1.0, 1.0]
    assert drq.epsilon_at(config, 1600 + 2500) == pytest.approx(0.505)
    assert drq.epsilon_at(config, 6600) == drq.epsilon_at(config, 10 ** 6) == pytest.approx(0.01)
    assert [drq.updates_due(config, s) for s in (0, 1600, 1604, 100_000)] == [0, 0, 4, 98_400]
    quarter = drq.DrQConfig(replay_ratio=0.25)
    assert [drq.updates_due(quarter, s) - drq.updates_due(quarter, s - 4)
            for s in range(1604, 1624, 4)] == [1] * 5
    slow = drq.DrQConfig(replay_ratio=0.25, num_envs=2)
    assert [drq.updates_due(slow, s) - drq.updates_due(slow, s - 2)
            for s in range(1602, 1612, 2)] == [0, 1, 0, 1, 0]


# -- configs --------------------------------------------------------------------------------------

@pytest.mark.parametrize("field, value, message", [
    ("replay_ratio", 0, "replay_ratio must be > 0, got 0"),
    ("n_step", 0, "n_step must be >= 1, got 0"),
    ("gamma", 1.5, r"gamma must be in \[0, 1\], got 1.5"),
    ("epsilon_eval", -0.1, r"epsilon_eval must be in \[0, 1\], got -0.1"),
    ("network", "resnet", r"network must be one of \['nature', 'nips', 'tiny'\], got 'resnet'"),
    ("buffer_size", 12, "buffer_size 12 holds 6 transitions per env .* needs n_step \\+ 4 = 7"),
    ("intensity_scale", 0.5, "intensity_scale must be < 0.5"),
    ("clip_rewards", "yes", "clip_rewards must be True or False, got 'yes'"),
    ("batch_size", 1.5, "batch_size must be an int >= 1, got 1.5"),
])
def test_drq_config_fields_are_checked(field, value, message):
    with pytest.raises(ValueError, match=message):
        tiny(**{field: value})


@pytest.mark.parametrize("setting, message", [
    ("replay_ratio=0", "replay_ratio must be > 0, got 0"),
    ("replay_ratio=fast", "replay_ratio must be a number, got 'fast'"),
    ("n_step=2.5", "n_step must be an int, got '2.5'"),
    ("network=resnet", "network must be one of ['nature', 'nips', 'tiny'], got 'resnet'"),
    ("terminal_on_life_loss=maybe", "terminal_on_life_loss must be true or false, got 'maybe'"),
    ("update_epochs=2", "unknown DrQ(ε) hyperparameter 'update_epochs'; --set takes "
                        "['adam_eps', 'augment_pad', 'batch_size', "),
    ("total_steps=5", "set total_steps with --steps, not --set"),
])
def test_bad_set_values_are_clear_errors(setting, message, capsys, tmp_path):
    assert main(["train", "drq", "--game", "Breakout", "--set", setting, "--out",
                 str(tmp_path / "run"), "--quiet"]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


# -- training, resuming, the commands -------------------------------------------------------------

def read_log(path):
    with open(path / "log.csv", newline="") as f:
        return [{k: v for k, v in r.items() if k not in drq.TIMING_FIELDS}
                for r in csv.DictReader(f)]


def read_checkpoint(path):
    with open(path / "checkpoint.pkl", "rb") as f:
        return pickle.load(f)


def assert_trees_equal(a, b):
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    assert len(la) == len(lb)
    for x, y in zip(la, lb):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    out = tmp_path_factory.mktemp("drq-full")
    return out, drq.train(tiny(), out, progress=False)


def test_training_writes_its_files(uninterrupted):
    out, summary = uninterrupted
    assert summary["finished"] and summary["agent_steps"] == 120
    assert summary["gradient_updates"] == drq.updates_due(tiny(), 118) > 0
    assert {p.name for p in out.iterdir()} == {"config.json", "log.csv", "episodes.csv",
                                              "checkpoint.pkl", "summary.json"}  # no replay
    log = read_log(out)
    assert [int(r["global_step"]) for r in log] == [30, 60, 90, 120]
    assert float(log[-1]["loss"]) >= 0 and float(log[0]["epsilon"]) == 1.0
    ckpt = read_checkpoint(out)
    assert ckpt["replay"] is None and ckpt["iteration"] == 60


def test_resume_reproduces_the_uninterrupted_run(uninterrupted, tmp_path):
    """Stopped between log rows and checkpoints, resumed twice: the same log, episodes,
    parameters, target, optimizer, key and emulators as the run that never stopped."""
    full, _ = uninterrupted
    partial = drq.train(tiny(), tmp_path, progress=False, stop_after=23)
    assert not partial["finished"] and not (tmp_path / "summary.json").exists()
    assert sorted(p.name for p in tmp_path.glob("replay-*.pkl")) == ["replay-23.pkl"]
    drq.train(tiny(), tmp_path, resume=True, progress=False, stop_after=41)
    assert sorted(p.name for p in tmp_path.glob("replay-*.pkl")) == ["replay-41.pkl"]
    with open(tmp_path / "replay-41.pkl", "rb") as f:
        rows = pickle.load(f)["experience"]
    assert rows["frame"].shape == (2, 41, 84, 84)  # the rows written so far, one per step
    # Breakout's lost lives end the learner's episodes, not the env's
    assert rows["done"].sum() > rows["first"][:, 1:].sum() + rows["cut"].sum()
    assert drq.train(tiny(), tmp_path, resume=True, progress=False)["iterations_now"] == 19
    assert not list(tmp_path.glob("replay-*.pkl"))
    assert read_log(tmp_path) == read_log(full)
    assert (tmp_path / "episodes.csv").read_text() == (full / "episodes.csv").read_text()
    a, b = read_checkpoint(full), read_checkpoint(tmp_path)
    keys = ("params", "target_params", "opt_state", "updates", "key", "obs", "lives", "first")
    assert_trees_equal([a[k] for k in keys], [b[k] for k in keys])
    assert pickle.dumps(a["envs"]) == pickle.dumps(b["envs"])


def test_train_eval_and_table_through_the_commands(uninterrupted, tmp_path, capsys):
    """stori-jax train drq (the fixture's run, through the command line), eval of its
    checkpoint (ε-greedy with ε 0.001), a table with a DrQ(ε) column beside PPO's, and suite
    --checkpoint on eval's seed."""
    run = tmp_path / "Breakout-1" / "drq-seed0"
    sets = [f"--set={k}={v}" for k, v in TINY.items()
            if k not in ("game", "preset", "total_steps")]
    assert main(["train", "drq", "--game", "breakout", "--preset", "1", "--steps", "120",
                 "--out", str(run), "--quiet", *sets]) == 0
    assert "trained 120 agent steps" in capsys.readouterr().out
    assert read_log(run) == read_log(uninterrupted[0])
    assert main(["eval", "--checkpoint", str(run / "checkpoint.pkl"), "--episodes", "2",
                 "--num-envs", "2", "--max-episode-frames", "60", "--quiet"]) == 0
    result = json.loads((run / "eval-sampled.json").read_text())
    assert (result["agent"], result["policy"], result["eval_seed"]) == ("drq", "sampled", 10_000)
    assert (result["trained_agent_steps"], result["run_finished"]) == (120, True)
    ppo_run = tmp_path / "Breakout-1" / "ppo-seed0"
    from baselines.evaluate import write_result

    write_result(dict(game="Breakout", preset="1", agent="ppo", policy="sampled", train_seed=0,
                      mean_return=2.0, episodes=2), ppo_run)
    capsys.readouterr()
    assert main(["table", str(tmp_path), "--out", str(tmp_path / "table")]) == 0
    header, _, row = capsys.readouterr().out.splitlines()[:3]
    assert header.startswith("| game | preset | PPO (ours) | DrQ(ε) (ours) | Random (ours) |")
    assert row.startswith(f"| Breakout | 1 | 2.00 (1 seed) | {result['mean_return']:.2f} (1 seed)"
                          " | - |")
    assert (tmp_path / "table" / "curves-Breakout.png").exists()
    assert main(["suite", "--checkpoint", str(run / "checkpoint.pkl"), "--presets", "1",
                 "--episodes", "1", "--num-envs", "1", "--max-steps", "10", "--no-gallery",
                 "--quiet", "--out", str(tmp_path / "suite")]) == 0
    suite = json.loads((tmp_path / "suite" / "results.json").read_text())
    assert suite["seed"] == 10_000 and [r["agent_steps"] for r in suite["rows"]] == [10]


def test_a_drq_checkpoint_acts_epsilon_greedy_or_greedy(uninterrupted):
    full, _ = uninterrupted
    ckpt = drq.load_checkpoint(full / "checkpoint.pkl")
    config, greedy = drq.policy_of(ckpt, "greedy")
    _, sampled = drq.policy_of(dict(ckpt, config=dict(ckpt["config"], epsilon_eval=1.0)))
    obs = jax.random.randint(jax.random.PRNGKey(0), (64, 84, 84, 4), 0, 256).astype(jnp.uint8)
    q = jax.jit(drq.make_network(config, 4).apply)(ckpt["params"], obs)
    np.testing.assert_array_equal(greedy(obs, jax.random.PRNGKey(1)), np.argmax(q, axis=-1))
    assert len(set(np.asarray(sampled(obs, jax.random.PRNGKey(1))).tolist())) == 4  # ε = 1
    assert drq.AGENT.training_progress(ckpt) == dict(trained_agent_steps=120,
                                                     run_total_steps=120, run_finished=True)
    with pytest.raises(ValueError, match="not a stori-jax DrQ checkpoint"):
        drq.check_checkpoint(dict(ckpt, format="stori-jax-ppo-1"), full / "checkpoint.pkl")


def test_a_table_of_two_agents_has_a_column_and_a_row_of_curves_each(tmp_path, monkeypatch):
    """A PPO run and a DrQ(ε) run of one seed are two agents' runs, not one seed twice; each
    agent gets its column (PPO first), its row of panels, and notes that name it."""
    import dataclasses

    import matplotlib.pyplot as plt

    from baselines.evaluate import write_result

    configs = dict(ppo=dict(game="Boxing", preset="1", seed=0),
                   drq=dataclasses.asdict(drq.DrQConfig(game="Boxing", preset="1", seed=0)))
    for agent, config in configs.items():
        for seed in (0, 7):
            run = tmp_path / "Boxing-1" / f"{agent}-seed{seed}"
            run.mkdir(parents=True)
            (run / "config.json").write_text(json.dumps(dict(config, seed=seed)))
            (run / "episodes.csv").write_text("global_step,env,return,length\n100,0,1.0,5\n")
            if (agent, seed) != ("drq", 7):
                write_result(dict(game="Boxing", preset="1", agent=agent, policy="sampled",
                                  train_seed=seed, mean_return=1.0 + seed, episodes=3), run)
    figures, close = [], plt.close
    monkeypatch.setattr(plt, "close", figures.append)
    text, _ = build_table(tmp_path, tmp_path / "out")
    assert text.splitlines()[0] == ("| game | preset | PPO (ours) | DrQ(ε) (ours) | Random (ours) "
                                    "| DreamerV3 (paper) | STORM (paper) | seeds (PPO) | "
                                    "episodes per seed |")
    assert text.splitlines()[2] == ("| Boxing | 1 | 4.50 ± 4.95 | 1.00 (1 seed) | - | 39.32 ± 6.79 "
                                    "| 29.48 ± 15.41 | 0, 7; DrQ(ε): 0 | 3 |")
    assert [ax.get_title() for ax in figures[0].axes] == ["PPO: Boxing 1", "DrQ(ε): Boxing 1"]
    close(figures[0])
    notes = json.loads((tmp_path / "out" / "table.json").read_text())["notes"]
    assert notes[0] == ("Boxing 1 DrQ(ε): seed(s) [7] have no eval-sampled.json: in the curves, "
                        "not in the table")
