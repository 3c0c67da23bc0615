"""The PPO baseline, the evaluation protocol, the results table and their command line, on
tiny networks and budgets."""

from __future__ import annotations

import csv
import dataclasses
import functools
import json
import pickle
import re
import shutil
import warnings
from pathlib import Path

import ale_py
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import stori_jax
from baselines import networks, ppo, runs
from baselines.evaluate import evaluate, write_result
from baselines.table import (PAPER_RESULTS, STD_OVER_SEEDS, aggregate, build_table, learning_curves,
                             load_evaluations, markdown, smoothed)
from stori_jax import provenance
from stori_jax.cli import main
from stori_jax.suite import episode_quotas

TINY = dict(game="Breakout", preset="1", network="tiny", num_envs=4, num_steps=16,
            num_minibatches=2, update_epochs=2, total_steps=192, checkpoint_every=1)


def tiny(**kw) -> ppo.PPOConfig:
    return ppo.PPOConfig(**{**TINY, **kw})


def random_frames(n, seed=0):
    """``n`` stacks of 84x84x4 random uint8 frames (numpy: a large jax.random draw takes XLA
    seconds to compile)."""
    return np.random.default_rng(seed).integers(0, 256, (n, 84, 84, 4), dtype=np.uint8)


# -- network and update -----------------------------------------------------------------------

@pytest.mark.parametrize("features,kernel,stride,size", [(32, 8, 4, 84), (64, 4, 2, 20),
                                                         (64, 3, 1, 9)])
def test_conv_is_the_usual_convolution(features, kernel, stride, size):
    x = np.random.default_rng(0).uniform(size=(2, size, size, 5)).astype(np.float32)
    conv = networks.Conv(features, kernel, stride)
    params = jax.jit(conv.init)(jax.random.PRNGKey(1), x)
    dense = params["params"]["Dense_0"]
    k = kernel // stride
    # the dense kernel's rows, regrouped as the (kernel, kernel, in, out) conv kernel
    w = dense["kernel"].reshape(k, k, stride, stride, 5, features).transpose(0, 2, 1, 3, 4, 5)
    w = w.reshape(kernel, kernel, 5, features)
    expected = jax.lax.conv_general_dilated(x, w, (stride, stride), "VALID",
                                            dimension_numbers=("NHWC", "HWIO", "NHWC"))
    np.testing.assert_allclose(jax.jit(conv.apply)(params, x), expected + dense["bias"],
                               rtol=1e-4, atol=1e-4)


def test_nature_torso_has_the_nature_shapes():
    net = ppo.ActorCritic(num_actions=4, network="nature")
    params = jax.eval_shape(net.init, jax.random.PRNGKey(0), jnp.zeros((1, 84, 84, 4),
                                                                       jnp.uint8))
    sizes = [p["Dense_0"]["kernel"].shape for name, p in params["params"].items()
             if name.startswith("Conv")]
    assert sizes == [(8 * 8 * 4, 32), (4 * 4 * 32, 64), (3 * 3 * 64, 64)]
    assert params["params"]["Dense_0"]["kernel"].shape == (7 * 7 * 64, 512)


def test_factored_head_is_a_direction_distribution_times_a_fire_distribution():
    table = ppo.direction_and_fire(ppo.FULL_ACTION_SET)
    assert len({tuple(row) for row in table}) == 18 and set(table[:, 0]) == set(range(9))
    assert ppo.FULL_ACTION_SET[1] == "FIRE" and tuple(table[1]) == (0, 1)  # NOOP's direction
    assert tuple(table[ppo.FULL_ACTION_SET.index("DOWNLEFTFIRE")]) == tuple(
        table[ppo.FULL_ACTION_SET.index("DOWNLEFT")] + [0, 1])
    net = ppo.ActorCritic(num_actions=18, network="tiny", action_head="factored")
    obs = random_frames(3)
    params = jax.jit(net.init)(jax.random.PRNGKey(1), obs)
    # larger head weights, so that the two factors are far from uniform
    params = jax.tree.map(lambda p: p * 300, params)
    probs = np.exp(np.asarray(jax.jit(net.apply)(params, obs)[0], np.float64))
    np.testing.assert_allclose(probs.sum(axis=1), 1.0, rtol=1e-5)
    by_fire_direction = np.zeros((3, 2, 9))
    for action, (direction, fire) in enumerate(table):
        by_fire_direction[:, fire, direction] = probs[:, action]
    p_fire = by_fire_direction.sum(axis=2, keepdims=True)
    p_direction = by_fire_direction.sum(axis=1, keepdims=True)
    np.testing.assert_allclose(by_fire_direction, p_fire * p_direction, rtol=1e-4, atol=1e-7)
    assert np.ptp(p_fire[..., 0]) > 0.05, "the factors depend on the observation"


