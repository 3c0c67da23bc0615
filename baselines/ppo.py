"""PPO on a STORI preset, in one file (after CleanRL's ppo_atari and PureJaxRL).

Read top to bottom: hyperparameters, network, acting, rollouts (two half-batches stepped in turn,
so the agent chooses one half's actions while the other half's emulators run), advantages, the
jitted update, checkpoints, the training loop.

Deterministic: the same config on the same machine gives the same curve, bit for bit, and a run
resumed from a checkpoint continues exactly as if it had never stopped (the checkpoint holds the
emulators' states too).  Command line: ``stori-jax train ppo --game Breakout --preset 3.1``.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import NamedTuple

import ale_py
import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import optax

from baselines import runs
from baselines.agents import Agent
from baselines.evaluate import CHECKPOINT_POLICIES, stori_game
from baselines.networks import NETWORKS, TORSOS, conv_torso, random_shift
from baselines.runs import (TRAINING_KEYS, RunConfig, append_csv, read_checkpoint,
                            recorded_parts, save_checkpoint, write_summary)
from stori_jax.checks import check_int, check_real
from stori_jax.core import agent_key
from stori_jax.presets import canonical_preset

ACTION_HEADS = ("joint", "factored")
# ALE's full action set by name, in index order (games whose minimal set is all 18 use it as is)
FULL_ACTION_SET = [a.name for a in sorted(ale_py.Action.__members__.values(),
                                            key=lambda a: a.value)]
LOG_FIELDS = ("iteration", "global_step", "episodes", "mean_return", "mean_length", "pg_loss",
              "v_loss", "entropy", "approx_kl", "clipfrac", "explained_variance", "lr", "sps",
              "rollout_sps", "update_s")
EPISODE_FIELDS = ("global_step", "env", "return", "length")
# the columns of log.csv that measure this machine's speed, not the run's learning
TIMING_FIELDS = ("sps", "rollout_sps", "update_s")


# -- hyperparameters ------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class PPOConfig(RunConfig):
    """CleanRL's Atari defaults; ``total_steps`` counts agent steps summed over the envs."""

    TITLE = "PPO"

    game: str = "Breakout"
    preset: str = "3.1"
    seed: int = 0
    total_steps: int = 100_000
    num_envs: int = 8             # split into two halves stepped in turn (must be even)
    num_steps: int = 128          # rollout length per env per iteration
    learning_rate: float = 2.5e-4
    anneal_lr: bool = True
    gamma: float = 0.99
    gae_lambda: float = 0.95
    num_minibatches: int = 4
    update_epochs: int = 4
    clip_coef: float = 0.1
    clip_vloss: bool = True
    ent_coef: float = 0.01
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    network: str = "nature"       # "nature" (Mnih 2015), "nips" (Mnih 2013, 3x cheaper), "tiny"
    augment_shift: int = 0        # DrQ/RAD random shifts of up to this many pixels in the update
    action_head: str = "joint"    # "joint": one softmax over the actions; "factored": a
                                  # direction softmax times a fire softmax (ALE's full 18 actions)
    checkpoint_every: int = 10    # iterations between checkpoints (and always at the end)

    @property
    def batch_size(self) -> int:
        return self.num_envs * self.num_steps

    @property
    def minibatch_size(self) -> int:
        return self.batch_size // self.num_minibatches

    @property
    def num_iterations(self) -> int:
        """Enough iterations for at least ``total_steps`` agent steps."""
        return -(-self.total_steps // self.batch_size)

    def __post_init__(self):
        import stori_jax

        object.__setattr__(self, "game", stori_game(self.game))
        # one spelling per preset in the results; an unknown preset: a clear ValueError
        object.__setattr__(self, "preset", canonical_preset(self.game, self.preset))
        for name in ("seed", "total_steps", "num_envs", "num_steps", "num_minibatches",
                     "update_epochs", "checkpoint_every", "augment_shift"):
            minimum = 0 if name in ("seed", "augment_shift") else 1
            object.__setattr__(self, name, check_int(name, getattr(self, name), minimum))
        for name in ("gamma", "gae_lambda"):
            object.__setattr__(self, name, check_real(name, getattr(self, name), 0, 1))
        for name in ("learning_rate", "clip_coef", "ent_coef", "vf_coef", "max_grad_norm"):
            object.__setattr__(self, name, check_real(name, getattr(self, name), 0))
        for name in ("learning_rate", "max_grad_norm"):  # at 0 the policy never changes
            if getattr(self, name) == 0:
                raise ValueError(f"{name} must be > 0, got 0")
        for name in ("anneal_lr", "clip_vloss"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be True or False, got {getattr(self, name)!r}")
        from stori_jax.checks import MAX_SEED

        if self.seed > (MAX_SEED - 1) // 2:  # the two halves' envs use seeds 2*seed, 2*seed+1
            raise ValueError(f"seed must be in [0, {(MAX_SEED - 1) // 2}], got {self.seed}")
        if self.num_envs % 2:
            raise ValueError(f"num_envs must be even (two halves stepped in turn), "
                             f"got {self.num_envs}")
        if self.batch_size % self.num_minibatches:
            raise ValueError(f"num_envs * num_steps ({self.batch_size}) must be divisible by "
                             f"num_minibatches ({self.num_minibatches})")
        if self.network not in NETWORKS:
            raise ValueError(f"network must be one of {list(NETWORKS)}, got {self.network!r}")
        if self.action_head not in ACTION_HEADS:
            raise ValueError(f"action_head must be one of {list(ACTION_HEADS)}, "
                             f"got {self.action_head!r}")
        updates = self.num_iterations * updates_per_iteration(self)
        if self.anneal_lr and updates > np.iinfo(np.int32).max:  # the schedule counts in int32
            raise ValueError(f"total_steps is too large for anneal_lr: {self.num_iterations} "
                             f"iterations x {updates_per_iteration(self)} updates each = "
                             f"{updates} optimizer updates, the learning-rate schedule counts "
                             f"at most {np.iinfo(np.int32).max}; train fewer steps, or turn "
                             "anneal_lr off (--set anneal_lr=false)")
        num_actions = stori_jax.get_game(self.game).num_actions
        if self.action_head == "factored" and num_actions != len(FULL_ACTION_SET):
            raise ValueError(f"action_head='factored' needs a game that plays ALE's full "
                             f"{len(FULL_ACTION_SET)} actions (e.g. Boxing, BankHeist); "
                             f"{self.game} has {num_actions}: use action_head='joint'")


# -- network --------------------------------------------------------------------------------------

def direction_and_fire(names: list[str]) -> np.ndarray:
    """(A, 2) int32: each action as (its direction's index, 1 if it fires).  ALE's full set is
    every one of 9 directions (NOOP, UP, RIGHT, ..., DOWNLEFT) with and without FIRE."""
    directions = [name.replace("FIRE", "") or "NOOP" for name in names]
    order = list(dict.fromkeys(directions))
    return np.array([(order.index(d), "FIRE" in name) for d, name in zip(directions, names)],
                    np.int32)


DIRECTION_AND_FIRE = direction_and_fire(FULL_ACTION_SET)  # the factored head's action table
NUM_DIRECTIONS = int(DIRECTION_AND_FIRE[:, 0].max()) + 1


class ActorCritic(nn.Module):
    """Atari CNN torso on (B, 84, 84, 4) uint8 frames; policy logits and a value.

    ``action_head="factored"`` (ALE's full action set only) makes the policy a product of a
    direction distribution and a fire distribution: its logits are the normalised log-probs
    log p(direction) + log p(fire), so every sample teaches the fire head whatever its direction.
    """

    num_actions: int
    network: str = "nature"
    action_head: str = "joint"

    @nn.compact
    def __call__(self, obs):
        x = conv_torso(obs, self.network)
        x = nn.relu(nn.Dense(TORSOS[self.network][1], kernel_init=nn.initializers.orthogonal(np.sqrt(2)))(x))

        def head(size):
            return nn.Dense(size, kernel_init=nn.initializers.orthogonal(0.01))(x)

        if self.action_head == "joint":
            logits = head(self.num_actions)
        else:
            direction = jax.nn.log_softmax(head(NUM_DIRECTIONS))
            fire = jax.nn.log_softmax(head(2))
            logits = direction[:, DIRECTION_AND_FIRE[:, 0]] + fire[:, DIRECTION_AND_FIRE[:, 1]]
        value = nn.Dense(1, kernel_init=nn.initializers.orthogonal(1.0))(x)
        return logits, value[:, 0]


# -- acting ---------------------------------------------------------------------------------------

def make_network(config: PPOConfig, num_actions: int) -> ActorCritic:
    return ActorCritic(num_actions=num_actions, network=config.network,
                       action_head=config.action_head)


def learning_rate_schedule(config: PPOConfig) -> optax.ScalarOrSchedule:
    """The learning rate of each minibatch update (counted from 0 over the whole run): annealed
    linearly to 0 at the run's last update with `anneal_lr`, a constant float without (so the
    optimizer state has no schedule count, as in checkpoints made before this function)."""
    if not config.anneal_lr:
        return config.learning_rate
    return optax.linear_schedule(config.learning_rate, 0.0,
                                 config.num_iterations * updates_per_iteration(config))


def learning_rate_at(config: PPOConfig, update_count: int) -> float:
    """The rate the optimizer uses for its update number `update_count` (as the log shows it)."""
    schedule = learning_rate_schedule(config)
    return float(schedule(update_count) if callable(schedule) else schedule)


def updates_per_iteration(config: PPOConfig) -> int:
    return config.update_epochs * config.num_minibatches


def make_optimizer(config: PPOConfig) -> optax.GradientTransformation:
    return optax.chain(optax.clip_by_global_norm(config.max_grad_norm),
                       optax.adam(learning_rate_schedule(config), eps=1e-5))


def act(network: ActorCritic, params, obs, key):
    """Sample actions: (action, log-prob, value), each (B,)."""
    logits, value = network.apply(params, obs)
    action = jax.random.categorical(key, logits)
    logp = jax.nn.log_softmax(logits)[jnp.arange(action.shape[0]), action]
    return action.astype(jnp.int32), logp, value


# -- rollouts -------------------------------------------------------------------------------------

class Rollout(NamedTuple):
    """One iteration's experience, every leaf (num_steps, num_envs, ...)."""

    obs: jax.Array
    action: jax.Array
    logp: jax.Array
    value: jax.Array
    reward: jax.Array      # clipped to its sign, as usual on Atari; where the frame cap cut the
    #                        episode off (truncated, not terminated), plus gamma x the value of
    #                        the observation it ended on (info["final_obs"])
    done: jax.Array        # the episode ended after this step (terminated or truncated)


def train_env_seeds(seed: int) -> tuple[int, int]:
    """The env seeds of a training run's two half-batches: distinct for distinct seeds."""
    return 2 * seed, 2 * seed + 1


def make_envs(config: PPOConfig):
    """Two half-batches with their own emulator workers (none emulated in this process, which
    chooses actions meanwhile), one core of the machine left for the agent; seeds
    :func:`train_env_seeds`.  The split over workers never changes the results."""
    import stori_jax
    from stori_jax.builder import FRAME_SKIP, check_memory

    check_memory(config.num_envs, FRAME_SKIP)  # both halves: named by the whole batch
    half = config.num_envs // 2
    return [stori_jax.make(config.game, config.preset, num_envs=half, seed=env_seed,
                           obs="atari84", num_workers=workers_per_half(half), inline_envs=0)
            for env_seed in train_env_seeds(config.seed)]


def workers_per_half(half: int) -> int:
    """Emulator workers of each half-batch of ``half`` envs: half the cores but one each (the
    cores :func:`baselines.runs.cores` allows: a grid trial's share of its node)."""
    from baselines.runs import cores

    return max(1, min(half, (cores() - 1) // 2))


def collect(envs, act_fn, params, obs, key, num_steps: int, episodes: list, step0: int,
            value_fn=None, gamma: float = 0.0):
    """Step both halves ``num_steps`` times under the policy: each half's actions are chosen
    while the other half emulates.  Returns (Rollout, last obs per half, key); finished
    episodes are appended to ``episodes`` as (global_step, env, return, length).  With
    ``value_fn(params, obs) -> (B,) values``, an episode cut off at the frame cap is
    bootstrapped: its last reward gets ``gamma`` x the value of the observation it ended on
    (the step's ``done`` still stops GAE there, so the value stands in for what follows)."""
    half = envs[0].num_envs
    records = ([], [])

    def cut_off_value(truncated, terminated, info):
        """gamma V(final obs) where the cap cut an episode off, else 0; None where none was."""
        cut = np.asarray(truncated) & ~np.asarray(terminated)
        if value_fn is None or not cut.any():
            return None
        return jnp.where(cut, gamma * value_fn(params, info["final_obs"]), 0.0)

    def choose(g):
        nonlocal key
        key, k = jax.random.split(key)
        actions = act_fn(params, obs[g], k)
        envs[g].send(actions[0])
        return actions

    def finish(g, actions, t):
        next_obs, reward, terminated, truncated, info = envs[g].recv()
        done = terminated | truncated
        reward = jnp.sign(reward)
        bootstrap = cut_off_value(truncated, terminated, info)
        if bootstrap is not None:  # (no change to a rollout the cap never cuts)
            reward = reward + bootstrap
        records[g].append((obs[g], *actions, reward, done))
        obs[g] = next_obs
        finished = np.flatnonzero(np.asarray(done))
        if finished.size:
            returns = np.asarray(info["episode_return"])
            lengths = np.asarray(info["episode_length"])
            episodes.extend((step0 + (t + 1) * 2 * half, g * half + int(i), float(returns[i]),
                             int(lengths[i])) for i in finished)

    actions0 = choose(0)
    for t in range(num_steps):
        actions1 = choose(1)            # while half 0 emulates step t
        finish(0, actions0, t)
        if t + 1 < num_steps:
            actions0 = choose(0)        # while half 1 emulates step t
        finish(1, actions1, t)
    halves = [jax.tree.map(lambda *xs: jnp.stack(xs), *records[g]) for g in (0, 1)]
    rollout = Rollout(*jax.tree.map(lambda a, b: jnp.concatenate([a, b], axis=1), *halves))
    return rollout, obs, key


# -- advantages and the update --------------------------------------------------------------------

def gae(rollout: Rollout, last_value, gamma: float, lam: float):
    """Generalised advantage estimates and returns, (T, B) each."""
    def backwards(carry, step):
        next_value, next_advantage = carry
        reward, value, done = step
        not_done = 1.0 - done.astype(jnp.float32)
        delta = reward + gamma * next_value * not_done - value
        advantage = delta + gamma * lam * not_done * next_advantage
        return (value, advantage), advantage

    _, advantages = jax.lax.scan(backwards, (last_value, jnp.zeros_like(last_value)),
                                 (rollout.reward, rollout.value, rollout.done), reverse=True)
    return advantages, advantages + rollout.value


def ppo_loss(network, config: PPOConfig, params, batch):
    obs, action, old_logp, old_value, advantage, target = batch
    logits, value = network.apply(params, obs)
    log_probs = jax.nn.log_softmax(logits)
    logp = log_probs[jnp.arange(action.shape[0]), action]
    log_ratio = logp - old_logp
    ratio = jnp.exp(log_ratio)
    advantage = (advantage - advantage.mean()) / (advantage.std() + 1e-8)
    pg_loss = jnp.maximum(-advantage * ratio,
                          -advantage * jnp.clip(ratio, 1 - config.clip_coef,
                                                1 + config.clip_coef)).mean()
    if config.clip_vloss:
        clipped = old_value + jnp.clip(value - old_value, -config.clip_coef, config.clip_coef)
        v_loss = 0.5 * jnp.maximum((value - target) ** 2, (clipped - target) ** 2).mean()
    else:
        v_loss = 0.5 * ((value - target) ** 2).mean()
    entropy = -(jnp.exp(log_probs) * log_probs).sum(-1).mean()
    loss = pg_loss - config.ent_coef * entropy + config.vf_coef * v_loss
    metrics = dict(pg_loss=pg_loss, v_loss=v_loss, entropy=entropy,
                   approx_kl=((ratio - 1) - log_ratio).mean(),
                   clipfrac=(jnp.abs(ratio - 1) > config.clip_coef).mean())
    return loss, metrics


def make_update(network, optimizer, config: PPOConfig):
    """The whole PPO update of one iteration, jitted: GAE, then epochs x minibatches of SGD."""
    grad_fn = jax.value_and_grad(lambda p, b: ppo_loss(network, config, p, b), has_aux=True)

    def minibatch_step(carry, batch_and_key):
        params, opt_state = carry
        batch, key = batch_and_key
        if config.augment_shift:  # the update sees shifted frames (RAD); acting never does
            batch = (random_shift(batch[0], key, config.augment_shift), *batch[1:])
        (loss, metrics), grads = grad_fn(params, batch)
        updates, opt_state = optimizer.update(grads, opt_state, params)
        return (optax.apply_updates(params, updates), opt_state), dict(metrics, loss=loss)

    def epoch(carry, key):
        params, opt_state, flat = carry
        order_key, shift_key = jax.random.split(key)
        order = jax.random.permutation(order_key, config.batch_size)
        shuffled = jax.tree.map(
            lambda x: x[order].reshape(config.num_minibatches, config.minibatch_size,
                                       *x.shape[1:]), flat)
        shift_keys = jax.random.split(shift_key, config.num_minibatches)
        (params, opt_state), metrics = jax.lax.scan(minibatch_step, (params, opt_state),
                                                    (shuffled, shift_keys))
        return (params, opt_state, flat), metrics

    @jax.jit
    def update(params, opt_state, rollout: Rollout, last_obs, key):
        _, last_value = network.apply(params, last_obs)
        advantages, targets = gae(rollout, last_value, config.gamma, config.gae_lambda)
        flat = jax.tree.map(lambda x: x.reshape(config.batch_size, *x.shape[2:]),
                            (rollout.obs, rollout.action, rollout.logp, rollout.value,
                             advantages, targets))
        keys = jax.random.split(key, config.update_epochs)
        (params, opt_state, _), metrics = jax.lax.scan(epoch, (params, opt_state, flat), keys)
        values = rollout.value.reshape(-1)
        explained = 1 - jnp.var(targets.reshape(-1) - values) / (jnp.var(targets) + 1e-8)
        metrics = jax.tree.map(jnp.mean, metrics)
        return params, opt_state, dict(metrics, explained_variance=explained)

    return update


# -- checkpoints ----------------------------------------------------------------------------------

# what a checkpoint holds beyond its format, config and params, for a run to continue from it
RESUME_STATE = ("iteration", "opt_state", "key", "obs", "envs", "elapsed_s")
CHECKPOINT_FORMAT = "stori-jax-ppo-1"

def load_checkpoint(path: Path) -> dict:
    """The payload of a checkpoint written by :func:`train`; a ValueError saying why if
    ``path`` is not one."""
    return check_checkpoint(read_checkpoint(path, "stori-jax PPO"), path)


def check_checkpoint(payload: dict, path: Path) -> dict:
    """``payload`` (read from ``path``) if it is a PPO checkpoint; a ValueError saying why not."""
    return runs.check_checkpoint(payload, path, checkpoint_format=CHECKPOINT_FORMAT,
                                 config_class=PPOConfig)


# -- training -------------------------------------------------------------------------------------

def train(config: PPOConfig, out: Path, *, resume: bool = False, progress: bool = True,
          stop_after: int | None = None) -> dict:
    """Train PPO; write ``out``/config.json, log.csv, episodes.csv, checkpoint.pkl and
    summary.json.  ``resume`` continues from ``out``/checkpoint.pkl.  ``stop_after`` stops
    (with a checkpoint) after that many iterations in total, as an interruption would.  The
    summary's ``software`` is what this call started with; ``software_parts`` lists the
    software of every part of a resumed run where it changed (resuming with other software
    warns: the run may no longer match an uninterrupted one bit for bit).  A resume with
    nothing to train returns the run's summary as recorded and touches no file (but writes a
    finished run's summary.json if an interruption came before it)."""
    from tqdm import tqdm

    run = runs.start_training(config, out, "ppo", resume=resume, stop_after=stop_after,
                              load_checkpoint=load_checkpoint, resume_state=RESUME_STATE,
                              log_fields=LOG_FIELDS, episode_fields=EPISODE_FIELDS)
    out, ckpt, last, ckpt_path = run.out, run.ckpt, run.last, run.checkpoint
    if run.nothing_to_train:
        parts = recorded_parts(ckpt)
        return run.untrained(_summary(config, last, ckpt["elapsed_s"], parts[-1]["software"],
                                      parts))
    envs = make_envs(config)
    try:
        network = make_network(config, envs[0].num_actions)
        optimizer = make_optimizer(config)
        act_fn = jax.jit(lambda p, o, k: act(network, p, o, k))
        value_fn = jax.jit(lambda p, o: network.apply(p, o)[1])
        update = make_update(network, optimizer, config)
        if ckpt is not None:
            params, opt_state = ckpt["params"], ckpt["opt_state"]
            key, start, obs = ckpt["key"], ckpt["iteration"], list(ckpt["obs"])
            parts = run.resume_files(start * config.batch_size)
            for env, snap in zip(envs, ckpt["envs"]):
                env.restore(snap)
            elapsed = ckpt["elapsed_s"]
        else:
            key = agent_key(config.seed)  # the env seeds 2*seed, 2*seed+1 draw their own chains
            key, init_key = jax.random.split(key)
            obs = [env.reset()[0] for env in envs]
            params = network.init(init_key, obs[0])
            opt_state = optimizer.init(params)
            start, elapsed = 0, 0.0
            parts = run.begin_files(config)
        bar = tqdm(total=config.num_iterations * config.batch_size, initial=start
                   * config.batch_size, unit="step", disable=not progress,
                   desc=f"ppo {config.game} {config.preset} seed {config.seed}")
        recent = []
        for iteration in range(start, last):
            t0 = time.perf_counter()
            step0 = iteration * config.batch_size
            episodes = []
            rollout, obs, key = collect(envs, act_fn, params, obs, key, config.num_steps,
                                        episodes, step0, value_fn, config.gamma)
            jax.block_until_ready(rollout)
            t1 = time.perf_counter()
            key, update_key = jax.random.split(key)
            params, opt_state, metrics = update(params, opt_state, rollout,
                                                jnp.concatenate(obs), update_key)
            metrics = jax.device_get(metrics)
            t2 = time.perf_counter()
            elapsed += t2 - t0
            step = step0 + config.batch_size
            returns = [e[2] for e in episodes]
            recent = (recent + returns)[-20:]
            # the rate the next update will use (this iteration's updates ran above it)
            lr = learning_rate_at(config, (iteration + 1) * updates_per_iteration(config))
            row = dict(iteration=iteration + 1, global_step=step, episodes=len(returns),
                       mean_return=np.mean(returns) if returns else "",
                       mean_length=np.mean([e[3] for e in episodes]) if episodes else "",
                       lr=lr, sps=step / elapsed, rollout_sps=config.batch_size / (t1 - t0),
                       update_s=t2 - t1, **{k: float(v) for k, v in metrics.items()
                                            if k in LOG_FIELDS})
            append_csv(run.log, [[row[f] for f in LOG_FIELDS]])
            append_csv(run.episodes, episodes)
            bar.update(config.batch_size)
            bar.set_postfix(ret=f"{np.mean(recent):.1f}" if recent else "-",
                            sps=f"{step / elapsed:.0f}")
            if (iteration + 1) % config.checkpoint_every == 0 or iteration + 1 == last:
                save_checkpoint(ckpt_path, dict(
                    format=CHECKPOINT_FORMAT, config=dataclasses.asdict(config),
                    iteration=iteration + 1, params=params, opt_state=opt_state, key=key,
                    obs=obs, envs=[env.snapshot() for env in envs], elapsed_s=elapsed,
                    software_parts=parts))
        bar.close()
    finally:
        for env in envs:
            env.close()
    summary = _summary(config, last, elapsed, run.made_with, parts)
    write_summary(out, summary)
    return dict(summary, iterations_now=last - start,
                agent_steps_now=(last - start) * config.batch_size)


def _summary(config: PPOConfig, iterations: int, elapsed: float, made_with: dict,
             software_parts: list) -> dict:
    """summary.json's content for a run trained ``iterations`` in ``elapsed`` seconds."""
    return dict(config=dataclasses.asdict(config), iterations_done=iterations,
                finished=iterations == config.num_iterations,
                agent_steps=iterations * config.batch_size, train_seconds=elapsed,
                train_sps=iterations * config.batch_size / max(elapsed, 1e-9),
                software=made_with, software_parts=software_parts)


def env_only_sps(config: PPOConfig, agent_steps: int = 2048) -> float:
    """Agent steps per second of the same two half-batches under uniform random actions, with
    no network: the ceiling training SPS is compared with."""
    envs = make_envs(config)
    try:
        rng = np.random.default_rng(config.seed)
        obs = [env.reset()[0] for env in envs]
        half, n = envs[0].num_envs, envs[0].num_actions
        envs[0].send(rng.integers(0, n, half))
        rounds = max(agent_steps // config.num_envs, 1)
        start = time.perf_counter()
        for t in range(rounds):
            envs[1].send(rng.integers(0, n, half))
            obs[0] = envs[0].recv()[0]
            if t + 1 < rounds:
                envs[0].send(rng.integers(0, n, half))
            obs[1] = envs[1].recv()[0]
        jax.block_until_ready(obs)
        return rounds * config.num_envs / (time.perf_counter() - start)
    finally:
        for env in envs:
            env.close()


def load_policy(checkpoint: Path, mode: str = "sampled"):
    """(config, policy(obs, key) -> (B,) int32 actions) of a checkpoint, acting ``sampled``
    (from its distribution) or ``greedy`` (argmax), jitted."""
    return policy_of(load_checkpoint(checkpoint), mode)


def progress_of(config: PPOConfig, agent_steps: int) -> dict:
    """How far a run of ``config`` that trained ``agent_steps`` had got (TRAINING_KEYS): those
    steps, the run's budget (total_steps) and whether it had finished its iterations."""
    return dict(zip(TRAINING_KEYS, (agent_steps, config.total_steps,
                                    agent_steps >= config.num_iterations * config.batch_size)))


def training_progress(ckpt: dict) -> dict:
    """:func:`progress_of` a checkpoint's run; {} for a checkpoint that does not say (no
    iteration count)."""
    if not isinstance(ckpt.get("iteration"), int):
        return {}
    config = PPOConfig.from_recorded(ckpt["config"])
    return progress_of(config, ckpt["iteration"] * config.batch_size)


def policy_of(ckpt: dict, mode: str = "sampled"):
    """:func:`load_policy` of a loaded checkpoint payload."""
    if mode not in CHECKPOINT_POLICIES:
        raise ValueError(f"mode must be one of {list(CHECKPOINT_POLICIES)}, got {mode!r}")
    config = PPOConfig.from_recorded(ckpt["config"])
    import stori_jax

    network = make_network(config, stori_jax.get_game(config.game).num_actions)
    params = ckpt["params"]

    @jax.jit
    def policy(obs, key):
        logits, _ = network.apply(params, obs)
        if mode == "greedy":
            return jnp.argmax(logits, axis=-1).astype(jnp.int32)
        return jax.random.categorical(key, logits).astype(jnp.int32)

    return config, policy


AGENT = Agent(name="ppo", title="PPO", config_class=PPOConfig,
              checkpoint_format=CHECKPOINT_FORMAT, train=train,
              check_checkpoint=check_checkpoint, policy_of=policy_of,
              training_progress=training_progress, train_env_seeds=train_env_seeds,
              steps_per_iteration=lambda config: config.batch_size)