@functools.partial(jax.jit, static_argnums=(0, 1))
def synthetic_batch(config, network, params, obs):
    """(rollout of the policy on the frames ``obs`` (T, B, ...), its last observation, the flat
    minibatch ppo_loss takes), in one compiled call."""
    k = jax.random.split(jax.random.PRNGKey(0), 4)
    t, b = config.num_steps, config.num_envs
    action, logp, value = jax.vmap(lambda o, kk: ppo.act(network, params, o, kk))(
        obs, jax.random.split(k[1], t))
    reward = jnp.sign(jax.random.normal(k[2], (t, b))) * (jax.random.uniform(k[3], (t, b)) < .3)
    done = jnp.zeros((t, b), bool).at[t // 2, 0].set(True)
    rollout = ppo.Rollout(obs, action, logp, value, reward, done)
    _, last_value = network.apply(params, obs[-1])
    advantages, targets = ppo.gae(rollout, last_value, config.gamma, config.gae_lambda)
    flat = jax.tree.map(lambda x: x.reshape(config.batch_size, *x.shape[2:]),
                        (obs, action, logp, value, advantages, targets))
    return rollout, obs[-1], flat


@pytest.mark.parametrize("augment_shift,game,action_head,learning_rate", [
    (0, "Breakout", "joint", 1e-3),
    (4, "Boxing", "factored", 2.5e-4),  # at 1e-3 this batch's clipped value loss overshoots
])
def test_an_update_lowers_the_loss_on_a_fixed_batch(augment_shift, game, action_head,
                                                     learning_rate):
    config = tiny(learning_rate=learning_rate, update_epochs=4, augment_shift=augment_shift,
                  game=game, action_head=action_head)
    network = ppo.make_network(config, stori_jax.get_game(game).num_actions)
    params = jax.jit(network.init)(jax.random.PRNGKey(0), jnp.zeros((1, 84, 84, 4), jnp.uint8))
    optimizer = ppo.make_optimizer(config)
    frames = random_frames(config.num_steps * config.num_envs).reshape(
        config.num_steps, config.num_envs, 84, 84, 4)
    rollout, last_obs, flat = synthetic_batch(config, network, params, frames)
    loss = jax.jit(lambda params: ppo.ppo_loss(network, config, params, flat)[0])
    before = loss(params)
    update = ppo.make_update(network, optimizer, config)
    new_params, _, metrics = update(params, optimizer.init(params), rollout, last_obs,
                                    jax.random.PRNGKey(1))
    after = loss(new_params)
    assert float(after) < float(before) - 1e-3, (before, after)
    assert 0 <= float(metrics["clipfrac"]) <= 1 and np.isfinite(float(metrics["approx_kl"]))


def test_random_shift_crops_the_edge_padded_frames_at_offsets_within_the_pad():
    pad = 3
    obs = jnp.asarray(random_frames(32))
    shifted = np.asarray(networks.random_shift(obs, jax.random.PRNGKey(1), pad))
    assert shifted.shape == obs.shape and shifted.dtype == np.uint8
    padded = np.pad(np.asarray(obs), ((0, 0), (pad, pad), (pad, pad), (0, 0)), mode="edge")
    offsets = []
    for frame, out in zip(padded, shifted):
        found = [(i, j) for i in range(2 * pad + 1) for j in range(2 * pad + 1)
                 if np.array_equal(frame[i:i + 84, j:j + 84], out)]
        assert len(found) == 1, "every output is one crop of its own padded frame stack"
        offsets.append(found[0])
    assert len(set(offsets)) > 10, "each sample draws its own offset"
    np.testing.assert_array_equal(networks.random_shift(obs, jax.random.PRNGKey(1), pad), shifted)
    np.testing.assert_array_equal(networks.random_shift(obs, jax.random.PRNGKey(1), 0), obs)


@pytest.mark.parametrize("field, value, message", [
    ("augment_shift", -1, "augment_shift must be >= 0, got -1"),
    ("augment_shift", 1.5, "augment_shift must be an int >= 0, got 1.5"),
    ("num_envs", True, "num_envs must be an int >= 1, got True"),
    ("gamma", "0.9", r"gamma must be a number in \[0, 1\], got '0.9'"),
    ("gae_lambda", 1.5, r"gae_lambda must be in \[0, 1\], got 1.5"),
    ("learning_rate", "3e-4", "learning_rate must be a finite number >= 0, got '3e-4'"),
    ("ent_coef", float("nan"), "ent_coef must be a finite number >= 0, got nan"),
    ("anneal_lr", "no", "anneal_lr must be True or False, got 'no'"),
    ("clip_vloss", 1, "clip_vloss must be True or False, got 1"),
])
def test_ppo_config_fields_are_checked(field, value, message):
    with pytest.raises(ValueError, match=message):
        tiny(**{field: value})


def test_a_learning_rate_schedule_longer_than_int32_is_refused_only_when_annealed():
    """optax's schedule counts updates in int32: beyond it the first update was an
    OverflowError from inside jit; without annealing nothing counts that far."""
    updates = ppo.updates_per_iteration(tiny())
    fits = (2**31 - 1) // updates * tiny().batch_size  # the most agent steps that fit
    assert tiny(total_steps=fits).num_iterations * updates <= 2**31 - 1
    with pytest.raises(ValueError, match="total_steps is too large for anneal_lr"):
        tiny(total_steps=fits + 1)
    assert tiny(total_steps=fits + 1, anneal_lr=False).total_steps == fits + 1


def test_ppo_config_spells_the_game_one_way():
    assert tiny(game="BREAKOUT").game == tiny(game="breakout").game == "Breakout"


def test_ppo_config_stores_plain_python_numbers():
    config = tiny(num_envs=np.int64(2), gamma=np.float32(0.5), learning_rate=1)
    assert type(config.num_envs) is int and type(config.gamma) is float
    assert type(config.learning_rate) is float and config.learning_rate == 1.0


def test_seed_must_leave_room_for_both_halves_env_seeds():
    assert tiny(seed=2**30 - 1).seed == 2**30 - 1  # its second half's envs use seed 2**31 - 1
    with pytest.raises(ValueError, match=r"seed must be in \[0, 1073741823\], got 1073741824"):
        tiny(seed=2**30)


def test_gae_by_hand():
    rollout = ppo.Rollout(obs=None, action=None, logp=None,
                          value=jnp.array([[0.5], [1.0]]), reward=jnp.array([[1.0], [0.0]]),
                          done=jnp.array([[False], [True]]))
    adv, ret = ppo.gae(rollout, jnp.array([7.0]), gamma=0.9, lam=0.5)
    # step 1 ends the episode: its delta ignores the bootstrap value 7
    d1 = 0.0 - 1.0
    d0 = 1.0 + 0.9 * 1.0 - 0.5
    np.testing.assert_allclose(adv[:, 0], [d0 + 0.9 * 0.5 * d1, d1], rtol=1e-6)
    np.testing.assert_allclose(ret, adv + rollout.value)


def reference_gae(reward, value, done, last_value, gamma, lam):
    """GAE as its definition reads: A_t = sum_l (gamma lam)^l delta_{t+l}, the sum and the
    bootstrap stopping at the end of the episode (done[t]: it ended after step t)."""
    steps, envs = reward.shape
    values = np.concatenate([value, last_value[None]])  # V(s_T): the bootstrap value
    delta = reward + gamma * values[1:] * (1 - done) - value
    advantages = np.zeros_like(reward)
    for b in range(envs):
        for t in range(steps):
            for l in range(steps - t):
                advantages[t, b] += (gamma * lam) ** l * delta[t + l, b]
                if done[t + l, b]:
                    break
    return advantages, advantages + value


def test_gae_is_the_discounted_sum_of_td_errors_cut_at_episode_ends():
    """A hand-made batch with episodes ending mid-rollout, on consecutive steps and on the last
    step: no advantage may flow back across an episode's end (only the bootstrap was checked)."""
    rng = np.random.default_rng(0)
    reward = rng.normal(size=(7, 3))
    value = rng.normal(size=(7, 3))
    done = np.zeros((7, 3), bool)
    done[2, 0] = done[3, 0] = True          # two episodes end on consecutive steps
    done[4, 1] = True                       # one ends mid-rollout
    done[6, 2] = True                       # one ends on the last step: no bootstrap
    last_value = np.array([5.0, -3.0, 11.0])
    rollout = ppo.Rollout(obs=None, action=None, logp=None, value=jnp.asarray(value, jnp.float32),
                          reward=jnp.asarray(reward, jnp.float32), done=jnp.asarray(done))
    adv, ret = ppo.gae(rollout, jnp.asarray(last_value, jnp.float32), gamma=0.9, lam=0.8)
    expected_adv, expected_ret = reference_gae(reward, value, done, last_value, 0.9, 0.8)
    np.testing.assert_allclose(adv, expected_adv, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(ret, expected_ret, rtol=1e-5, atol=1e-5)


class TableNetwork:
    """A stand-in for the network: its parameters are a table of logits and values, one row per
    sample, and its 'frames' are the samples' indices into it."""

    @staticmethod
    def apply(params, obs):
        return params["logits"][obs], params["value"][obs]


def reference_ppo_loss(logits, value, batch, clip, ent_coef, vf_coef, clip_vloss):
    """CleanRL's ppo_atari loss, in float64 numpy: normalised advantages, the clipped
    surrogate, the (clipped) value loss, the entropy bonus, and the logged KL and clip fraction."""
    _, action, old_logp, old_value, advantage, target = (np.asarray(x, np.float64) for x in batch)
    log_probs = logits - np.log(np.exp(logits).sum(axis=1, keepdims=True))
    log_ratio = log_probs[np.arange(len(action)), action.astype(int)] - old_logp
    ratio = np.exp(log_ratio)
    adv = (advantage - advantage.mean()) / (advantage.std() + 1e-8)
    pg_loss = np.maximum(-adv * ratio, -adv * np.clip(ratio, 1 - clip, 1 + clip)).mean()
    if clip_vloss:
        clipped = old_value + np.clip(value - old_value, -clip, clip)
        v_loss = 0.5 * np.maximum((value - target) ** 2, (clipped - target) ** 2).mean()
    else:
        v_loss = 0.5 * ((value - target) ** 2).mean()
    entropy = -(np.exp(log_probs) * log_probs).sum(axis=1).mean()
    return pg_loss - ent_coef * entropy + vf_coef * v_loss, dict(
        pg_loss=pg_loss, v_loss=v_loss, entropy=entropy,
        approx_kl=((ratio - 1) - log_ratio).mean(),
        clipfrac=(np.abs(ratio - 1) > clip).mean())


@pytest.mark.parametrize("clip_vloss", [True, False])
def test_the_ppo_loss_is_cleanrls_on_a_hand_made_batch(clip_vloss):
    """The loss checked against a numpy reference, on a batch whose ratios and values lie on
    both sides of the clip range and whose advantages are far from normalised (the loss-lowering
    test passes with the clipping reversed, the entropy bonus's sign flipped or the advantage
    normalisation removed)."""
    rng = np.random.default_rng(1)
    n, num_actions = 24, 4
    logits = rng.normal(size=(n, num_actions))
    action = rng.integers(0, num_actions, n)
    log_probs = logits - np.log(np.exp(logits).sum(axis=1, keepdims=True))
    old_logp = log_probs[np.arange(n), action] - np.linspace(-0.45, 0.45, n)  # ratios 0.64..1.57
    value = rng.normal(size=n)
    old_value = value + rng.uniform(-0.6, 0.6, n)  # half of them beyond the clip range
    advantage = 3.0 + 2.0 * rng.normal(size=n)
    target = value + rng.normal(size=n)
    batch = tuple(jnp.asarray(x, dtype) for x, dtype in (
        (np.arange(n), jnp.int32), (action, jnp.int32), (old_logp, jnp.float32),
        (old_value, jnp.float32), (advantage, jnp.float32), (target, jnp.float32)))
    config = tiny(clip_coef=0.2, ent_coef=0.05, vf_coef=0.7, clip_vloss=clip_vloss)
    params = dict(logits=jnp.asarray(logits, jnp.float32), value=jnp.asarray(value, jnp.float32))
    loss, metrics = ppo.ppo_loss(TableNetwork(), config, params, batch)
    expected_loss, expected = reference_ppo_loss(logits, value, batch, 0.2, 0.05, 0.7, clip_vloss)
    assert 0.2 < expected["clipfrac"] < 0.8, "the batch has ratios on both sides of the clip"
    np.testing.assert_allclose(float(loss), expected_loss, rtol=1e-5, atol=1e-6)
    for name, value in expected.items():
        np.testing.assert_allclose(float(metrics[name]), value, rtol=1e-5, atol=1e-6,
                                   err_msg=name)


def test_act_samples_from_the_policy_and_returns_the_sampled_actions_log_probs():
    logits = 3 * jax.random.normal(jax.random.PRNGKey(0), (64, 4))
    params = dict(logits=logits, value=jnp.arange(64.0))
    action, logp, value = ppo.act(TableNetwork(), params, jnp.arange(64), jax.random.PRNGKey(2))
    np.testing.assert_array_equal(action, jax.random.categorical(jax.random.PRNGKey(2), logits))
    log_probs = np.asarray(jax.nn.log_softmax(logits))
    np.testing.assert_allclose(logp, log_probs[np.arange(64), np.asarray(action)], rtol=1e-6)
    np.testing.assert_array_equal(value, np.arange(64.0))
    assert len(set(np.asarray(action).tolist())) == 4, "the draws are not one action"


def test_each_epoch_visits_every_sample_once_in_minibatches_of_a_fresh_order(monkeypatch):
    config = tiny(update_epochs=3, num_minibatches=4)
    t, b = config.num_steps, config.num_envs
    ids = jnp.arange(config.batch_size).reshape(t, b)  # each sample's frames: its index
    rollout = ppo.Rollout(obs=ids, action=jnp.zeros((t, b), jnp.int32), logp=jnp.zeros((t, b)),
                          value=jnp.zeros((t, b)), reward=jnp.ones((t, b)),
                          done=jnp.zeros((t, b), bool))
    params = dict(logits=jnp.zeros((config.batch_size, 4)), value=jnp.zeros(config.batch_size))
    seen = []
    loss = ppo.ppo_loss

    def spy(network, config, params, batch):
        jax.debug.callback(lambda i: seen.append(np.asarray(i)), batch[0], ordered=True)
        return loss(network, config, params, batch)

    monkeypatch.setattr(ppo, "ppo_loss", spy)
    optimizer = ppo.make_optimizer(config)
    update = ppo.make_update(TableNetwork(), optimizer, config)
    jax.block_until_ready(update(params, optimizer.init(params), rollout, ids[-1],
                                 jax.random.PRNGKey(1)))
    jax.effects_barrier()
    assert [len(batch) for batch in seen] == [config.minibatch_size] * 12
    epochs = [np.concatenate(seen[e * 4:(e + 1) * 4]) for e in range(3)]
    for order in epochs:
        assert sorted(order) == list(range(config.batch_size)), "every sample once an epoch"
    assert len({tuple(order) for order in epochs}) == 3, "each epoch shuffles anew"
    assert list(epochs[0]) != list(range(config.batch_size))


def test_the_update_trains_on_the_gae_of_its_rollout_and_logs_the_mean_of_its_minibatches(
        monkeypatch):
    """Each minibatch's advantages and targets are GAE's (gamma and lambda as configured, the
    bootstrap the value of the observation after the rollout) of its own samples; the logged
    losses are the mean over epochs x minibatches, and the explained variance is the value
    predictions' of the targets (the loss-lowering and loss tests pass with advantages and
    targets swapped, gamma and lambda swapped, or either log wrong)."""
    config = tiny(update_epochs=2, num_minibatches=4, gamma=0.9, gae_lambda=0.5)
    t, b, n = config.num_steps, config.num_envs, config.batch_size
    rng = np.random.default_rng(3)
    ids = jnp.arange(n).reshape(t, b)  # each sample's frames: its index; n.. the last obs
    table = rng.normal(size=n + b).astype(np.float32)
    rollout = ppo.Rollout(obs=ids, action=jnp.asarray(rng.integers(0, 4, (t, b)), jnp.int32),
                          logp=jnp.full((t, b), -np.log(4.0)), value=jnp.asarray(table[:n]
                                                                                .reshape(t, b)),
                          reward=jnp.asarray(rng.normal(size=(t, b)), jnp.float32),
                          done=jnp.asarray(rng.random((t, b)) < 0.2))
    params = dict(logits=jnp.zeros((n + b, 4)), value=jnp.asarray(table))
    advantages, targets = reference_gae(np.asarray(rollout.reward, np.float64), table[:n]
                                        .reshape(t, b).astype(np.float64),
                                        np.asarray(rollout.done), table[n:].astype(np.float64),
                                        0.9, 0.5)
    seen, loss = [], ppo.ppo_loss

    def spy(network, config, params, batch):
        out = loss(network, config, params, batch)
        jax.debug.callback(lambda *x: seen.append([np.asarray(v) for v in x]), batch[0],
                           batch[4], batch[5], out[1]["pg_loss"], out[1]["v_loss"],
                           ordered=True)
        return out

    monkeypatch.setattr(ppo, "ppo_loss", spy)
    optimizer = ppo.make_optimizer(config)
    update = ppo.make_update(TableNetwork(), optimizer, config)
    *_, metrics = update(params, optimizer.init(params), rollout, jnp.arange(n, n + b),
                         jax.random.PRNGKey(1))
    metrics = jax.device_get(metrics)
    jax.effects_barrier()
    assert len(seen) == 8
    for index, advantage, target, _, _ in seen:
        np.testing.assert_allclose(advantage, advantages.reshape(-1)[index], rtol=1e-5,
                                   atol=1e-5)
        np.testing.assert_allclose(target, targets.reshape(-1)[index], rtol=1e-5, atol=1e-5)
    for column, name in ((3, "pg_loss"), (4, "v_loss")):
        np.testing.assert_allclose(metrics[name], np.mean([x[column] for x in seen]), rtol=1e-5)
    residual = targets.reshape(-1) - table[:n]
    np.testing.assert_allclose(metrics["explained_variance"],
                               1 - residual.var() / targets.var(), rtol=1e-4)


def test_gradients_are_clipped_to_max_grad_norm_before_adam():
    """Adam alone is nearly scale-free, so only its eps (1e-5, CleanRL's) shows the clipping:
    a gradient clipped to norm 1e-9 moves the parameters about 1e-4 as far as an unclipped
    one."""
    grads = {"w": jnp.array([3.0, -4.0])}
    params = {"w": jnp.zeros(2)}
    for max_grad_norm, norm in ((10.0, 5.0), (1e-9, 1e-9)):
        optimizer = ppo.make_optimizer(tiny(max_grad_norm=max_grad_norm, anneal_lr=False,
                                            learning_rate=0.1))
        updates, _ = optimizer.update(grads, optimizer.init(params), params)
        g = np.array([3.0, -4.0]) * norm / 5.0  # the gradient clipped to norm max_grad_norm
        # Adam's first step: -lr * m_hat / (sqrt(v_hat) + eps), with m_hat = g, v_hat = g ** 2
        np.testing.assert_allclose(updates["w"], -0.1 * g / (np.abs(g) + 1e-5), rtol=1e-4)


# -- training runs: determinism and resume ----------------------------------------------------

def read_log(path):
    with open(path / "log.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return [{k: v for k, v in r.items() if k not in ppo.TIMING_FIELDS} for r in rows]


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
    out = tmp_path_factory.mktemp("full")
    summary = ppo.train(tiny(), out, progress=False)
    return out, summary


def test_training_writes_its_files(uninterrupted):
    out, summary = uninterrupted
    assert summary["finished"] and summary["agent_steps"] == 3 * 64
    assert {p.name for p in out.iterdir()} >= {"config.json", "log.csv", "episodes.csv",
                                              "checkpoint.pkl", "summary.json"}
    recorded = json.loads((out / "summary.json").read_text())["software"]
    assert recorded["packages"]["jax"] == jax.__version__
    assert recorded["commit"] == provenance.code_commit()
    log = read_log(out)
    assert [int(r["global_step"]) for r in log] == [64, 128, 192]
    assert json.loads((out / "config.json").read_text())["network"] == "tiny"


def test_the_logged_learning_rate_is_the_optimizers(uninterrupted):
    """`lr` is the rate the optimizer's next update uses: its schedule at its update count."""
    out, _ = uninterrupted
    config = tiny()
    counted = lambda x: "count" in getattr(x, "_fields", ())  # optax's schedule states
    states = jax.tree.leaves(read_checkpoint(out)["opt_state"], is_leaf=counted)
    assert {int(s.count) for s in states if counted(s)} == {
        3 * config.update_epochs * config.num_minibatches}, "one count per minibatch update"
    logged = [float(r["lr"]) for r in read_log(out)]
    np.testing.assert_allclose(logged, [config.learning_rate * (1 - i / 3) for i in (1, 2, 3)],
                               rtol=1e-6, atol=1e-12)
    assert ppo.learning_rate_schedule(tiny(anneal_lr=False)) == config.learning_rate
    assert ppo.learning_rate_at(tiny(anneal_lr=False), 7) == config.learning_rate


def test_resume_reproduces_the_uninterrupted_run(uninterrupted, tmp_path):
    full, _ = uninterrupted
    partial = ppo.train(tiny(), tmp_path, progress=False, stop_after=1)
    assert not partial["finished"] and not (tmp_path / "summary.json").exists()
    assert len(read_log(tmp_path)) == 1
    assert ppo.train(tiny(), tmp_path, resume=True, progress=False)["iterations_now"] == 2
    assert read_log(tmp_path) == read_log(full)
    assert (tmp_path / "episodes.csv").read_text() == (full / "episodes.csv").read_text()
    a, b = read_checkpoint(full), read_checkpoint(tmp_path)
    assert_trees_equal((a["params"], a["opt_state"], a["key"], a["obs"]),
                       (b["params"], b["opt_state"], b["key"], b["obs"]))


def test_resume_after_a_crash_between_checkpoints_drops_the_rows_it_trains_again(
        uninterrupted, tmp_path, monkeypatch):
    """A run that dies after logging an iteration but before checkpointing it (every 2nd
    iteration here): its log is one row ahead of its checkpoint. Resuming trains that iteration
    again, and the log and episodes must hold it once, as the uninterrupted run's do (every
    other resume test checkpointed at its last logged row)."""
    full, _ = uninterrupted
    save, saved = ppo.save_checkpoint, []

    def dies_at_the_second_save(path, payload):  # iteration 3's rows logged, never saved
        saved.append(payload["iteration"])
        if len(saved) == 2:
            raise KeyboardInterrupt
        save(path, payload)

    monkeypatch.setattr(ppo, "save_checkpoint", dies_at_the_second_save)
    with pytest.raises(KeyboardInterrupt):
        ppo.train(tiny(checkpoint_every=2), tmp_path, progress=False)
    monkeypatch.setattr(ppo, "save_checkpoint", save)
    assert saved == [2, 3] and read_checkpoint(tmp_path)["iteration"] == 2
    assert len(read_log(tmp_path)) == 3  # one row past the checkpoint
    ppo.train(tiny(checkpoint_every=2), tmp_path, resume=True, progress=False)
    assert read_log(tmp_path) == read_log(full)
    assert (tmp_path / "episodes.csv").read_text() == (full / "episodes.csv").read_text()


def test_a_resumed_run_records_each_parts_software_and_warns_when_it_changed(
        uninterrupted, tmp_path, monkeypatch):
    """A resumed run's summary named only its last part's software; a part trained with other
    software (another jax, another commit) went unnoticed."""
    full, summary = uninterrupted
    assert summary["software_parts"] == [dict(from_iteration=0, software=summary["software"])]
    ppo.train(tiny(), tmp_path, progress=False, stop_after=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the same software: no warning
        ppo.train(tiny(), tmp_path, progress=False, stop_after=2, resume=True)
    first = provenance.software()
    later = dict(first, commit="0" * 40, packages=dict(first["packages"], jax="9.9"))
    monkeypatch.setattr(runs, "software", lambda: later)
    with pytest.warns(UserWarning, match=r"other software \(commit \S+ -> '0{40}'; "
                      r"jax '[^']+' -> '9\.9'\): from iteration 2 on"):
        ppo.train(tiny(), tmp_path, progress=False, resume=True)
    recorded = json.loads((tmp_path / "summary.json").read_text())
    assert recorded["software"] == later
    assert recorded["software_parts"] == [dict(from_iteration=0, software=first),
                                          dict(from_iteration=2, software=later)]
    # a checkpoint from before the history was kept: its parts' software is unrecorded
    ckpt = read_checkpoint(full)
    del ckpt["software_parts"]
    assert runs.software_parts(ckpt, 3, later, full / "checkpoint.pkl") == [
        dict(from_iteration=0, software=None), dict(from_iteration=3, software=later)]


def test_resuming_a_finished_run_says_there_is_nothing_to_train(uninterrupted, capsys):
    """It printed 'trained 192 agent steps in 6 s' and trained nothing."""
    full, _ = uninterrupted
    log = read_log(full)
    settings = [a for k, v in TINY.items() if k not in ("game", "preset", "total_steps")
                for a in ("--set", f"{k}={v}")]
    assert main(["train", "ppo", "--game", "Breakout", "--preset", "1", "--steps", "192",
                 *settings, "--out", str(full), "--resume", "--quiet"]) == 0
    assert f"nothing to train: {full} holds a finished run of 192 agent steps" in \
        capsys.readouterr().out
    assert read_log(full) == log


def test_resuming_a_finished_run_touches_no_file(uninterrupted, monkeypatch):
    """With other software it warned that the run 'will not match' from its last iteration on,
    and rewrote summary.json with that software as a part of the run, though nothing trained."""
    full, summary = uninterrupted
    files = {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in full.iterdir()}
    later = dict(summary["software"], commit="0" * 40)
    monkeypatch.setattr(runs, "software", lambda: later)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        again = ppo.train(tiny(), full, progress=False, resume=True)
    assert {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in full.iterdir()} == files
    assert again == dict(summary, iterations_now=0, agent_steps_now=0)


def test_resuming_a_run_stopped_before_its_summary_writes_it(uninterrupted, tmp_path):
    """An interruption after the last checkpoint but before summary.json: --resume has nothing
    to train and writes the summary (run_evidence.py resumes such runs and reads it)."""
    import shutil

    full, _ = uninterrupted
    run = tmp_path / "run"
    shutil.copytree(full, run)
    (run / "summary.json").unlink()
    assert ppo.train(tiny(), run, progress=False, resume=True)["iterations_now"] == 0
    assert json.loads((run / "summary.json").read_text()) == json.loads(
        (full / "summary.json").read_text())


@pytest.fixture(scope="module")
def staged_once(tmp_path_factory):
    """run_long.py's stages (1 and 2) of the tiny run (trained once per module)."""
    from baselines.evidence import run_long

    root = tmp_path_factory.mktemp("staged")
    run, by_step = root / "run", root / "by-step"
    run_long.train_in_stages(tiny(), run, by_step, stages=(1, 2), episodes=2, num_envs=2,
                             progress=False)
    return run, by_step


@pytest.fixture
def staged(staged_once, tmp_path):
    """A copy of the staged run in tmp_path (its run and by-step folders), for a test to change."""
    run, by_step = tmp_path / "run", tmp_path / "by-step"
    shutil.copytree(staged_once[0], run)
    shutil.copytree(staged_once[1], by_step)
    return run, by_step


def count_calls(monkeypatch):
    """Count (and let through) ppo.train's and evaluate's calls from run_long."""
    import baselines.evaluate

    calls = dict(train=0, evaluate=0)
    for module, name in ((ppo, "train"), (baselines.evaluate, "evaluate")):
        def counted(*args, _real=getattr(module, name), _name=name, **kwargs):
            calls[_name] += 1
            return _real(*args, **kwargs)
        monkeypatch.setattr(module, name, counted)
    return calls


def test_a_run_trained_in_stages_is_the_uninterrupted_run_with_each_stage_evaluated(
        uninterrupted, staged_once, tmp_path, monkeypatch):
    """The run ends as the uninterrupted one; each stage's checkpoint is the one a run stopped
    there holds, evaluated with its own progress; a second call trains and evaluates
    nothing."""
    from baselines.evidence import run_long

    full, _ = uninterrupted
    run, by_step = staged_once
    assert read_log(run) == read_log(full)
    assert (run / "episodes.csv").read_text() == (full / "episodes.csv").read_text()
    stopped = tmp_path / "stopped"
    ppo.train(tiny(), stopped, progress=False, stop_after=1)
    a, b = read_checkpoint(by_step / "64" / "seed0"), read_checkpoint(stopped)
    assert a["iteration"] == 1
    assert_trees_equal((a["params"], a["opt_state"], a["key"]),
                       (b["params"], b["opt_state"], b["key"]))
    for where, steps, finished in ((by_step / "64" / "seed0", 64, False),
                                   (by_step / "128" / "seed0", 128, False), (run, 192, True)):
        result = json.loads((where / "eval-sampled.json").read_text())
        assert (result["trained_agent_steps"], result["run_finished"]) == (steps, finished)
        assert result["episodes"] == 2 and result["eval_seed"] == 10_000
        assert result["checkpoint"] == str((where / "checkpoint.pkl").resolve())  # not ours
    assert not list(run.parent.rglob("*.tmp")) and not list(tmp_path.rglob("*.tmp"))
    calls = count_calls(monkeypatch)
    run_long.train_in_stages(tiny(), run, by_step, stages=(1, 2), episodes=2, num_envs=2,
                             progress=False)
    assert calls == dict(train=0, evaluate=0)


def test_stages_resume_where_an_interruption_left_them(uninterrupted, staged, tmp_path,
                                                       monkeypatch):
    """Stopped at any point, the script does only what is left: a stage trained but not
    copied aside, a copy not evaluated, a run trained but without its summary."""
    from baselines.evidence import run_long

    full, _ = uninterrupted
    run, by_step = staged
    again, again_by_step = tmp_path / "again", tmp_path / "again-by-step"
    ppo.train(tiny(), again, progress=False, stop_after=1)  # stopped before the copy
    calls = count_calls(monkeypatch)
    run_long.train_in_stages(tiny(), again, again_by_step, stages=(1, 2), episodes=2,
                             num_envs=2, progress=False)
    assert calls == dict(train=3, evaluate=3)  # stage 1 has nothing left to train
    assert read_log(again) == read_log(full)
    for where in ("64/seed0", "128/seed0"):
        assert (json.loads((again_by_step / where / "eval-sampled.json").read_text())["returns"]
                == json.loads((by_step / where / "eval-sampled.json").read_text())["returns"])
    (by_step / "128" / "seed0" / "eval-sampled.json").unlink()  # copied, not evaluated
    (run / "summary.json").unlink()  # trained, summary not written
    calls = count_calls(monkeypatch)
    run_long.train_in_stages(tiny(), run, by_step, stages=(1, 2), episodes=2, num_envs=2,
                             progress=False)
    assert calls == dict(train=1, evaluate=1)
    assert json.loads((run / "summary.json").read_text())["finished"]


def test_stages_refuse_what_they_cannot_resume(staged, tmp_path):
    """A run trained past a stage whose checkpoint is missing, a run without its checkpoint
    (a fresh clone's: checkpoints are not committed) and bad stages are refused by name;
    the run's files are left as they were."""
    from baselines.evidence import run_long

    run, by_step = staged
    log = (run / "log.csv").read_text()
    with pytest.raises(ValueError, match=r"has trained 3 iterations, past stage 1, and .*"
                                         r"elsewhere/64/seed0/checkpoint.pkl is missing"):
        run_long.train_in_stages(tiny(), run, tmp_path / "elsewhere", stages=(1,), episodes=2,
                                 num_envs=2, progress=False)
    (run / "checkpoint.pkl").unlink()
    with pytest.raises(ValueError, match=r"run holds a finished run \(summary.json, "
                                         r"eval-sampled.json\) without "
                                         r"its checkpoint.pkl"):
        run_long.train_in_stages(tiny(), run, tmp_path / "elsewhere", stages=(1,), episodes=2,
                                 num_envs=2, progress=False)
    assert (run / "log.csv").read_text() == log
    for stages in ((0,), (3,), (2, 1), (1, 1)):
        with pytest.raises(ValueError, match=r"stages must be increasing iterations between 1 "
                                             rf"and 2 .*got {re.escape(str(list(stages)))}"):
            run_long.train_in_stages(tiny(), tmp_path / "bad", by_step, stages=stages)


def long_evaluation(root, where, seed, steps, returns, **fields):
    write_result(dict(dict(game="Boxing", preset="3.1", policy="sampled", train_seed=seed,
                           trained_agent_steps=steps, run_total_steps=1_000_000,
                           episodes=len(returns), mean_return=float(np.mean(returns)),
                           std_return=float(np.std(returns))), **fields), root / where)


def test_the_onset_table_lists_each_stages_evaluations_by_seed(tmp_path, monkeypatch):
    """run_long.py's onset.md: a row per agent steps (from each evaluation's own record, not
    its folder), each seed's mean ± episode std, the mean ± std of the seed means (saying how
    many seeds where some are missing), the random policy's row."""
    from baselines.evidence import run_long

    long_evaluation(tmp_path, "runs/seed0", 0, 3000, [4.0, 6.0])
    long_evaluation(tmp_path, "runs/seed7", 7, 3000, [1.0, 3.0])
    long_evaluation(tmp_path, "by-step/1000/seed0", 0, 1000, [0.0, 1.0])
    long_evaluation(tmp_path, "by-step/1000/seed7", 7, 1000, [-1.0, 1.0])
    long_evaluation(tmp_path, "by-step/1000/seed13", 13, 1000, [3.0, 5.0])
    long_evaluation(tmp_path, "by-step/2000/seed0", 0, 2000, [2.0, 2.0])
    random = {0: dict(mean_return=0.5, std_return=1.0), 7: dict(mean_return=1.5, std_return=2.0),
              13: dict(mean_return=1.0, std_return=3.0)}
    monkeypatch.setattr(run_long, "random_evaluations", lambda seeds: random)
    text = run_long.write_onset(tmp_path)
    assert text == (tmp_path / "onset.md").read_text()
    assert text.splitlines()[:7] == [
        "| agent steps | seed 0 | seed 7 | seed 13 | mean ± std over seeds |",
        "|---|---|---|---|---|",
        "| 1,000 | 0.50 ± 0.50 | 0.00 ± 1.00 | 4.00 ± 1.00 | 1.50 ± 2.18 |",
        "| 2,000 | 2.00 ± 0.00 | - | - | - |",
        "| 3,000 | 5.00 ± 1.00 | 2.00 ± 1.00 | - | 3.50 ± 2.12 (2 of 3 seeds) |",
        "| random policy | 0.50 ± 1.00 | 1.50 ± 2.00 | 1.00 ± 3.00 | 1.00 ± 0.50 |", ""]
    assert "its 2 evaluation episodes ± their std" in text
    assert (tmp_path / "onset.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_random_policys_boxing_evaluations_are_the_recorded_ones():
    from baselines.evidence import run_long
    from baselines.evidence.run_evidence import run_dir

    found = run_long.random_evaluations(run_long.SEEDS)
    assert sorted(found) == list(run_long.SEEDS)
    for seed, result in found.items():
        assert (result["game"], result["preset"], result["train_seed"]) == ("Boxing", "3.1", seed)
        assert result == json.loads((run_dir("Boxing", "3.1", "random", seed)
                                     / "eval-random.json").read_text())


@pytest.mark.parametrize("where, fields, match", [
    ("elsewhere/seed0", dict(), r"a second evaluation of seed 0 at 2000 agent steps \(the "
                                r"other: .*by-step/2000/seed0/eval-sampled.json\)"),
    ("old", dict(trained_agent_steps=None), r"old/eval-sampled.json lacks trained_agent_steps"),
    ("other", dict(preset="1"), r"other/eval-sampled.json: preset is '1', not '3.1'"),
    ("greedy", dict(policy="greedy"), r"greedy/eval-greedy.json: policy is 'greedy', not "
                                      r"'sampled'"),
    ("short", dict(run_total_steps=100_000), r"run_total_steps is 100000, not 1000000"),
])
def test_the_onset_refuses_evaluations_it_cannot_place(tmp_path, where, fields, match):
    from baselines.evidence import run_long

    with pytest.raises(ValueError, match=r"no evaluations below .*: run the script first"):
        run_long.write_onset(tmp_path)
    long_evaluation(tmp_path, "by-step/2000/seed0", 0, 2000, [2.0])
    long_evaluation(tmp_path, where, 0, 2000, [9.0], **fields)
    if fields.get("trained_agent_steps", 1) is None:
        path = tmp_path / where / "eval-sampled.json"
        path.write_text(json.dumps({k: v for k, v in json.loads(path.read_text()).items()
                                    if k != "trained_agent_steps"}))
    with pytest.raises(ValueError, match=match):
        run_long.evaluations_by_step(tmp_path)


def test_same_seed_same_updates_other_seed_others(uninterrupted, tmp_path):
    full, _ = uninterrupted
    ppo.train(tiny(), tmp_path / "same", progress=False, stop_after=1)
    first = read_log(full)[0]
    assert read_log(tmp_path / "same") == [first]
    ppo.train(tiny(seed=1), tmp_path / "other", progress=False, stop_after=1)
    assert read_log(tmp_path / "other")[0]["pg_loss"] != first["pg_loss"]


def test_resume_refuses_another_config(uninterrupted, tmp_path):
    full, _ = uninterrupted
    ppo.train(tiny(total_steps=64), tmp_path, progress=False)
    with pytest.raises(ValueError, match=r"different config: ent_coef \S+ there, 0\.5 now$"):
        ppo.train(tiny(total_steps=64, ent_coef=0.5), tmp_path, resume=True, progress=False)
    with pytest.raises(ValueError, match="does not exist"):
        ppo.train(tiny(), tmp_path / "nothing", resume=True, progress=False)
    shutil.copytree(full, tmp_path / "at-3")
    with pytest.raises(ValueError, match=r"stop_after 2 is before .*checkpoint.pkl's iteration "
                                         "3: a run cannot go back"):
        ppo.train(tiny(), tmp_path / "at-3", resume=True, progress=False, stop_after=2)
    assert read_log(tmp_path / "at-3") == read_log(full)
    with pytest.raises(ValueError, match="stop_after must be >= 1, got 0"):
        ppo.train(tiny(), tmp_path / "other", progress=False, stop_after=0)


@pytest.mark.parametrize("kw,match", [
    (dict(num_envs=3), "num_envs must be even"), (dict(network="resnet"), "network must be"),
    (dict(num_minibatches=5), "divisible"), (dict(gamma=1.5), "gamma"),
    (dict(preset="9.9"), "preset"), (dict(game="Pong2"), "game"), (dict(seed=-1), "seed"),
    (dict(action_head="tree"), "action_head must be one of"),
    (dict(action_head="factored"), "full 18 actions.*Breakout has 4"),
    (dict(learning_rate=0), "learning_rate must be > 0"),
    (dict(max_grad_norm=0.0), "max_grad_norm must be > 0"),
])
def test_bad_hyperparameters_are_named(kw, match):
    with pytest.raises(ValueError, match=match):
        tiny(**kw)


def test_overrides_are_typed():
    config = ppo.PPOConfig.from_overrides(tiny(), {"learning_rate": "1e-3", "anneal_lr": "false",
                                                   "num_envs": "8"})
    assert (config.learning_rate, config.anneal_lr, config.num_envs) == (1e-3, False, 8)
    with pytest.raises(ValueError, match="num_envs must be an int"):
        ppo.PPOConfig.from_overrides(tiny(), {"num_envs": "eight"})


class ScriptedHalf:
    """A stand-in for one half-batch of stori-jax envs (send/recv, snapshot/restore) playing a
    script: global env e gets reward 3 (e + 1) when (t + e) % 3 == 0 and -2 when (t + e) % 5 == 0
    on its t-th step, and its episode terminates when (t + e) % 7 == 0 or is truncated when
    (t + 2 e) % 11 == 0.  Frames carry t and e (and info's final_obs 100 + e where an episode
    ended); the actions sent are kept."""

    num_actions = 4

    def __init__(self, num_envs: int, first: int):
        self.num_envs, self.ids = num_envs, first + np.arange(num_envs)
        self.t, self.returns, self.lengths = 0, np.zeros(num_envs), np.zeros(num_envs, int)
        self.sent = []

    def frames(self):
        obs = np.zeros((self.num_envs, 84, 84, 4), np.uint8)
        obs[:, 0, 0, 0], obs[:, 0, 0, 1] = self.t % 256, self.ids
        return obs

    def reset(self):
        return self.frames(), {}

    def send(self, actions):
        self.sent.append(np.asarray(actions))

    def recv(self):
        self.t += 1
        t, e = self.t, self.ids
        reward = np.where((t + e) % 3 == 0, 3.0 * (e + 1), np.where((t + e) % 5 == 0, -2.0, 0.0))
        terminated, truncated = (t + e) % 7 == 0, (t + 2 * e) % 11 == 0
        done = terminated | truncated
        self.returns, self.lengths = self.returns + reward, self.lengths + 1
        final_obs = self.frames()  # the ended episodes' last frames carry 100 + e
        final_obs[:, 0, 0, 2] = np.where(done, 100 + e, 0)
        info = dict(episode_return=np.where(done, self.returns, 0.0),
                    episode_length=np.where(done, self.lengths, 0), final_obs=final_obs)
        self.returns = np.where(done, 0.0, self.returns)
        self.lengths = np.where(done, 0, self.lengths)
        return self.frames(), reward.astype(np.float32), terminated, truncated, info

    def snapshot(self):
        return dict(t=self.t, returns=self.returns.copy(), lengths=self.lengths.copy())

    def restore(self, snapshot):
        self.t, self.returns, self.lengths = (snapshot[k] for k in ("t", "returns", "lengths"))

    def close(self):
        pass


def scripted_episodes(num_envs: int, steps: int):
    """Every episode the script ends in ``steps`` steps of all envs: (global_step, env, return,
    length), global_step counting the agent steps of all envs, as episodes.csv does."""
    halves = [ScriptedHalf(num_envs // 2, 0), ScriptedHalf(num_envs // 2, num_envs // 2)]
    episodes = []
    for t in range(1, steps + 1):
        for half in halves:
            _, _, terminated, truncated, info = half.recv()
            for i in np.flatnonzero(terminated | truncated):
                episodes.append((t * num_envs, int(half.ids[i]), float(info["episode_return"][i]),
                                 int(info["episode_length"][i])))
    return sorted(episodes)


def test_a_rollout_records_each_step_of_both_halves_with_sign_clipped_rewards():
    """What collect() stores per step and env: the frames the action was chosen on, that
    action, the reward clipped to its sign, done = terminated or truncated, env e in column e,
    and every finished episode with its global step and env; every action with a key of its
    own."""
    halves = [ScriptedHalf(3, 0), ScriptedHalf(3, 3)]
    keys = []

    def act_fn(params, obs, key):
        keys.append(np.asarray(key))
        frames = np.asarray(obs)[:, 0, 0]
        action = (frames[:, 0].astype(int) + frames[:, 1]) % 4
        return (jnp.asarray(action, jnp.int32), jnp.asarray(frames[:, 1], jnp.float32),
                jnp.asarray(frames[:, 0], jnp.float32))

    episodes = []
    obs = [half.reset()[0] for half in halves]
    rollout, obs, key = ppo.collect(halves, act_fn, None, obs, jax.random.PRNGKey(0), 5,
                                    episodes, step0=600)
    t, e = np.arange(5)[:, None], np.arange(6)[None, :]
    frames = np.asarray(rollout.obs)[:, :, 0, 0]
    np.testing.assert_array_equal(frames[..., 0], np.broadcast_to(t, (5, 6)))  # before the step
    np.testing.assert_array_equal(frames[..., 1], np.broadcast_to(e, (5, 6)))
    np.testing.assert_array_equal(rollout.action, (t + e) % 4)
    np.testing.assert_array_equal(np.concatenate([np.stack(h.sent) for h in halves], axis=1),
                                  (t + e) % 4)
    np.testing.assert_array_equal(rollout.logp, np.broadcast_to(e, (5, 6)))
    raw = np.where((t + 1 + e) % 3 == 0, 3.0 * (e + 1), np.where((t + 1 + e) % 5 == 0, -2.0, 0.0))
    np.testing.assert_array_equal(rollout.reward, np.sign(raw))
    assert np.abs(raw).max() > 1, "rewards beyond +-1 are there to be clipped"
    terminated, truncated = (t + 1 + e) % 7 == 0, (t + 1 + 2 * e) % 11 == 0
    assert terminated.any() and truncated.any()
    np.testing.assert_array_equal(rollout.done, terminated | truncated)
    assert sorted(episodes) == [(600 + s, env, r, n) for s, env, r, n in scripted_episodes(6, 5)]
    assert np.asarray(obs[1])[0, 0, 0, 0] == 5
    assert len(keys) == 10 and len({k.tobytes() for k in keys}) == 10, "a key per action"
    assert not any(np.array_equal(np.asarray(key), k) for k in keys)


def test_an_episode_cut_off_at_the_cap_is_bootstrapped_from_its_final_observation():
    """With a value function, a truncated (and not terminated) step's reward is its sign plus
    gamma x the value of info["final_obs"]; every other step's is its sign alone, and done
    still marks the end (GAE does not reach into the next episode)."""
    halves = [ScriptedHalf(3, 0), ScriptedHalf(3, 3)]

    def act_fn(params, obs, key):
        return (jnp.zeros(obs.shape[0], jnp.int32), jnp.zeros(obs.shape[0]),
                jnp.zeros(obs.shape[0]))

    def value_fn(params, obs):  # the final frame's marker as its value
        return jnp.asarray(np.asarray(obs)[:, 0, 0, 2], jnp.float32)

    obs = [half.reset()[0] for half in halves]
    steps, gamma = 12, 0.5
    rollout, _, _ = ppo.collect(halves, act_fn, None, obs, jax.random.PRNGKey(0), steps, [],
                                step0=0, value_fn=value_fn, gamma=gamma)
    t, e = np.arange(1, steps + 1)[:, None], np.arange(6)[None, :]
    raw = np.where((t + e) % 3 == 0, 3.0 * (e + 1), np.where((t + e) % 5 == 0, -2.0, 0.0))
    terminated, truncated = (t + e) % 7 == 0, (t + 2 * e) % 11 == 0
    cut = truncated & ~terminated
    assert cut.any() and (truncated & terminated).any(), "both kinds of end are in the script"
    np.testing.assert_array_equal(rollout.reward,
                                  np.sign(raw) + np.where(cut, gamma * (100 + e), 0.0))
    np.testing.assert_array_equal(rollout.done, terminated | truncated)


def scripted_clock():
    """perf_counter for train(): the n-th call reads n ** 2 seconds, so that every iteration
    takes its own time (t0, t1, t2 of iteration k: (3k)^2, (3k + 1)^2, (3k + 2)^2)."""
    calls = iter(range(10**6))
    return lambda: float(next(calls)) ** 2


def test_the_log_counts_this_iterations_episodes_and_measures_speed_over_the_whole_run(
        tmp_path, monkeypatch):
    """log.csv on scripted envs and a scripted clock: each row's episodes, mean return and mean
    length are those of the episodes.csv rows of its iteration; sps is the run's agent steps
    over its whole training time (carried over a resume), rollout_sps this iteration's
    rollout, update_s its update; checkpoints every checkpoint_every iterations and at the
    end."""
    config = tiny(total_steps=5 * 64, checkpoint_every=2)
    monkeypatch.setattr(ppo, "make_envs", lambda c: [ScriptedHalf(2, 0), ScriptedHalf(2, 2)])
    monkeypatch.setattr(ppo, "time", type("Clock", (), dict(perf_counter=scripted_clock())))
    saved, save = [], ppo.save_checkpoint
    monkeypatch.setattr(ppo, "save_checkpoint",
                        lambda path, payload: (saved.append(payload["iteration"]),
                                               save(path, payload)))
    updates, make_update = [], ppo.make_update

    def recording_make_update(*args):
        update = make_update(*args)

        def recorded(params, opt_state, rollout, last_obs, key):
            updates.append((np.asarray(rollout.obs), np.asarray(last_obs)))
            return update(params, opt_state, rollout, last_obs, key)
        return recorded

    monkeypatch.setattr(ppo, "make_update", recording_make_update)
    ppo.train(config, tmp_path, progress=False, stop_after=3)
    summary = ppo.train(config, tmp_path, progress=False, resume=True)
    assert saved == [2, 3, 4, 5]
    # each update bootstraps from the observations after its rollout (step t + 1 of each env)
    for i, (obs, last_obs) in enumerate(updates):
        np.testing.assert_array_equal(last_obs[:, 0, 0, 0], (i + 1) * config.num_steps % 256)
        np.testing.assert_array_equal(last_obs[:, 0, 0, 1], [0, 1, 2, 3])
        np.testing.assert_array_equal(obs[-1][:, 0, 0, 0] + 1, last_obs[:, 0, 0, 0])
    with open(tmp_path / "episodes.csv", newline="") as f:
        episodes = [(int(r["global_step"]), int(r["env"]), float(r["return"]), int(r["length"]))
                    for r in csv.DictReader(f)]
    assert sorted(episodes) == scripted_episodes(4, 5 * 16)
    with open(tmp_path / "log.csv", newline="") as f:
        log = list(csv.DictReader(f))
    k = np.arange(5)
    iteration_s = (3 * k + 2) ** 2 - (3 * k) ** 2
    for i, row in enumerate(log):
        mine = [e for e in episodes if 64 * i < e[0] <= 64 * (i + 1)]
        assert int(row["episodes"]) == len(mine) > 0
        assert float(row["mean_return"]) == pytest.approx(np.mean([e[2] for e in mine]))
        assert float(row["mean_length"]) == pytest.approx(np.mean([e[3] for e in mine]))
        assert float(row["sps"]) == pytest.approx(64 * (i + 1) / iteration_s[:i + 1].sum())
        assert float(row["rollout_sps"]) == pytest.approx(64 / ((3 * i + 1) ** 2 - (3 * i) ** 2))
        assert float(row["update_s"]) == pytest.approx((3 * i + 2) ** 2 - (3 * i + 1) ** 2)
    assert summary["train_seconds"] == pytest.approx(iteration_s.sum())
    assert summary["train_sps"] == pytest.approx(5 * 64 / iteration_s.sum())


# -- evaluation -------------------------------------------------------------------------------

def test_quotas_split_the_episodes():
    assert list(episode_quotas(100, 16)) == [7] * 4 + [6] * 12
    assert episode_quotas(5, 5).sum() == 5


def test_random_evaluation_is_reproducible_and_exact_in_count(tmp_path):
    kw = dict(policy="random", episodes=3, num_envs=2, max_episode_frames=800, progress=False)
    a = evaluate("Breakout", "3.1", **kw)
    b = evaluate("Breakout", "3.1", **kw)
    assert a["returns"] == b["returns"] and len(a["returns"]) == 3
    assert a["eval_seed"] == 10_000 and a["agent"] == "random"
    with pytest.raises(ValueError, match="seed must be >= 0, got -1"):
        evaluate("Breakout", "3.1", seed=-1, **kw)
    assert write_result(a, tmp_path).name == "eval-random.json"


@pytest.mark.parametrize("policy", ["greedy", "sampled"])
def test_checkpoint_evaluation(uninterrupted, policy):
    full, _ = uninterrupted
    result = evaluate("Breakout", "1", policy=policy, episodes=2, num_envs=2,
                      checkpoint=full / "checkpoint.pkl", max_episode_frames=400,
                      progress=False)
    assert len(result["returns"]) == 2 and result["agent"] == "ppo"
    with pytest.raises(ValueError, match="trained on Breakout 1"):
        evaluate("Breakout", "3.1", policy=policy, episodes=1,
                 checkpoint=full / "checkpoint.pkl", progress=False)
    seed = ppo.PPOConfig.from_recorded(
        ppo.load_checkpoint(full / "checkpoint.pkl")["config"]).seed
    for eval_seed in ppo.train_env_seeds(seed):
        with pytest.raises(ValueError, match=rf"eval seed {eval_seed} is one of the training "
                                             r"envs' seeds .* choose another --eval-seed"):
            evaluate("Breakout", "1", policy=policy, episodes=1, eval_seed=eval_seed,
                     checkpoint=full / "checkpoint.pkl", progress=False)


def test_a_checkpoints_evaluation_is_filed_under_its_training_seed(uninterrupted, tmp_path):
    """Without `seed`, a checkpoint's result carries its own training seed (and the evaluation
    seeds follow from it); another seed is refused, as `eval --seed` refuses it."""
    full, _ = uninterrupted
    payload = read_checkpoint(full)
    payload["config"] = dict(payload["config"], seed=7)
    ppo.save_checkpoint(tmp_path / "checkpoint.pkl", payload)
    kw = dict(policy="greedy", episodes=1, num_envs=1, checkpoint=tmp_path / "checkpoint.pkl",
              max_episode_frames=40, progress=False)
    result = evaluate("Breakout", "1", **kw)
    assert (result["train_seed"], result["eval_seed"]) == (7, 10_007)
    config = ppo.PPOConfig.from_recorded(payload["config"])
    assert payload["iteration"] == config.num_iterations  # the run had finished
    assert (result["trained_agent_steps"], result["run_total_steps"], result["run_finished"]) \
        == (config.num_iterations * config.batch_size, config.total_steps, True)
    payload["iteration"] -= 1  # a checkpoint from before the run's end
    ppo.save_checkpoint(tmp_path / "checkpoint.pkl", payload)
    result = evaluate("Breakout", "1", **kw)
    assert (result["trained_agent_steps"], result["run_finished"]) == (
        (config.num_iterations - 1) * config.batch_size, False)
    assert evaluate("Breakout", "1", seed=7, **kw)["eval_seed"] == 10_007
    with pytest.raises(ValueError, match=r"seed 0 differs from the training seed 7 of "
                                         r"checkpoint .* give eval_seed"):
        evaluate("Breakout", "1", seed=0, **kw)


class ScriptedEvalEnv:
    """A stand-in for ``stori_jax.make``'s env in an evaluation: env i's episodes last 2 + 3 i
    steps and its k-th returns 10 i + k; env 1's second episode is cut off at the frame cap
    (truncated), env 2's first ends on the very step that reaches it (both)."""

    def __init__(self, game, preset, *, num_envs, seed, obs, max_episode_frames):
        self.made = dict(game=game, preset=preset, num_envs=num_envs, seed=seed, obs=obs,
                         max_episode_frames=max_episode_frames)
        self.num_envs, self.steps = num_envs, np.zeros(num_envs, int)
        self.episode = np.zeros(num_envs, int)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        pass

    def reset(self):
        return np.zeros((self.num_envs, 84, 84, 4), np.uint8), {}

    def step(self, actions):
        assert np.asarray(actions).shape == (self.num_envs,)
        i = np.arange(self.num_envs)
        self.steps += 1
        done = self.steps == 2 + 3 * i
        truncated = done & (((i == 1) & (self.episode == 1)) | ((i == 2) & (self.episode == 0)))
        terminated = done & ~((i == 1) & (self.episode == 1))
        info = dict(episode_return=np.where(done, 10.0 * i + self.episode, 0.0),
                    episode_length=np.where(done, self.steps, 0))
        self.episode, self.steps = self.episode + done, np.where(done, 0, self.steps)
        return self.reset()[0], np.zeros(self.num_envs), terminated, truncated, info


def test_evaluation_plays_each_envs_first_episodes_and_reports_their_mean_and_std(monkeypatch):
    """On scripted envs: env i plays its first quota[i] episodes (not the first episodes to
    end, which favours short ones), std_return is the std over the episodes with ddof = 0, an
    episode counts as cut off only when the cap ended it, the env is made on the evaluation
    seed (training seed + 10000), and the policy acts with keys from agent_key(eval seed)."""
    made, keys = [], []

    def make(*args, **kwargs):
        made.append(ScriptedEvalEnv(*args, **kwargs))
        return made[-1]

    def random_policy(num_actions):
        assert num_actions == 4

        def policy(obs, key):
            keys.append(np.asarray(key))
            return np.zeros(obs.shape[0], np.int32)
        return policy

    monkeypatch.setattr(stori_jax, "make", make)
    monkeypatch.setattr("stori_jax.suite.random_policy", random_policy)
    result = evaluate("Breakout", "2.1", policy="random", episodes=7, num_envs=3, seed=5,
                      max_episode_frames=1234, progress=False)
    assert made[0].made == dict(game="Breakout", preset="2.1", num_envs=3, seed=10_005,
                                obs="atari84", max_episode_frames=1234)
    assert list(episode_quotas(7, 3)) == [3, 2, 2]
    assert result["returns"] == [0.0, 1.0, 2.0, 10.0, 11.0, 20.0, 21.0]
    assert result["lengths"] == [2, 2, 2, 5, 5, 8, 8]
    returns = np.array(result["returns"])
    assert result["mean_return"] == pytest.approx(returns.sum() / 7)
    assert result["std_return"] == pytest.approx(
        np.sqrt(((returns - returns.mean()) ** 2).sum() / 7))  # ddof = 0
    assert result["truncated"] == 1
    assert (result["eval_seed"], result["train_seed"], result["agent_steps"]) == (10_005, 5, 48)
    key = stori_jax.agent_key(10_005)
    for used in keys:
        key, k = jax.random.split(key)
        np.testing.assert_array_equal(used, k)
    assert len(keys) == 16
    # fewer episodes than envs: only as many envs as episodes are made (the rest would play
    # no counted episode)
    result = evaluate("Breakout", "2.1", policy="random", episodes=2, num_envs=3, seed=5,
                      max_episode_frames=1234, progress=False)
    assert made[-1].made["num_envs"] == result["num_envs"] == 2


def test_the_random_baseline_policy_is_uniform_over_the_games_actions():
    from stori_jax.suite import random_policy

    for num_actions in (4, 18):
        policy = random_policy(num_actions)
        obs = jnp.zeros((20_000, 1), jnp.uint8)
        counts = np.bincount(np.asarray(policy(obs, jax.random.PRNGKey(0))),
                             minlength=num_actions)
        assert len(counts) == num_actions
        expected = 20_000 / num_actions
        # chi-square with num_actions - 1 degrees of freedom, far below any p < 1e-6 bound
        assert ((counts - expected) ** 2 / expected).sum() < 3 * num_actions + 30, counts


def test_greedy_acts_by_the_argmax_and_sampled_draws_from_the_policy(uninterrupted):
    full, _ = uninterrupted
    config, greedy = ppo.load_policy(full / "checkpoint.pkl", "greedy")
    _, sampled = ppo.load_policy(full / "checkpoint.pkl", "sampled")
    network = ppo.make_network(config, 4)
    params = ppo.load_checkpoint(full / "checkpoint.pkl")["params"]
    obs = jnp.asarray(random_frames(16))
    logits, _ = jax.jit(network.apply)(params, obs)
    draws = []
    for key in jax.random.split(jax.random.PRNGKey(1), 8):
        np.testing.assert_array_equal(greedy(obs, key), np.argmax(logits, axis=-1))
        draws.append(np.asarray(sampled(obs, key)))
        np.testing.assert_array_equal(draws[-1], jax.random.categorical(key, logits))
    assert len({d.tobytes() for d in draws}) > 1, "sampled actions depend on the key"


# -- the table --------------------------------------------------------------------------------

def fake_training_run(root, preset, seed, returns, last_step=None):
    """A Breakout PPO run folder: its config and one episode per return, every 100 steps (and a
    log whose last global_step is ``last_step``)."""
    run = root / f"Breakout-{preset}" / f"ppo-seed{seed}"
    run.mkdir(parents=True)
    (run / "config.json").write_text(json.dumps(dict(game="Breakout", preset=preset, seed=seed)))
    (run / "episodes.csv").write_text("global_step,env,return,length\n" + "".join(
        f"{100 * (k + 1)},0,{r},5\n" for k, r in enumerate(returns)))
    if last_step is not None:
        (run / "log.csv").write_text(f"iteration,global_step\n1,{last_step}\n")


def fake_eval(root, game, preset, agent, seed, mean, policy=None):
    policy = policy or ("random" if agent == "random" else "sampled")
    write_result(dict(game=game, preset=preset, agent=agent, policy=policy, train_seed=seed,
                      mean_return=mean, episodes=100), root / f"{game}-{preset}" /
                 f"{agent}-seed{seed}")


def test_the_table_notes_evaluations_cut_off_at_the_frame_cap(tmp_path, capsys):
    """An evaluation whose episodes were cut off at max_episode_frames, pooled with one under
    the usual cap, made a row of the table without a word (in table.md, table.json or on
    stderr)."""
    for seed, cap, cut in ((0, 108_000, 0), (7, 400, 4)):
        write_result(dict(game="Breakout", preset="3.1", agent="ppo", policy="sampled",
                          train_seed=seed, mean_return=1.0, episodes=4, max_episode_frames=cap,
                          truncated=cut), tmp_path / f"ppo-seed{seed}")
    fake_eval(tmp_path, "Breakout", "3.1", "random", 0, 1.0)  # recorded before caps were
    text, _ = build_table(tmp_path, tmp_path / "out")
    notes = ["Breakout 3.1 PPO seed(s) [0, 7]: how far the evaluated checkpoints had trained "
             "is not recorded",
             "Breakout 3.1 PPO seed 7: 4 of 4 episodes cut off at max_episode_frames 400 "
             "(their returns stop there)",
             "Breakout 3.1: the evaluations ran under different frame caps (max_episode_frames "
             "400, 108000)"]
    err = capsys.readouterr().err
    table = json.loads((tmp_path / "out" / "table.json").read_text())
    assert table["notes"] == notes
    assert table["rows"][0]["PPO"]["truncated"] == [0, 4]
    assert table["rows"][0]["Random"]["max_episode_frames"] == [None]
    written = (tmp_path / "out" / "table.md").read_text()
    assert written == f"{text}\n{STD_OVER_SEEDS}\n" + "".join(f"\n- {note}" for note in notes) \
        + "\n"
    for note in notes:
        assert f"note: {note}" in err and note not in text  # printed once by stori-jax table
    write_result(dict(game="Breakout", preset="3.1", agent="ppo", policy="sampled",
                      train_seed=13, mean_return=1.0, episodes=4, max_episode_frames="400"),
                 tmp_path / "ppo-seed13")
    with pytest.raises(ValueError, match="max_episode_frames must be an int >= 1, got '400'"):
        build_table(tmp_path, tmp_path / "out")


def test_the_table_notes_other_budgets_unfinished_runs_and_the_papers_other_environments(
        tmp_path):
    """A checkpoint of an unfinished run, or a run of another budget than the paper's 100k,
    stood in the table beside the paper's numbers without a word, and so did the paper's
    numbers of presets whose reference environment had a defect this project corrects. An
    older evaluation that did not record its training is read from its run's summary.json, or
    its config.json and log.csv; one that nothing explains is named."""
    def ppo_eval(preset, seed, **training):
        write_result(dict(game="Gopher", preset=preset, agent="ppo", policy="sampled",
                          train_seed=seed, mean_return=50.0, episodes=2, **training),
                     tmp_path / preset / f"ppo-seed{seed}")

    ppo_eval("2.1", 0, trained_agent_steps=100_352, run_total_steps=100_000, run_finished=True)
    ppo_eval("2.1", 7, trained_agent_steps=1_024, run_total_steps=12_288, run_finished=False)
    ppo_eval("2.1", 13)  # a finished run of 1M steps, recorded before evaluations said
    (tmp_path / "2.1" / "ppo-seed13" / "summary.json").write_text(json.dumps(dict(
        config=dict(total_steps=1_000_000), agent_steps=1_001_472, finished=True)))
    ppo_eval("3.1", 0)  # an unfinished run's older evaluation: its config and log say
    run = tmp_path / "3.1" / "ppo-seed0"
    (run / "config.json").write_text(json.dumps(dict(game="Gopher", preset="3.1", seed=0,
                                                     num_envs=2, num_steps=8, total_steps=48)))
    (run / "log.csv").write_text("iteration,global_step\n1,16\n2,32\n")
    ppo_eval("3.1", 7, trained_agent_steps="all", run_total_steps=48, run_finished=True)
    fake_eval(tmp_path, "BankHeist", "2.1", "random", 0, 1.0)  # the paper's numbers: a note
    build_table(tmp_path, tmp_path / "out")
    table = json.loads((tmp_path / "out" / "table.json").read_text())
    assert table["notes"] == [
        "Gopher 2.1: the paper's numbers come from another environment: the reference's "
        "'hole stays open' rule mostly undid the gopher's digging (docs/spec.md section 7, the "
        "likely cause of DreamerV3's 11333); here it undoes only the farmer's fills",
        "BankHeist 2.1: the paper's numbers come from another environment: the reference's "
        "city switch dropped the player back to an early level; here the level is kept "
        "(docs/spec.md section 8)",
        "Gopher 2.1 PPO: checkpoints of unfinished runs (seed 7: 1024 of 12288 agent steps)",
        "Gopher 2.1 PPO seed(s) [7]: runs of 12288 agent steps (the paper's: 100000)",
        "Gopher 2.1 PPO seed(s) [13]: runs of 1000000 agent steps (the paper's: 100000)",
        "Gopher 3.1 PPO seed(s) [7]: how far the evaluated checkpoints had trained is not "
        "recorded",  # not a count of steps
        "Gopher 3.1 PPO: checkpoints of unfinished runs (seed 0: 32 of 48 agent steps)",
        "Gopher 3.1 PPO seed(s) [0]: runs of 48 agent steps (the paper's: 100000)"]
    rows = {(r["game"], r["preset"]): r for r in table["rows"]}
    assert rows["Gopher", "2.1"]["PPO"]["training"][2] == dict(
        trained_agent_steps=1_001_472, run_total_steps=1_000_000, run_finished=True)


def test_the_table_joins_a_preset_spelt_in_lower_case_to_its_row(tmp_path):
    for seed, preset in ((0, "3.2C"), (7, "3.2c")):
        fake_eval(tmp_path, "Breakout", preset, "ppo", seed, 2.0 * seed)
    text, _ = build_table(tmp_path, tmp_path / "out")
    assert [line.split(" | ")[:3] for line in text.splitlines()[2:]] == [
        ["| Breakout", "3.2C", "7.00 ± 9.90"]]


def test_table_aggregates_seeds_beside_the_paper(tmp_path):
    for seed, mean in ((0, 1.0), (7, 2.0), (13, 3.0)):
        fake_eval(tmp_path, "Breakout", "3.1", "ppo", seed, mean)
        fake_eval(tmp_path, "Breakout", "3.1", "ppo", seed, 100.0, policy="greedy")
        fake_eval(tmp_path, "Breakout", "3.1", "random", seed, 1.5)
    fake_eval(tmp_path, "Boxing", "1", "ppo", 0, -4.0)
    run = tmp_path / "Breakout-3.1" / "ppo-seed0"
    (run / "config.json").write_text(json.dumps(dict(game="Breakout", preset="3.1", seed=0)))
    (run / "episodes.csv").write_text("global_step,env,return,length\n10,0,1.0,5\n20,1,3.0,9\n")
    text, paths = build_table(tmp_path, tmp_path / "out")
    lines = text.splitlines()
    assert lines[2].startswith("| Breakout | 3.1 | 2.00 ± 1.00 | 1.50 ± 0.00 | 60.71 ± 41.89 | "
                               "24.17 ± 3.55 | 0, 7, 13 | 100 |")
    assert lines[3].startswith("| Boxing | 1 | -4.00 (1 seed) | - | 39.32 ± 6.79 |")
    greedy = build_table(tmp_path, tmp_path / "g", ppo_policy="greedy")[0]
    assert "| 100.00 ± 0.00 |" in greedy and "| PPO greedy (ours) |" in greedy
    assert "| PPO (ours) |" in text
    assert (tmp_path / "out" / "curves-Breakout.png").stat().st_size > 1000
    assert json.loads((tmp_path / "out" / "table.json").read_text())["rows"][0]["PPO"][
        "per_seed"] == [1.0, 2.0, 3.0]
    assert len(PAPER_RESULTS) == 24


def test_paper_results_are_the_spec_table():
    """docs/spec.md section 11, typed in from it (every row, DreamerV3 mean ± std and STORM
    mean ± std), against the table the results are printed beside."""
    spec = """
        Breakout 1 8.67 0.30 9.20 1.72
        Breakout 2.1 13.80 3.26 16.44 2.03
        Breakout 2.2 14.86 1.74 20.45 2.92
        Breakout 3.1 60.71 41.89 24.17 3.55
        Breakout 3.2A 10.65 0.41 12.05 0.89
        Breakout 3.2B 3.57 1.43 6.48 2.50
        Breakout 3.2C 1.89 0.49 3.96 1.42
        Boxing 1 39.32 6.79 29.48 15.41
        Boxing 2.1 43.00 31.98 54.69 20.44
        Boxing 2.2 42.21 35.54 22.44 3.54
        Boxing 3.1 84.22 1.68 86.18 11.29
        Boxing 3.2A 86.90 1.33 85.22 11.77
        Boxing 3.2B 61.74 17.71 45.41 26.56
        Boxing 3.2C 56.52 18.45 52.66 25.68
        Gopher 1 1137.00 56.98 1303.53 724.76
        Gopher 2.1 11333.53 14761.12 950.67 188.37
        Gopher 2.2 2190.87 407.24 2315.40 893.32
        Gopher 3.1 3235.27 443.51 3811.67 2431.85
        Gopher 3.2 1521.13 451.45 936.40 106.83
        BankHeist 1 197.63 20.76 128.03 31.41
        BankHeist 2.1 663.60 587.85 467.80 507.74
        BankHeist 2.2 682.67 476.90 267.70 295.86
        BankHeist 3.1 562.30 320.74 1015.73 148.43
        BankHeist 3.2 849.80 514.15 43.10 22.85
    """
    expected = {}
    for line in spec.strip().splitlines():
        game, preset, *numbers = line.split()
        expected[(game, preset)] = tuple(float(x) for x in numbers)
    assert len(expected) == 24
    assert PAPER_RESULTS == expected


def test_table_errors(tmp_path):
    with pytest.raises(ValueError, match="no eval"):
        load_evaluations(tmp_path)
    fake_eval(tmp_path, "Breakout", "3.1", "ppo", 0, 1.0)
    fake_eval(tmp_path / "copy", "Breakout", "3.1", "ppo", 0, 2.0)
    with pytest.raises(ValueError, match="two PPO evaluations"):
        aggregate(load_evaluations(tmp_path))
    with pytest.raises(ValueError, match=r"no PPO evaluation with policy 'greedy': the PPO "
                                         r"evaluations here are \['sampled'\]"):
        aggregate(load_evaluations(tmp_path), ppo_policy="greedy")
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "eval-x.json").write_text("{}")
    with pytest.raises(ValueError, match="lacks"):
        load_evaluations(tmp_path)
    fake_eval(tmp_path / "pong", "Pong", "zzz", "random", 0, 1.0)
    with pytest.raises(ValueError, match="pong/Pong-zzz/random-seed0/eval-random.json: unknown "
                                         "game 'Pong' for presets"):
        load_evaluations(tmp_path / "pong")


@pytest.mark.parametrize("config_edit, episodes, message", [
    (dict(seed=[1]), None, r"config\.json: seed must be an int in \[0, 2147483647\], got \[1\]"),
    (dict(seed="x"), None, r"config\.json: seed must be an int"),
    (dict(seed=-4), None, r"config\.json: seed must be in \[0, 2147483647\], got -4"),
    (dict(preset="9.9"), None, r"config\.json: unknown preset '9\.9'"),
    ({}, b"", r"episodes\.csv lacks the columns \['global_step', 'return'\]"),
    ({}, b"global_step,return\n\xff\xfe,1\n", r"episodes\.csv is not a training run's "
                                                r"episodes\.csv: 'utf-8' codec"),
])
def test_the_curves_name_the_file_a_bad_training_run_has(tmp_path, config_edit, episodes,
                                                          message):
    """A config.json seed of [1] was a bare TypeError (unhashable) and "x" or -4 were taken;
    an empty episodes.csv was "I/O operation on closed file" and a non-UTF-8 one named no
    file."""
    run = tmp_path / "Breakout-3.1" / "ppo-seed0"
    run.mkdir(parents=True)
    (run / "config.json").write_text(json.dumps(dict(dict(game="Breakout", preset="3.1", seed=0),
                                                     **config_edit)))
    (run / "episodes.csv").write_bytes(b"global_step,env,return,length\n64,0,1.0,5\n"
                                       if episodes is None else episodes)
    with pytest.raises(ValueError, match=message):
        learning_curves(tmp_path)


def test_two_training_runs_of_one_seed_are_refused_as_two_evaluations_are(tmp_path):
    """A second run of a (game, preset, seed), an aborted one without an evaluation, was drawn
    as a second "seed 0" line and pooled into the mean over seeds, without a note."""
    for where, mean in (("final", 10.0), ("aborted", 0.0)):
        run = tmp_path / where / "ppo-seed0"
        run.mkdir(parents=True)
        (run / "config.json").write_text(json.dumps(dict(game="Breakout", preset="3.1", seed=0)))
        (run / "episodes.csv").write_text(f"global_step,env,return,length\n64,0,{mean},5\n")
    fake_eval(tmp_path / "final", "Breakout", "3.1", "ppo", 0, 10.0)
    with pytest.raises(ValueError, match=r"two training runs of Breakout 3\.1 seed 0: .*aborted"
                                         r"/ppo-seed0 and .*final/ppo-seed0"):
        build_table(tmp_path, tmp_path / "out")
    assert not (tmp_path / "out").exists()  # refused before anything is written
    shutil.rmtree(tmp_path / "aborted")
    text, _ = build_table(tmp_path, tmp_path / "out")
    written = (tmp_path / "out" / "table.md").read_text()
    assert written.startswith(f"{text}\n{STD_OVER_SEEDS}\n\n- ") and "ddof = 1" in STD_OVER_SEEDS
    assert json.loads((tmp_path / "out" / "table.json").read_text())["std"] == STD_OVER_SEEDS


def test_table_joins_spellings_and_names_differing_seed_sets(tmp_path):
    fake_eval(tmp_path, "Breakout", "3.1", "ppo", 0, 1.0)
    fake_eval(tmp_path, "breakout", "3.1", "random", 0, 2.0)
    fake_eval(tmp_path, "Breakout", "3.1", "random", 7, 3.0)
    text = markdown(aggregate(load_evaluations(tmp_path)))
    assert text.splitlines()[2] == ("| Breakout | 3.1 | 1.00 (1 seed) | 2.50 ± 0.71 | 60.71 ± 41.89 "
                                    "| 24.17 ± 3.55 | 0; Random: 0, 7 | 100 |")
    fake_eval(tmp_path, "Boxing", "1", "random", 13, 0.5)
    text = markdown(aggregate(load_evaluations(tmp_path)))
    assert text.splitlines()[3].endswith("| Random: 13 | 100 |")


def test_smoothing_is_the_mean_of_the_latest_episodes():
    out = smoothed(np.array([1, 2, 3]), np.array([1.0, 2.0, 6.0]), np.array([0, 2, 3]), 2)
    assert np.isnan(out[0]) and out[1] == 1.5 and out[2] == 4.0


def test_curves_stop_where_a_run_stopped_and_the_table_names_what_it_leaves_out(tmp_path,
                                                                                 capsys):
    """A short run's curve was drawn flat to the longest run's end (and pulled the mean
    down); training runs without an evaluation were in the curves but silently not in the
    table; runs of different hyperparameters were pooled without a word."""
    for seed, last, lr in ((0, 1000, 2.5e-4), (1, 8000, 1e-3)):
        run = tmp_path / "Breakout-2.1" / f"ppo-seed{seed}"
        run.mkdir(parents=True)
        (run / "config.json").write_text(json.dumps(dict(game="Breakout", preset="2.1",
                                                         seed=seed, learning_rate=lr)))
        (run / "episodes.csv").write_text(f"global_step,env,return,length\n500,0,1.0,5\n"
                                          f"{last - 100},1,3.0,9\n")
        (run / "log.csv").write_text(f"iteration,global_step\n1,{last}\n")
    fake_eval(tmp_path, "Breakout", "2.1", "ppo", 1, 2.0)
    fake_eval(tmp_path / "greedy", "Breakout", "2.1", "ppo", 0, 2.0, policy="greedy")
    build_table(tmp_path, tmp_path / "out")
    err = capsys.readouterr().err
    # seed 0's greedy evaluation is not in the sampled table: the run is still left out
    assert "Breakout 2.1: seed(s) [0] have no eval-sampled.json: in the curves, not in the " \
        "table" in err
    assert "Breakout 2.1: the runs pooled in the curves (and, where evaluated, in the table's " \
        "mean) differ in learning_rate" in err
    # a config.json written before a field existed is that field's default, not another config
    for seed in (2, 3):
        run = tmp_path / "Boxing-3.1" / f"ppo-seed{seed}"
        run.mkdir(parents=True)
        recorded = dataclasses.asdict(ppo.PPOConfig(game="Boxing", seed=seed))
        if seed == 2:
            del recorded["action_head"], recorded["augment_shift"]
        (run / "config.json").write_text(json.dumps(recorded))
        (run / "episodes.csv").write_text("global_step,env,return,length\n64,0,1.0,5\n")
        fake_eval(tmp_path, "Boxing", "3.1", "ppo", seed, 1.0)
    build_table(tmp_path, tmp_path / "out")
    assert "Boxing 3.1: the runs pooled" not in capsys.readouterr().err
    short = next(run for run in learning_curves(tmp_path)[("Breakout", "2.1", "ppo")]
                 if run[2] == 0)
    steps, returns, _, end, _ = short
    assert end == 1000  # the log's last step, past the last episode's
    line = smoothed(steps, returns, np.array([600.0, 1000.0, 5000.0]), 20, end)
    assert line[0] == 1.0 and line[1] == 2.0 and np.isnan(line[2])


PAPER_LAYOUT = [("Breakout", p) for p in ("1", "2.1", "2.2", "3.1", "3.2A", "3.2B", "3.2C")] + [
    ("Boxing", p) for p in ("1", "2.1", "2.2", "3.1", "3.2A", "3.2B", "3.2C")] + [
    (game, p) for game in ("Gopher", "BankHeist") for p in ("1", "2.1", "2.2", "3.1", "3.2")]


def test_the_table_rows_follow_the_papers_layout(tmp_path):
    """docs/spec.md section 11's row order: Breakout, Boxing, Gopher, BankHeist, each from type 1
    to 3.2, whatever order the evaluations are found in."""
    for i, (game, preset) in enumerate(reversed(PAPER_LAYOUT)):
        fake_eval(tmp_path / f"{i:02d}", game, preset, "ppo", 0, float(i))
    rows = aggregate(load_evaluations(tmp_path))
    assert [(r["game"], r["preset"]) for r in rows] == PAPER_LAYOUT
    assert [line.split(" | ")[:2] for line in markdown(rows).splitlines()[2:]] == [
        [f"| {game}", preset] for game, preset in PAPER_LAYOUT]


def test_the_curves_show_each_seed_their_mean_and_the_random_policys_mean(tmp_path,
                                                                         monkeypatch):
    """One panel per preset in the paper's order; in each, every seed's smoothed curve, their
    mean, and the random policy's evaluation mean (over its seeds) as a dashed line."""
    import matplotlib.pyplot as plt

    from baselines.table import plot_curves

    for preset, seed, returns in (("3.1", 0, (1.0, 3.0)), ("3.1", 7, (5.0, 7.0)),
                                  ("1", 0, (2.0, 2.0))):
        fake_training_run(tmp_path, preset, seed, returns)
    for seed, mean in ((0, 1.0), (7, 4.0)):
        fake_eval(tmp_path, "Breakout", "3.1", "random", seed, mean)
    figures, close = [], plt.close
    monkeypatch.setattr(plt, "close", figures.append)  # keep the figure to look at
    evaluations = load_evaluations(tmp_path)
    paths = plot_curves(learning_curves(tmp_path), evaluations, tmp_path / "out", window=20)
    assert [p.name for p in paths] == ["curves-Breakout.png"] and len(figures) == 1
    panels = figures[0].axes
    assert [ax.get_title() for ax in panels] == ["Breakout 1", "Breakout 3.1"]
    lines = {line.get_label(): np.asarray(line.get_ydata(), float) for line in panels[1].lines}
    assert set(lines) == {"seed 0", "seed 7", "mean over seeds", "random policy (eval)"}
    np.testing.assert_allclose(lines["mean over seeds"], (lines["seed 0"] + lines["seed 7"]) / 2)
    assert np.nanmax(lines["mean over seeds"]) == 4.0  # the latest episodes' mean, (2 + 6) / 2
    np.testing.assert_array_equal(lines["random policy (eval)"], [2.5, 2.5])
    dashed = [line for line in panels[1].lines if line.get_label() == "random policy (eval)"]
    assert dashed[0].get_linestyle() == "--"
    assert "random policy (eval)" not in [line.get_label() for line in panels[0].lines]
    close(figures[0])


def test_the_curves_legend_names_every_line_of_every_panel_in_one_colour_per_seed(tmp_path,
                                                                                   monkeypatch):
    """The legend was the last panel's: a random-policy line or a seed only in another panel was
    missing from it, and a seed's colour depended on its place in each panel. A seed without a
    finished episode empties the mean over seeds: the panel says so, and keeps its axis."""
    import matplotlib.pyplot as plt

    from baselines.table import plot_curves

    for preset, seed, returns in (("1", 13, (1.0, 3.0)), ("3.1", 0, (5.0,)), ("3.1", 13, ())):
        fake_training_run(tmp_path, preset, seed, returns, last_step=400)
    fake_eval(tmp_path, "Breakout", "1", "random", 0, 1.0)  # the first panel only
    figures, close = [], plt.close
    monkeypatch.setattr(plt, "close", figures.append)
    plot_curves(learning_curves(tmp_path), load_evaluations(tmp_path), tmp_path / "out")
    first, last = figures[0].axes
    assert [t.get_text() for t in last.get_legend().get_texts()] == [
        "seed 0", "seed 13", "mean over seeds", "random policy (eval)"]
    colour = {(ax.get_title(), line.get_label()): line.get_color()
              for ax in (first, last) for line in ax.lines}
    assert colour[("Breakout 1", "seed 13")] == colour[("Breakout 3.1", "seed 13")] != colour[
        ("Breakout 3.1", "seed 0")]
    assert [t.get_text() for t in last.texts] == ["seed(s) [13]: no finished episode,\nso no mean"]
    assert len(first.texts) == 0 and last.get_xlim() == (0, 400)
    close(figures[0])


# -- the command line -------------------------------------------------------------------------

@pytest.mark.parametrize("argv,match", [
    (["train", "ppo", "--game", "Pong2"], "unknown game"),
    (["train", "ppo", "--game", "Pong"], "game must be one of the STORI games ['Breakout', "),
    (["eval", "--random", "--game", "pong", "--preset", "3.1"], "the baselines play the paper"),
    (["eval", "--random", "--game", "Pong", "--preset", "3.1"], "--game must be one of the STORI"),
    (["eval", "--random", "--game", "Pong2", "--preset", "3.1"], "--game: unknown game 'Pong2'"),
    (["eval", "--random", "--game", "Breakout", "--preset", "3.1", "--num-envs", "1000000000",
      "--episodes", "100000000"],  # one env per episode: --episodes is the batch's size
     "--episodes 100000000 with frame_skip=4 needs"),
    (["train", "ppo", "--game", "Breakout", "--preset", "4"], "preset"),
    (["train", "ppo", "--game", "Breakout", "--steps", "1000000000000"],  # optax: OverflowError
     "--steps is too large for anneal_lr: 976562500 iterations x 16 updates each"),
    # checked on the config asked for, not on one with the default --steps (the --out check
    # after it is what refuses this run)
    (["train", "ppo", "--game", "Breakout", "--steps", "2", "--set", "num_envs=2", "--set",
      "num_steps=1", "--set", "num_minibatches=1", "--set", "update_epochs=50000", "--out",
      "/dev/null"], "--out /dev/null exists and is not a directory"),
    (["train", "ppo", "--game", "Breakout", "--set", "lr"], "FIELD=VALUE"),
    (["train", "ppo", "--game", "Breakout", "--set", "nope=1"],
     "unknown PPO hyperparameter 'nope'; --set takes ['action_head', "),
    (["train", "ppo", "--game", "Breakout", "--set", "seed=3"], "--seed"),
    (["train", "ppo", "--game", "Breakout", "--set", "total_steps=64"],
     "set total_steps with --steps, not --set"),
    (["train", "ppo", "--game", "Breakout", "--set", "preset=1"],
     "set preset with --preset, not --set"),
    (["train", "ppo", "--game", "Breakout", "--steps", "0"], "--steps must be >= 1"),
    (["eval"], "--checkpoint PATH or --random"),
    (["eval", "--random", "--game", "Breakout"], "--game and --preset"),
    (["eval", "--checkpoint", "/nonexistent.pkl"], "does not exist"),
    (["eval", "--random", "--game", "Breakout", "--preset", "3.1", "--episodes", "0"],
     "--episodes must be >= 1, got 0"),
    (["eval", "--random", "--game", "Breakout", "--preset", "3.1", "--max-episode-frames",
      "2147483648"], "--max-episode-frames must be in [1, 2147483647], got 2147483648"),
    (["table", "/nonexistent"], "not a directory"),
])
def test_cli_errors_are_clear(argv, match, capsys):
    assert main(argv) == 2
    assert match in capsys.readouterr().err


@pytest.mark.parametrize("argv, match", [
    (["--seeds", "5"], "invalid choice: 5"),
    (["--only", "Pong-3.1"], "unknown runs ['Pong-3.1']"),
])
def test_run_evidence_names_bad_runs_and_seeds(argv, match, monkeypatch, capsys):
    from baselines.evidence import run_evidence

    monkeypatch.setattr("sys.argv", ["run_evidence.py", "--stage", "table", *argv])
    with pytest.raises(SystemExit) as exit_info:
        run_evidence.main()
    assert exit_info.value.code == 2 and match in capsys.readouterr().err


def test_a_finished_run_without_its_checkpoint_is_not_trained_over(uninterrupted, tmp_path,
                                                                     capsys):
    """Committed runs have no checkpoint.pkl: a fresh run in their directory would start again
    over their files and leave their evaluation beside the new run's curve; a run stopped
    before its first checkpoint (no summary yet) is simply started again."""
    import shutil

    full, _ = uninterrupted
    before = {p.name: p.read_bytes() for p in full.iterdir()}
    with pytest.raises(ValueError, match="already holds a run: resume it"):
        ppo.train(tiny(), full, progress=False)  # from Python too, not started over
    assert {p.name: p.read_bytes() for p in full.iterdir()} == before
    committed = tmp_path / "committed"
    shutil.copytree(full, committed, ignore=shutil.ignore_patterns("checkpoint.pkl"))
    (committed / "eval-sampled.json").write_text("{}")
    before = {p.name: p.read_bytes() for p in committed.iterdir()}
    assert main(["train", "ppo", "--game", "Breakout", "--out", str(committed), "--quiet",
                 "--eval-episodes", "1", "--force"]) == 2
    assert ("holds a finished run (summary.json, eval-sampled.json) without its checkpoint.pkl"
            in capsys.readouterr().err)
    assert main(["train", "ppo", "--game", "Breakout", "--out", str(committed), "--quiet",
                 "--resume"]) == 2  # not "run without --resume"
    assert (f"--resume: {committed} holds a finished run (summary.json, eval-sampled.json) "
            "without its checkpoint.pkl" in capsys.readouterr().err)
    (committed / "summary.json").unlink()
    with pytest.raises(ValueError, match=r"holds a finished run \(eval-sampled.json\)"):
        ppo.train(tiny(), committed, progress=False, stop_after=1)
    assert {p.name: p.read_bytes() for p in committed.iterdir()} == {
        name: data for name, data in before.items() if name != "summary.json"}
    (committed / "eval-sampled.json").unlink()  # now as a run stopped before its checkpoint
    ppo.train(tiny(), committed, progress=False, stop_after=1)
    assert (committed / "checkpoint.pkl").exists()


def test_cli_train_refuses_to_overwrite_and_evaluates(uninterrupted, tmp_path, capsys):
    full, _ = uninterrupted
    assert main(["train", "ppo", "--game", "Breakout", "--out", str(full), "--quiet"]) == 2
    assert "--resume" in capsys.readouterr().err
    assert main(["train", "ppo", "--game", "Breakout", "--out", str(tmp_path), "--resume",
                 "--quiet"]) == 2
    assert "holds no checkpoint.pkl" in capsys.readouterr().err
    assert main(["eval", "--checkpoint", str(full / "checkpoint.pkl"), "--episodes", "1",
                 "--policy", "greedy", "--num-envs", "1", "--out", str(tmp_path), "--quiet",
                 "--preset", "3.1", "--game", "breakout"]) == 2
    err = capsys.readouterr().err
    assert "--preset 3.1 differs from the checkpoint" in err  # not --game
    assert f"stori-jax suite --checkpoint {full / 'checkpoint.pkl'} --games Breakout --presets " \
        "3.1 plays its sampled policy on others" in err
    for flags, error in ((["--preset", "3.2c"], "--preset 3.2C differs from the checkpoint's 1"),
                         (["--preset", "9"], "--preset: unknown preset '9' for Breakout"),
                         (["--game", "Gopher", "--preset", "3.2A"],
                          "--game Gopher differs from the checkpoint's Breakout")):
        assert main(["eval", "--checkpoint", str(full / "checkpoint.pkl"), *flags, "--out",
                     str(tmp_path), "--quiet"]) == 2
        assert error in capsys.readouterr().err
    assert main(["eval", "--checkpoint", str(full / "checkpoint.pkl"), "--seed", "5",
                 "--out", str(tmp_path), "--quiet"]) == 2
    assert "--seed 5 differs from the checkpoint's 0 (to evaluate on other seeds, give " \
        "--eval-seed)" in capsys.readouterr().err
    # seed 10000's default eval seed, 20000, is a training env's: refused before training
    assert main(["train", "ppo", "--game", "Breakout", "--seed", "10000", "--eval-episodes", "1",
                 "--out", str(tmp_path / "s10000"), "--quiet"]) == 2
    assert "eval seed 20000 is one of the training envs' seeds [20000, 20001] (training seed " \
        "10000): the evaluation would replay training's episodes; train without " \
        "--eval-episodes" in capsys.readouterr().err
    assert not (tmp_path / "s10000" / "log.csv").exists()


def test_eval_counts_and_reports_episodes_cut_off_at_the_frame_cap(tmp_path, capsys):
    """A greedy Breakout policy that never fires played every episode to 108000 frames, and
    eval printed a mean of 0 with no word of it."""
    assert main(["eval", "--random", "--game", "Breakout", "--preset", "3.1", "--episodes", "2",
                 "--num-envs", "2", "--max-episode-frames", "40", "--out", str(tmp_path),
                 "--quiet"]) == 0
    result = json.loads((tmp_path / "eval-random.json").read_text())
    assert result["truncated"] == 2 and result["lengths"] == [10, 10]
    assert result["software"]["packages"]["ale-py"] == ale_py.__version__
    assert "note: 2 of 2 episodes were cut off at 40 frames (truncated; --max-episode-frames " \
        "sets the cap)" in capsys.readouterr().out
    assert main(["eval", "--random", "--game", "Breakout", "--preset", "3.1",
                 "--max-episode-frames", "0", "--out", str(tmp_path), "--quiet"]) == 2
    assert "--max-episode-frames must be" in capsys.readouterr().err


def test_cli_random_evaluation_spells_the_game_one_way_and_keeps_earlier_results(tmp_path,
                                                                                  capsys):
    assert main(["eval", "--random", "--game", "breakout", "--preset", "3.1", "--episodes", "1",
                 "--num-envs", "1", "--out", str(tmp_path), "--quiet"]) == 0
    assert json.loads((tmp_path / "eval-random.json").read_text())["game"] == "Breakout"
    assert "(std over 1 episode, eval seed 10000)" in capsys.readouterr().out
    again = ["eval", "--random", "--game", "Breakout", "--preset", "3.1", "--episodes", "2",
             "--num-envs", "1", "--out", str(tmp_path), "--quiet"]
    assert main(again) == 2  # an earlier evaluation is not replaced by accident
    assert "eval-random.json already holds an evaluation: pass --force" in capsys.readouterr().err
    assert json.loads((tmp_path / "eval-random.json").read_text())["episodes"] == 1
    assert main(again + ["--force"]) == 0
    assert json.loads((tmp_path / "eval-random.json").read_text())["episodes"] == 2
    assert main(["eval", "--random", "--game", "Breakout", "--preset", "3.1",
                 "--seed", str(2**31 - 10000), "--out", str(tmp_path / "other"), "--quiet"]) == 2
    assert "--seed + 10000 (the default --eval-seed) must be in [0, 2147483647]" \
        in capsys.readouterr().err


def test_suite_plays_a_checkpoint_on_its_games_presets(uninterrupted, tmp_path, capsys):
    full, _ = uninterrupted
    checkpoint = full / "checkpoint.pkl"
    assert main(["suite", "--checkpoint", str(checkpoint), "--presets", "3.1", "1",
                 "--episodes", "1", "--num-envs", "2", "--max-steps", "20", "--no-gallery",
                 "--quiet", "--out", str(tmp_path)]) == 0
    results = json.loads((tmp_path / "results.json").read_text())
    assert results["agent"] == str(checkpoint)
    assert [(r["game"], r["preset"]) for r in results["rows"]] == [("Breakout", "1"),
                                                                   ("Breakout", "3.1")]
    assert all(r["agent_steps"] == 20 for r in results["rows"])
    # on eval's seed, not on envs that replay training's draws (seed 0 trained on envs 0, 1)
    assert results["seed"] == 10_000
    capsys.readouterr()
    assert main(["suite", "--checkpoint", str(checkpoint), "--games", "Boxing", "--quiet",
                 "--no-gallery", "--out", str(tmp_path)]) == 2
    assert "plays Breakout only" in capsys.readouterr().err
    assert main(["suite", "--checkpoint", str(checkpoint), "--seed", "1", "--quiet",
                 "--no-gallery", "--out", str(tmp_path)]) == 2
    assert ("eval seed 1 is one of the training envs' seeds [0, 1] (training seed 0): the "
            "evaluation would replay training's episodes; choose another --seed (by default "
            "the training seed + 10000)") in capsys.readouterr().err


def test_cli_eval_passes_its_seeds_envs_and_default_policy_on(uninterrupted, tmp_path):
    """--seed files the random policy's result under that training seed, --eval-seed and
    --num-envs reach the evaluation, and a checkpoint acts `sampled` unless told otherwise."""
    assert main(["eval", "--random", "--game", "Breakout", "--preset", "3.1", "--seed", "3",
                 "--eval-seed", "123", "--num-envs", "2", "--episodes", "3",
                 "--max-episode-frames", "40", "--out", str(tmp_path / "random"),
                 "--quiet"]) == 0
    result = json.loads((tmp_path / "random" / "eval-random.json").read_text())
    assert (result["train_seed"], result["eval_seed"], result["num_envs"], result["episodes"],
            len(result["returns"])) == (3, 123, 2, 3, 3)
    full, _ = uninterrupted
    assert main(["eval", "--checkpoint", str(full / "checkpoint.pkl"), "--episodes", "1",
                 "--num-envs", "1", "--max-episode-frames", "40", "--out",
                 str(tmp_path / "ppo"), "--quiet"]) == 0
    assert [p.name for p in (tmp_path / "ppo").iterdir()] == ["eval-sampled.json"]
    result = json.loads((tmp_path / "ppo" / "eval-sampled.json").read_text())
    assert (result["policy"], result["eval_seed"], result["train_seed"]) == ("sampled", 10_000, 0)


def test_cli_eval_says_a_greedy_policy_on_a_preset_without_randomness_plays_one_episode(
        uninterrupted, tmp_path, capsys):
    full, _ = uninterrupted
    payload = read_checkpoint(full)
    payload["config"] = dict(payload["config"], preset="3.1")  # the same network plays 3.1
    ppo.save_checkpoint(tmp_path / "3.1" / "checkpoint.pkl", payload)
    payload["config"] = dict(payload["config"], preset="3.2A")  # blackout at p = 1: no draw
    ppo.save_checkpoint(tmp_path / "3.2A" / "checkpoint.pkl", payload)
    for checkpoint, noted in ((full / "checkpoint.pkl", False),
                              (tmp_path / "3.1" / "checkpoint.pkl", True),
                              (tmp_path / "3.2A" / "checkpoint.pkl", True)):
        assert main(["eval", "--checkpoint", str(checkpoint), "--policy", "greedy",
                     "--episodes", "1", "--num-envs", "1", "--max-episode-frames", "40",
                     "--out", str(tmp_path / "out" / checkpoint.parent.name), "--quiet"]) == 0
        out = capsys.readouterr().out
        assert ("has no randomness once the policy is greedy" in out) == noted, out


def test_cli_train_says_where_a_resumed_run_started_and_leaves_no_empty_folder(
        tmp_path, monkeypatch, capsys):
    """After --resume, train printed the whole run's steps as if this command had trained them
    all; a Ctrl-C before anything was written left the new run folder behind, empty."""
    def resumed(config, out, resume, progress):
        return dict(iterations_now=2, agent_steps=3 * config.batch_size, train_seconds=9.0,
                    train_sps=1.0, agent_steps_now=2 * config.batch_size)

    monkeypatch.setattr(ppo, "AGENT", dataclasses.replace(ppo.AGENT, train=resumed))
    args = ["train", "ppo", "--game", "Breakout", "--set", "num_envs=2", "--set",
            "num_steps=8", "--steps", "48", "--quiet"]
    (tmp_path / "run" / "checkpoint.pkl").parent.mkdir()
    (tmp_path / "run" / "checkpoint.pkl").write_bytes(b"")
    assert main([*args, "--out", str(tmp_path / "run"), "--resume"]) == 0
    assert "resumed at agent step 16, trained 32; the run: 48 agent steps in 9 s" in \
        capsys.readouterr().out

    def interrupted(config, out, resume, progress):
        out.mkdir(parents=True)
        raise KeyboardInterrupt

    monkeypatch.setattr(ppo, "AGENT", dataclasses.replace(ppo.AGENT, train=interrupted))
    assert main([*args, "--out", str(tmp_path / "new" / "run")]) == 130  # Ctrl-C's exit code
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_cli_train_evaluates_the_sampled_policy_of_its_checkpoint(tmp_path, monkeypatch,
                                                                    capsys):
    """--eval-episodes N: after training, N episodes of the run's checkpoint acting `sampled`
    on its preset, filed under its training seed (the default evaluation seeds)."""
    import baselines.evaluate

    calls = []

    def train(config, out, resume, progress):
        return dict(iterations_now=1, agent_steps=config.total_steps, train_seconds=1.0,
                    train_sps=1.0, agent_steps_now=config.total_steps)

    def evaluate(game, preset, **kwargs):
        calls.append(dict(kwargs, game=game, preset=preset))
        return dict(game=game, preset=preset, agent="ppo", policy=kwargs["policy"],
                    mean_return=1.0, std_return=0.5, truncated=0, episodes=kwargs["episodes"],
                    eval_seed=10_004)

    monkeypatch.setattr(ppo, "AGENT", dataclasses.replace(ppo.AGENT, train=train))
    monkeypatch.setattr(baselines.evaluate, "evaluate", evaluate)
    assert main(["train", "ppo", "--game", "boxing", "--preset", "3.2b", "--seed", "4",
                 "--steps", "64", "--eval-episodes", "3", "--out", str(tmp_path),
                 "--quiet"]) == 0
    assert calls == [dict(game="Boxing", preset="3.2B", policy="sampled", seed=4, episodes=3,
                          checkpoint=tmp_path / "checkpoint.pkl", progress=False)]
    assert json.loads((tmp_path / "eval-sampled.json").read_text())["policy"] == "sampled"
    assert "eval: Boxing 3.2B sampled: mean return 1.00 ± 0.50 (std over 3 episodes, eval " \
        "seed 10004); wrote" in capsys.readouterr().out  # as `eval` prints it
    # a second evaluation replaces the first only with --force, and that is known before training
    (tmp_path / "checkpoint.pkl").write_bytes(b"")  # a run to --resume
    again = ["train", "ppo", "--game", "boxing", "--preset", "3.2b", "--seed", "4", "--steps",
             "64", "--eval-episodes", "2", "--out", str(tmp_path), "--resume", "--quiet"]
    monkeypatch.setattr(ppo, "AGENT", dataclasses.replace(ppo.AGENT, train=lambda *a, **k: pytest.fail("trained before refusing")))
    assert main(again) == 2
    assert (f"{tmp_path / 'eval-sampled.json'} already holds an evaluation: pass --force to "
            "replace it, or train without --eval-episodes, then run stori-jax eval --checkpoint "
            f"{tmp_path}/checkpoint.pkl --out DIR") in capsys.readouterr().err
    assert json.loads((tmp_path / "eval-sampled.json").read_text())["episodes"] == 3
    monkeypatch.setattr(ppo, "AGENT", dataclasses.replace(ppo.AGENT, train=train))
    assert main(again + ["--force"]) == 0
    assert json.loads((tmp_path / "eval-sampled.json").read_text())["episodes"] == 2
    assert main(again[:-6] + ["--out", str(tmp_path), "--resume", "--force"]) == 2
    assert "--force replaces an evaluation: it needs --eval-episodes" in capsys.readouterr().err


def test_evaluate_asks_the_checkpoint_for_the_policy_it_was_given(uninterrupted, monkeypatch):
    """evaluate(policy="greedy") played the checkpoint's greedy policy only if it asked for it:
    policy_of's default is the sampled one."""
    full, _ = uninterrupted
    asked, real = [], ppo.policy_of

    def spy(ckpt, *args, **kwargs):
        asked.append(args[0] if args else kwargs.get("mode", "sampled"))
        return real(ckpt, *args, **kwargs)

    monkeypatch.setattr(ppo, "AGENT", dataclasses.replace(ppo.AGENT, policy_of=spy))
    for policy in ("greedy", "sampled"):
        result = evaluate("Breakout", "1", policy=policy, episodes=1, num_envs=1,
                          checkpoint=full / "checkpoint.pkl", max_episode_frames=40,
                          progress=False)
        assert result["policy"] == policy
    assert asked == ["greedy", "sampled"]


def test_overrides_read_1_and_0_as_true_and_false():
    config = ppo.PPOConfig.from_overrides(tiny(anneal_lr=False, clip_vloss=True),
                                          {"anneal_lr": "1", "clip_vloss": "0"})
    assert (config.anneal_lr, config.clip_vloss) == (True, False)
    config = ppo.PPOConfig.from_overrides(tiny(anneal_lr=False, clip_vloss=True),
                                          {"anneal_lr": "TRUE", "clip_vloss": "False"})
    assert (config.anneal_lr, config.clip_vloss) == (True, False)


def test_runs_that_differ_only_in_their_checkpoints_are_not_noted_as_differing(tmp_path):
    """checkpoint_every (like the seed) does not change the training: runs pooled in a panel
    that differ in it alone get no note; a hyperparameter that changes training does."""
    from baselines.table import table_notes

    for preset, seed, fields in (("3.1", 0, dict(checkpoint_every=1)),
                                 ("3.1", 7, dict(checkpoint_every=5)),
                                 ("1", 0, dict(learning_rate=1e-3)), ("1", 7, {})):
        fake_training_run(tmp_path, preset, seed, [1.0, 2.0])
        config = tmp_path / f"Breakout-{preset}" / f"ppo-seed{seed}" / "config.json"
        config.write_text(json.dumps(dict(json.loads(config.read_text()), **fields)))
        fake_eval(tmp_path, "Breakout", preset, "ppo", seed, 1.0)
    notes = table_notes(learning_curves(tmp_path), load_evaluations(tmp_path), "sampled")
    assert notes == ["Breakout 1: the runs pooled in the curves (and, where evaluated, in the "
                     "table's mean) differ in learning_rate"]


def test_cli_table_shows_the_policy_asked_for_and_writes_into_the_results_dir(tmp_path,
                                                                              capsys):
    """stori-jax table RESULTS_DIR --policy greedy: the greedy evaluations, in a column named
    so; without --out, table.md and table.json land in RESULTS_DIR itself."""
    for seed, mean in ((0, 1.0), (7, 3.0)):
        fake_eval(tmp_path, "Breakout", "3.1", "ppo", seed, mean)
        fake_eval(tmp_path, "Breakout", "3.1", "ppo", seed, 10.0 * mean, policy="greedy")
    assert main(["table", str(tmp_path), "--policy", "greedy"]) == 0
    out = capsys.readouterr().out
    assert "| PPO greedy (ours) |" in out and "| 20.00 ± 14.14 |" in out
    written = (tmp_path / "table.md").read_text()
    assert "| PPO greedy (ours) |" in written and "| 20.00 ± 14.14 |" in written
    assert json.loads((tmp_path / "table.json").read_text())["ppo_policy"] == "greedy"
    assert not (tmp_path / "table").exists()
    assert f"wrote {tmp_path / 'table.md'}, {tmp_path / 'table.json'}" in out


def test_cli_eval_of_a_checkpoints_greedy_policy_writes_eval_greedy_beside_it(
        uninterrupted, tmp_path, monkeypatch):
    """eval --checkpoint --policy greedy, without --out: eval-greedy.json, of the greedy
    policy, in the checkpoint's folder."""
    monkeypatch.chdir(tmp_path)  # nothing is written elsewhere
    full, _ = uninterrupted
    run = tmp_path / "run"
    run.mkdir()
    shutil.copy(full / "checkpoint.pkl", run / "checkpoint.pkl")
    assert main(["eval", "--checkpoint", str(run / "checkpoint.pkl"), "--policy", "greedy",
                 "--episodes", "1", "--num-envs", "1", "--max-episode-frames", "40",
                 "--quiet"]) == 0
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["checkpoint.pkl", "eval-greedy.json",
                                                            "run"]
    assert json.loads((run / "eval-greedy.json").read_text())["policy"] == "greedy"


def test_cli_default_run_folders_are_filed_under_the_seed(tmp_path, monkeypatch):
    """Without --out: train writes results/train/<game>-<preset>/ppo-seed<S>, eval --random
    results/train/<game>-<preset>/random-seed<S>, S the --seed given."""
    import baselines.evaluate

    monkeypatch.chdir(tmp_path)
    trained_into = []

    def train(config, out, resume, progress):
        trained_into.append(out)
        return dict(iterations_now=1, agent_steps=config.total_steps, train_seconds=1.0,
                    train_sps=1.0, agent_steps_now=config.total_steps)

    def evaluate(game, preset, **kwargs):
        return dict(game=game, preset=preset, agent="random", policy=kwargs["policy"],
                    train_seed=kwargs["seed"], mean_return=1.0, std_return=0.5, truncated=0,
                    episodes=kwargs["episodes"], eval_seed=10_007)

    monkeypatch.setattr(ppo, "AGENT", dataclasses.replace(ppo.AGENT, train=train))
    monkeypatch.setattr(baselines.evaluate, "evaluate", evaluate)
    assert main(["train", "ppo", "--game", "Breakout", "--seed", "7", "--set", "num_envs=2",
                 "--set", "num_steps=8", "--steps", "16", "--quiet"]) == 0
    assert trained_into == [Path("results/train/Breakout-3.1/ppo-seed7")]
    assert main(["eval", "--random", "--game", "Breakout", "--preset", "3.1", "--seed", "7",
                 "--episodes", "1", "--quiet"]) == 0
    written = tmp_path / "results" / "train" / "Breakout-3.1" / "random-seed7" / "eval-random.json"
    assert json.loads(written.read_text())["train_seed"] == 7
    assert [p for p in tmp_path.rglob("*") if p.is_file()] == [written]


def test_cli_train_says_when_steps_round_up_to_whole_iterations(tmp_path, monkeypatch, capsys):
    def train(config, out, resume, progress):
        return dict(iterations_now=config.num_iterations,
                    agent_steps=config.num_iterations * config.batch_size, train_seconds=1.0,
                    train_sps=1.0, agent_steps_now=config.num_iterations * config.batch_size)

    monkeypatch.setattr(ppo, "AGENT", dataclasses.replace(ppo.AGENT, train=train))
    args = ["train", "ppo", "--game", "Breakout", "--set", "num_envs=2", "--set", "num_steps=8",
            "--quiet"]
    assert main([*args, "--steps", "50", "--out", str(tmp_path / "a")]) == 0
    assert ("stori-jax: --steps 50 rounds up to 64 agent steps, whole iterations of 16 agent "
            "steps") in capsys.readouterr().err
    assert main([*args, "--steps", "48", "--out", str(tmp_path / "b")]) == 0
    assert "rounds up" not in capsys.readouterr().err
