"""DrQ(ε) on a STORI preset, in one file (after Dopamine's ``labs/atari_100k`` DrQ_eps.gin and
CleanRL's ``dqn_atari_jax``): the sample-efficient DQN of the Atari 100k benchmark.

Double DQN with a dueling head on the Nature CNN, 10-step returns, a target network copied
after every update, one gradient update per agent step (replay ratio 1) from uniform replay,
each sampled frame stack randomly shifted (edges padded by 4 pixels and cropped back) and its
intensity scaled by a little noise (DrQ, Kostrikov et al. 2020), and ε-greedy acting with
DrQ(ε)'s ε (Agarwal et al. 2021): 1 decaying linearly to 0.01 over 5000 agent steps after the
1600 of warm-up, 0.001 in evaluation.

Read top to bottom: hyperparameters, network, augmentation, replay (n-step transitions from
flashbax sequences), the TD loss and the jitted update, acting, checkpoints, the training loop.

Learning-side choices (the agent's, not the env's): a lost life ends the learner's episode (the
n-step return stops there and is not bootstrapped; the env's own episode goes on, whole games
as the paper plays them), and rewards are clipped to their sign.  Logs and evaluations report
the game's returns.

Replay: flashbax's trajectory buffer (``flashbax.make_trajectory_buffer``), one time axis per
env, one row per agent step holding the newest 84x84 frame of the observation (each frame
stored once), the action, the clipped reward and three flags: ``first`` (the observation
begins an episode: its stack is that frame repeated, as stori's ``reset_stack``), ``done`` (the
learner's terminal: a lost life or the game's end) and ``cut`` (the frame cap cut the episode
off).  A sample is a sequence of n + 4 rows: three rows of history, the transition's, and up
to its bootstrap state's row; the frame stacks are rebuilt from the rows (as the env's
``push_frame`` built them) and the n-step return stops at the first ``done`` or ``cut``, so it
never crosses an episode's end.  A return cut off by the frame cap would bootstrap from the
episode's final observation (``info['final_obs']``), which a row-per-step buffer does not keep:
those returns (at most n per episode that lasts 27,000 agent steps) are left out of the loss.

Deterministic: the same config on the same machine gives the same run, bit for bit, and a run
resumed from a checkpoint (parameters, optimizer, replay, keys, the emulators' states)
continues as if it had never stopped.  Command line: ``stori-jax train drq --game Boxing``.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from fractions import Fraction
from pathlib import Path
from typing import NamedTuple

import flashbax
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
from stori_jax.checks import MAX_SEED, check_int, check_real
from stori_jax.core import agent_key
from stori_jax.presets import canonical_preset

HISTORY = 3  # frames before the newest in a stack (stori's atari84 stacks 4)
LOG_FIELDS = ("iteration", "global_step", "updates", "episodes", "mean_return", "mean_length",
              "loss", "q_mean", "epsilon", "sps")
EPISODE_FIELDS = ("global_step", "env", "return", "length")
TIMING_FIELDS = ("sps",)  # the columns of log.csv that measure the machine, not the run


# -- hyperparameters ------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class DrQConfig(RunConfig):
    """DrQ(ε)'s hyperparameters (Dopamine's DrQ_eps.gin); ``total_steps`` counts agent steps
    summed over the envs."""

    TITLE = "DrQ"

    game: str = "Breakout"
    preset: str = "3.1"
    seed: int = 0
    total_steps: int = 100_000
    num_envs: int = 4                # envs stepped together; an iteration is one step of each
    replay_ratio: float = 1.0        # gradient updates per agent step
    batch_size: int = 32
    n_step: int = 10
    gamma: float = 0.99
    learning_rate: float = 1e-4
    adam_eps: float = 1.5e-4
    learning_starts: int = 1600      # transitions in the replay before the first update
    target_update_period: int = 1    # updates between copies of the online network
    epsilon_end: float = 0.01        # ε falls from 1 to this ...
    epsilon_decay_steps: int = 5000  # ... over these agent steps after learning_starts
    epsilon_eval: float = 0.001      # the evaluation's ("sampled") ε
    buffer_size: int = 100_000       # transitions (frames) the replay holds, over all envs
    augment_pad: int = 4             # random shifts of up to this many pixels (0: none)
    intensity_scale: float = 0.05    # x (1 + scale * clip(N(0, 1), -2, 2)) per sample (0: none)
    network: str = "nature"          # "nature" (Mnih 2015), "nips" (Mnih 2013), "tiny"
    terminal_on_life_loss: bool = True
    clip_rewards: bool = True
    log_every: int = 1000            # agent steps between log.csv rows
    checkpoint_every: int = 20_000   # agent steps between checkpoints (and always at the end)

    @property
    def num_iterations(self) -> int:
        """Enough iterations (one agent step of every env each) for ``total_steps``."""
        return -(-self.total_steps // self.num_envs)

    @property
    def sequence_length(self) -> int:
        """Rows of a replay sample: the stack's history, the transition, its n steps."""
        return HISTORY + 1 + self.n_step

    def __post_init__(self):
        object.__setattr__(self, "game", stori_game(self.game))
        object.__setattr__(self, "preset", canonical_preset(self.game, self.preset))
        for name, minimum in (("seed", 0), ("total_steps", 1), ("num_envs", 1),
                              ("batch_size", 1), ("n_step", 1), ("learning_starts", 0),
                              ("target_update_period", 1), ("epsilon_decay_steps", 1),
                              ("buffer_size", 1), ("augment_pad", 0), ("log_every", 1),
                              ("checkpoint_every", 1)):
            object.__setattr__(self, name, check_int(name, getattr(self, name), minimum,
                                                     MAX_SEED if name == "seed" else None))
        for name in ("gamma", "epsilon_end", "epsilon_eval"):
            object.__setattr__(self, name, check_real(name, getattr(self, name), 0, 1))
        for name in ("replay_ratio", "learning_rate", "adam_eps", "intensity_scale"):
            object.__setattr__(self, name, check_real(name, getattr(self, name), 0))
        for name in ("replay_ratio", "learning_rate", "adam_eps"):
            if getattr(self, name) == 0:
                raise ValueError(f"{name} must be > 0, got 0")
        if self.intensity_scale >= 0.5:  # the noise factor 1 + scale * [-2, 2] stays positive
            raise ValueError(f"intensity_scale must be < 0.5, got {self.intensity_scale}")
        for name in ("terminal_on_life_loss", "clip_rewards"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be True or False, got {getattr(self, name)!r}")
        if self.network not in NETWORKS:
            raise ValueError(f"network must be one of {list(NETWORKS)}, got {self.network!r}")
        per_env = self.buffer_size // self.num_envs
        if per_env < self.sequence_length:
            raise ValueError(f"buffer_size {self.buffer_size} holds {per_env} transitions per "
                             f"env (of num_envs {self.num_envs}); a sample needs n_step + 4 = "
                             f"{self.sequence_length}")
        if self.augment_pad > 84:
            raise ValueError(f"augment_pad must be <= 84, got {self.augment_pad}")


def train_env_seeds(seed: int) -> tuple[int]:
    """The env seed training plays: the training seed itself (evaluation plays seed + 10000)."""
    return (seed,)


def epsilon_at(config: DrQConfig, step: int) -> float:
    """ε of the agent step ``step`` (Dopamine's linearly_decaying_epsilon): 1 during the
    warm-up, then linear down to ``epsilon_end`` over ``epsilon_decay_steps``."""
    left = config.epsilon_decay_steps + config.learning_starts - step
    bonus = (1.0 - config.epsilon_end) * left / config.epsilon_decay_steps
    return config.epsilon_end + min(max(bonus, 0.0), 1.0 - config.epsilon_end)


def learner_ends(terminated, truncated, lives_before, lives_now, terminal_on_life_loss: bool):
    """(done, cut) of a step, each (B,) bool: ``done`` where the learner's episode ended (the
    game's end, or a life lost while the game goes on), ``cut`` where the frame cap cut the
    game off.  At an episode's end the env's lives are the next episode's already, so a life
    lost on the very step the cap cuts the game is not counted (the cut ends the return)."""
    terminated, truncated = np.asarray(terminated), np.asarray(truncated)
    ended = terminated | truncated
    life_lost = ~ended & (np.asarray(lives_now) < np.asarray(lives_before))
    return terminated | (terminal_on_life_loss & life_lost), truncated & ~terminated


def updates_due(config: DrQConfig, transitions: int) -> int:
    """Gradient updates done once the replay holds ``transitions``: ``replay_ratio`` per
    transition past ``learning_starts`` (and past the first full sample of every env)."""
    start = max(config.learning_starts, config.num_envs * config.sequence_length)
    return max(0, int(Fraction(config.replay_ratio) * (transitions - start)))


# -- network --------------------------------------------------------------------------------------

class QNetwork(nn.Module):
    """Q-values (B, A) of frame stacks (B, 84, 84, 4) in pixel units (uint8, or the float
    augmented ones): an Atari torso (``networks.TORSOS``, VALID convolutions as in Mnih 2015) and a
    dueling head, value + advantage - mean advantage, on a shared hidden layer (Dopamine's
    FullRainbowNetwork without noise or atoms)."""

    num_actions: int
    network: str = "nature"

    @nn.compact
    def __call__(self, obs):
        x = conv_torso(obs, self.network)
        dense = functools.partial(nn.Dense, kernel_init=nn.initializers.xavier_uniform())
        x = nn.relu(dense(TORSOS[self.network][1])(x))
        advantage = dense(self.num_actions)(x)
        value = dense(1)(x)
        return value + advantage - advantage.mean(axis=-1, keepdims=True)


def make_network(config: DrQConfig, num_actions: int) -> QNetwork:
    return QNetwork(num_actions=num_actions, network=config.network)


def make_optimizer(config: DrQConfig) -> optax.GradientTransformation:
    return optax.adam(config.learning_rate, eps=config.adam_eps)


# -- augmentation ---------------------------------------------------------------------------------

def augment(obs: jax.Array, key, pad: int, intensity_scale: float) -> jax.Array:
    """DrQ's augmentation of a batch of float frame stacks (B, 84, 84, 4), each sample its
    own draw: shifted by up to ``pad`` pixels (padded with its edge values and cropped back,
    :func:`baselines.networks.random_shift`), then scaled by 1 + ``intensity_scale`` x a standard
    normal clipped to [-2, 2] (Dopamine's ``drq_image_augmentation``).  The identity at pad 0
    and scale 0."""
    shift_key, noise_key = jax.random.split(key)
    if pad:
        obs = random_shift(obs, shift_key, pad)
    if intensity_scale:
        noise = jnp.clip(jax.random.normal(noise_key, (obs.shape[0], 1, 1, 1)), -2.0, 2.0)
        obs = obs * (1.0 + intensity_scale * noise)
    return obs


# -- replay ---------------------------------------------------------------------------------------

def make_buffer(config: DrQConfig):
    """flashbax's trajectory buffer: ``num_envs`` time axes of ``buffer_size // num_envs`` rows
    (:func:`empty_row`), sampled uniformly as sequences of ``sequence_length`` rows."""
    return flashbax.make_trajectory_buffer(
        add_batch_size=config.num_envs, sample_batch_size=config.batch_size,
        sample_sequence_length=config.sequence_length, period=1,
        min_length_time_axis=config.sequence_length,
        max_length_time_axis=config.buffer_size // config.num_envs)


def empty_row() -> dict:
    """One row of the replay: the newest frame of the observation, the action taken on it,
    the (clipped) reward, and whether the observation begins an episode (``first``), the
    learner's episode ended with this step (``done``), the frame cap cut it off (``cut``)."""
    return dict(frame=jnp.zeros((84, 84), jnp.uint8), action=jnp.int32(0),
                reward=jnp.float32(0), first=jnp.bool_(False), done=jnp.bool_(False),
                cut=jnp.bool_(False))


def stack_at(frames: jax.Array, first: jax.Array, j: int) -> jax.Array:
    """The frame stacks (B, 84, 84, 4) the env showed at row ``j`` of sequences of frames
    (B, L, 84, 84): rows j-3 .. j, a row before the episode's first repeating that first
    frame (stori's ``reset_stack`` and ``push_frame``)."""
    rows = jnp.arange(j - HISTORY, j + 1)
    began = first[:, j - HISTORY + 1:j + 1]
    start = jnp.max(jnp.where(began, rows[1:], j - HISTORY), axis=1)
    source = jnp.maximum(rows[None, :], start[:, None])
    stack = jnp.take_along_axis(frames, source[:, :, None, None], axis=1)
    return stack.transpose(0, 2, 3, 1)


class Transitions(NamedTuple):
    """A batch of n-step transitions, every leaf (B, ...)."""

    obs: jax.Array         # uint8 (B, 84, 84, 4)
    action: jax.Array      # int32
    ret: jax.Array         # sum_m gamma^m r_{t+m}, up to n steps or the learner's terminal
    discount: jax.Array    # gamma^n where the return is bootstrapped, 0 where it ended
    next_obs: jax.Array    # the bootstrap state, n steps on
    valid: jax.Array       # False where a frame-cap cut ends the return (left out of the loss)


def n_step_transitions(seq: dict, n: int, gamma: float) -> Transitions:
    """The transitions of sampled sequences of n + 4 rows (row 3 the transition's): the return
    sums the rewards of rows 3, 4, ... up to n of them, stopping after the first row that
    is ``done`` (no bootstrap) or ``cut`` (invalid), so it never crosses an episode's end."""
    reward = seq["reward"][:, HISTORY:HISTORY + n]
    stop = (seq["done"] | seq["cut"])[:, HISTORY:HISTORY + n]
    # alive[:, m]: no stop in the rows before step m of the return
    going = 1.0 - stop.astype(jnp.float32)
    alive = jnp.cumprod(jnp.concatenate([jnp.ones_like(going[:, :1]), going[:, :-1]], axis=1),
                        axis=1)
    discounts = jnp.asarray(gamma ** np.arange(n), jnp.float32)
    ret = (alive * discounts * reward).sum(axis=1)
    discount = jnp.float32(gamma ** n) * going.prod(axis=1)
    cut = seq["cut"][:, HISTORY:HISTORY + n]
    valid = ~jnp.any((alive > 0) & cut, axis=1)
    return Transitions(obs=stack_at(seq["frame"], seq["first"], HISTORY),
                       action=seq["action"][:, HISTORY], ret=ret, discount=discount,
                       next_obs=stack_at(seq["frame"], seq["first"], HISTORY + n), valid=valid)


# -- the TD loss and the update -------------------------------------------------------------------

class TrainState(NamedTuple):
    params: dict
    target_params: dict
    opt_state: tuple
    updates: jax.Array     # gradient updates so far (int32)


def td_loss(q_fn, params, target_params, batch: Transitions, shared_target: bool):
    """Double DQN's Huber loss (delta 1) over the valid transitions of ``batch``: the target
    is ret + discount x Q_target(s', argmax_a Q_online(s', a)).  ``shared_target``: the target
    network is the online one (copied after every update), so its Q-values are the online
    network's, computed once."""
    q = q_fn(params, batch.obs)
    rows = jnp.arange(q.shape[0])
    q_taken = q[rows, batch.action]
    next_online = q_fn(params, batch.next_obs)
    next_target = next_online if shared_target else q_fn(target_params, batch.next_obs)
    best = jnp.argmax(next_online, axis=-1)
    target = jax.lax.stop_gradient(batch.ret + batch.discount * next_target[rows, best])
    weight = batch.valid.astype(jnp.float32)
    loss = (weight * optax.huber_loss(q_taken, target, delta=1.0)).sum() / jnp.maximum(
        weight.sum(), 1.0)
    return loss, dict(q_mean=q_taken.mean())


def make_train_step(q_fn, optimizer, config: DrQConfig):
    """One gradient update on a batch of transitions, both its frame stacks augmented, and the
    target network's copy every ``target_update_period`` updates."""
    shared = config.target_update_period == 1
    grad_fn = jax.value_and_grad(
        lambda p, t, b: td_loss(q_fn, p, t, b, shared), has_aux=True)

    def train_step(state: TrainState, batch: Transitions, key):
        obs_key, next_key = jax.random.split(key)
        batch = batch._replace(
            obs=augment(batch.obs.astype(jnp.float32), obs_key, config.augment_pad,
                        config.intensity_scale),
            next_obs=augment(batch.next_obs.astype(jnp.float32), next_key, config.augment_pad,
                             config.intensity_scale))
        (loss, metrics), grads = grad_fn(state.params, state.target_params, batch)
        updates, opt_state = optimizer.update(grads, state.opt_state, state.params)
        params = optax.apply_updates(state.params, updates)
        count = state.updates + 1
        copy = count % config.target_update_period == 0
        target = jax.tree.map(lambda t, p: jnp.where(copy, p, t), state.target_params, params)
        return TrainState(params, target, opt_state, count), dict(metrics, loss=loss)

    return train_step


def make_update(q_fn, optimizer, buffer, config: DrQConfig):
    """``update(state, buffer_state, key, num_updates) -> (state, summed metrics)``: that many
    gradient updates on fresh uniform samples of the replay, in one jitted call."""
    train_step = make_train_step(q_fn, optimizer, config)

    @jax.jit
    def update(state: TrainState, buffer_state, key, num_updates):
        def one(i, carry):
            state, sums = carry
            sample_key, step_key = jax.random.split(jax.random.fold_in(key, i))
            seq = buffer.sample(buffer_state, sample_key).experience
            batch = n_step_transitions(seq, config.n_step, config.gamma)
            state, metrics = train_step(state, batch, step_key)
            return state, jax.tree.map(jnp.add, sums, metrics)

        zeros = dict(loss=jnp.float32(0), q_mean=jnp.float32(0))
        return jax.lax.fori_loop(0, num_updates, one, (state, zeros))

    return update


# -- acting ---------------------------------------------------------------------------------------

def epsilon_greedy(q_fn, params, obs, key, epsilon):
    """Each env's action: uniformly random with probability ``epsilon``, else the argmax."""
    q = q_fn(params, obs)
    random_key, explore_key = jax.random.split(key)
    random = jax.random.randint(random_key, (q.shape[0],), 0, q.shape[1])
    explore = jax.random.uniform(explore_key, (q.shape[0],)) < epsilon
    return jnp.where(explore, random, jnp.argmax(q, axis=-1)).astype(jnp.int32)


class Machinery(NamedTuple):
    """The jitted functions of a config (made once per config and game in a process)."""

    network: QNetwork
    optimizer: optax.GradientTransformation
    buffer: object
    act: object        # (params, obs, key, epsilon) -> actions
    add: object        # (buffer_state, obs, action, reward, first, done, cut) -> buffer_state
    update: object     # see make_update


@functools.lru_cache(maxsize=8)
def machinery(config: DrQConfig, num_actions: int) -> Machinery:
    network = make_network(config, num_actions)
    optimizer = make_optimizer(config)
    buffer = make_buffer(config)

    @jax.jit
    def act(params, obs, key, epsilon):
        return epsilon_greedy(network.apply, params, obs, key, epsilon)

    @functools.partial(jax.jit, donate_argnums=0)  # the replay is written in place
    def add(buffer_state, obs, action, reward, first, done, cut):
        reward = jnp.sign(reward) if config.clip_rewards else reward
        row = dict(frame=obs[..., -1], action=action.astype(jnp.int32),
                   reward=reward.astype(jnp.float32), first=first, done=done, cut=cut)
        return buffer.add(buffer_state, jax.tree.map(lambda x: x[:, None], row))

    return Machinery(network, optimizer, buffer, act, add,
                     make_update(network.apply, optimizer, buffer, config))


# -- checkpoints ----------------------------------------------------------------------------------

CHECKPOINT_FORMAT = "stori-jax-drq-1"
REPLAY_FORMAT = "stori-jax-drq-replay-1"
# what a checkpoint holds beyond its format, config and params, for a run to continue from it
RESUME_STATE = ("iteration", "target_params", "opt_state", "updates", "key", "obs", "lives",
                "first", "envs", "elapsed_s", "pending", "replay")


def load_checkpoint(path: Path) -> dict:
    """The payload of a checkpoint written by :func:`train`; a ValueError saying why if
    ``path`` is not one."""
    return check_checkpoint(read_checkpoint(path, "stori-jax DrQ"), path)


def check_checkpoint(payload: dict, path: Path) -> dict:
    """``payload`` (read from ``path``) if it is a DrQ checkpoint; a ValueError saying why not."""
    return runs.check_checkpoint(payload, path, checkpoint_format=CHECKPOINT_FORMAT,
                                 config_class=DrQConfig)


def save_replay(out: Path, iteration: int, buffer_state) -> str:
    """``out``/replay-<iteration>.pkl: the replay's filled rows and position (beside
    checkpoint.pkl, which names it: evaluation never reads it).  Returns the file's name."""
    filled = int(buffer_state.current_index)
    full = bool(buffer_state.is_full)
    experience = jax.tree.map(lambda x: x if full else x[:, :filled], buffer_state.experience)
    name = f"replay-{iteration}.pkl"
    save_checkpoint(Path(out) / name, dict(format=REPLAY_FORMAT, iteration=iteration,
                                           current_index=filled, is_full=full,
                                           experience=experience))
    return name


def load_replay(path: Path, iteration: int, buffer, empty):
    """The replay state saved by :func:`save_replay` for ``iteration``."""
    saved = read_checkpoint(path, "stori-jax DrQ replay")
    if saved["format"] != REPLAY_FORMAT or saved["iteration"] != iteration:
        raise ValueError(f"cannot resume: {path} is not the replay of iteration {iteration}")

    def filled(blank, rows):
        blank = np.zeros(blank.shape, blank.dtype)
        blank[:, :rows.shape[1]] = rows
        return jnp.asarray(blank)

    return empty.replace(experience=jax.tree.map(filled, empty.experience, saved["experience"]),
                         current_index=jnp.asarray(saved["current_index"],
                                                   empty.current_index.dtype),
                         is_full=jnp.asarray(saved["is_full"]))


def drop_replays(out: Path, keep: str | None) -> None:
    """Remove the replay files of earlier checkpoints (all of them once a run has finished)."""
    for path in Path(out).glob("replay-*.pkl"):
        if path.name != keep:
            path.unlink()


# -- training -------------------------------------------------------------------------------------

def make_env(config: DrQConfig):
    """The training envs: one batch of ``num_envs`` on seed :func:`train_env_seeds`, emulated
    by worker processes (one core left to the agent), so that the update runs while they
    step (as many cores as :func:`baselines.runs.cores` allows: a grid trial's share of its
    node).  The split over workers never changes the results."""
    import stori_jax

    from baselines.runs import cores

    workers = max(1, min(config.num_envs, cores() - 1))
    return stori_jax.make(config.game, config.preset, num_envs=config.num_envs,
                          seed=train_env_seeds(config.seed)[0], obs="atari84",
                          num_workers=workers, inline_envs=0)


def crossed(every: int, before: int, after: int) -> bool:
    """Whether a multiple of ``every`` lies in (before, after]."""
    return after // every > before // every


def train(config: DrQConfig, out: Path, *, resume: bool = False, progress: bool = True,
          stop_after: int | None = None) -> dict:
    """Train DrQ(ε); write ``out``/config.json, log.csv, episodes.csv, checkpoint.pkl (with
    replay-<iteration>.pkl beside it until the run has finished) and summary.json.
    ``resume`` continues from ``out``/checkpoint.pkl.  ``stop_after`` stops (with a
    checkpoint) after that many iterations in total, as an interruption would.  As
    :func:`baselines.ppo.train` otherwise (software parts, nothing to train)."""
    from tqdm import tqdm

    run = runs.start_training(config, out, "drq", resume=resume, stop_after=stop_after,
                              load_checkpoint=load_checkpoint, resume_state=RESUME_STATE,
                              log_fields=LOG_FIELDS, episode_fields=EPISODE_FIELDS)
    out, ckpt, last, ckpt_path = run.out, run.ckpt, run.last, run.checkpoint
    if run.nothing_to_train:
        parts = recorded_parts(ckpt)
        return run.untrained(_summary(config, last, int(ckpt["updates"]), ckpt["elapsed_s"],
                                      parts[-1]["software"], parts))
    e = config.num_envs
    env = make_env(config)
    try:
        m = machinery(config, env.num_actions)
        if ckpt is not None:
            if ckpt["replay"] is None:
                raise ValueError(f"cannot resume from {ckpt_path}: it keeps no replay")
            key, start, obs = ckpt["key"], ckpt["iteration"], jnp.asarray(ckpt["obs"])
            lives, first = np.asarray(ckpt["lives"]), np.asarray(ckpt["first"])
            state = TrainState(ckpt["params"], ckpt["target_params"], ckpt["opt_state"],
                               jnp.asarray(ckpt["updates"], jnp.int32))
            buffer_state = load_replay(out / ckpt["replay"], start, m.buffer,
                                       m.buffer.init(empty_row()))
            parts = run.resume_files(start * e)
            env.restore(ckpt["envs"][0])
            elapsed, pending = ckpt["elapsed_s"], ckpt["pending"]
        else:
            key = agent_key(config.seed)  # the env seed draws its own chain
            key, init_key = jax.random.split(key)
            obs, info = env.reset()
            lives, first = np.asarray(info["lives"]), np.ones(e, bool)
            params = m.network.init(init_key, obs)
            state = TrainState(params, params, m.optimizer.init(params), jnp.int32(0))
            buffer_state = m.buffer.init(empty_row())
            start, elapsed = 0, 0.0
            pending = dict(episodes=[], metrics=[], updates=0)
            parts = run.begin_files(config)
        bar = tqdm(total=config.num_iterations * e, initial=start * e, unit="step",
                   disable=not progress, desc=f"drq {config.game} {config.preset} seed "
                                              f"{config.seed}")
        recent = []
        for iteration in range(start, last):
            t0 = time.perf_counter()
            step = iteration * e  # agent steps (and transitions in the replay) so far
            epsilon = epsilon_at(config, step)
            key, act_key, update_key = jax.random.split(key, 3)
            actions = m.act(state.params, obs, act_key, np.float32(epsilon))
            env.send(actions)
            num_updates = updates_due(config, step) - updates_due(config, step - e)
            if num_updates:  # while the emulators step
                state, sums = m.update(state, buffer_state, update_key, num_updates)
                pending["metrics"].append(sums)
                pending["updates"] += num_updates
            next_obs, reward, terminated, truncated, info = env.recv()
            now = np.asarray(info["lives"])
            done, cut = learner_ends(terminated, truncated, lives, now,
                                     config.terminal_on_life_loss)
            ended = np.asarray(terminated) | np.asarray(truncated)
            buffer_state = m.add(buffer_state, obs, actions, reward, first, done, cut)
            obs, lives, first = next_obs, now, ended
            step += e
            if ended.any():
                returns = np.asarray(info["episode_return"])
                lengths = np.asarray(info["episode_length"])
                episodes = [(step, int(i), float(returns[i]), int(lengths[i]))
                            for i in np.flatnonzero(ended)]
                pending["episodes"].extend(episodes)
                recent = (recent + [ep[2] for ep in episodes])[-20:]
            elapsed += time.perf_counter() - t0
            bar.update(e)
            finished = iteration + 1 == config.num_iterations
            # a log row every log_every agent steps and at the end (not where a stop_after
            # stops: the checkpoint keeps what the next row sums, as an uninterrupted run has it)
            if crossed(config.log_every, step - e, step) or finished:
                _log(config, run.log, run.episodes, iteration + 1, step, int(state.updates),
                     epsilon, elapsed, pending)
                bar.set_postfix(ret=f"{np.mean(recent):.1f}" if recent else "-",
                                eps=f"{epsilon:.2f}", sps=f"{step / elapsed:.0f}")
            if crossed(config.checkpoint_every, step - e, step) or iteration + 1 == last:
                replay = None if finished else save_replay(out, iteration + 1, buffer_state)
                save_checkpoint(ckpt_path, dict(
                    format=CHECKPOINT_FORMAT, config=dataclasses.asdict(config),
                    iteration=iteration + 1, params=state.params,
                    target_params=state.target_params, opt_state=state.opt_state,
                    updates=int(state.updates), key=key, obs=obs, lives=lives, first=first,
                    envs=[env.snapshot()], elapsed_s=elapsed,
                    pending=jax.device_get(pending), replay=replay, software_parts=parts))
                drop_replays(out, replay)
        bar.close()
        updates = int(state.updates)
    finally:
        env.close()
    summary = _summary(config, last, updates, elapsed, run.made_with, parts)
    write_summary(out, summary)
    return dict(summary, iterations_now=last - start, agent_steps_now=(last - start) * e)


def _log(config, log_path, ep_path, iteration, step, updates, epsilon, elapsed, pending):
    """A log.csv row of the steps since the last one, and their episodes into episodes.csv;
    empties ``pending``."""
    episodes, metrics = pending["episodes"], jax.device_get(pending["metrics"])
    n = pending["updates"]
    mean = {k: (sum(float(x[k]) for x in metrics) / n if n else "") for k in ("loss", "q_mean")}
    row = dict(iteration=iteration, global_step=step, updates=updates, episodes=len(episodes),
               mean_return=np.mean([ep[2] for ep in episodes]) if episodes else "",
               mean_length=np.mean([ep[3] for ep in episodes]) if episodes else "",
               epsilon=epsilon, sps=step / max(elapsed, 1e-9), **mean)
    append_csv(log_path, [[row[f] for f in LOG_FIELDS]])
    append_csv(ep_path, episodes)
    pending.update(episodes=[], metrics=[], updates=0)


def _summary(config: DrQConfig, iterations: int, updates: int, elapsed: float, made_with: dict,
             software_parts: list) -> dict:
    """summary.json's content for a run trained ``iterations`` in ``elapsed`` seconds."""
    steps = iterations * config.num_envs
    return dict(config=dataclasses.asdict(config), iterations_done=iterations,
                finished=iterations == config.num_iterations, agent_steps=steps,
                gradient_updates=updates, train_seconds=elapsed,
                train_sps=steps / max(elapsed, 1e-9), software=made_with,
                software_parts=software_parts)


# -- policies of a checkpoint ---------------------------------------------------------------------

def training_progress(ckpt: dict) -> dict:
    """How far a checkpoint's run had trained (TRAINING_KEYS); {} where it does not say."""
    if not isinstance(ckpt.get("iteration"), int):
        return {}
    config = DrQConfig.from_recorded(ckpt["config"])
    return dict(zip(TRAINING_KEYS, (ckpt["iteration"] * config.num_envs, config.total_steps,
                                    ckpt["iteration"] >= config.num_iterations)))


def policy_of(ckpt: dict, mode: str = "sampled"):
    """(config, policy(obs, key) -> (B,) int32 actions) of a loaded checkpoint, jitted:
    ``sampled`` is ε-greedy with the evaluation ε (``epsilon_eval``, 0.001), ``greedy`` the
    argmax."""
    if mode not in CHECKPOINT_POLICIES:
        raise ValueError(f"mode must be one of {list(CHECKPOINT_POLICIES)}, got {mode!r}")
    config = DrQConfig.from_recorded(ckpt["config"])
    import stori_jax

    network = make_network(config, stori_jax.get_game(config.game).num_actions)
    params = ckpt["params"]
    epsilon = config.epsilon_eval if mode == "sampled" else 0.0

    @jax.jit
    def policy(obs, key):
        if mode == "greedy":
            return jnp.argmax(network.apply(params, obs), axis=-1).astype(jnp.int32)
        return epsilon_greedy(network.apply, params, obs, key, epsilon)

    return config, policy


def update_speed(config: DrQConfig, num_actions: int = 18, updates: int = 50) -> float:
    """Gradient updates per second of the jitted update (batch ``batch_size``, augmentation
    and replay sampling included) on a replay of random frames, compiled first."""
    m = machinery(config, num_actions)
    key = jax.random.PRNGKey(0)
    params = m.network.init(key, jnp.zeros((1, 84, 84, 4), jnp.uint8))
    state = TrainState(params, params, m.optimizer.init(params), jnp.int32(0))
    buffer_state = m.buffer.init(empty_row())
    rows = 4 * config.sequence_length
    frames = jax.random.randint(key, (config.num_envs, rows, 84, 84), 0, 256).astype(jnp.uint8)
    batch = dict(jax.tree.map(lambda x: jnp.broadcast_to(x, (config.num_envs, rows) + x.shape),
                              empty_row()), frame=frames)
    buffer_state = m.buffer.add(buffer_state, batch)
    jax.block_until_ready(m.update(state, buffer_state, key, 2))
    start = time.perf_counter()
    jax.block_until_ready(m.update(state, buffer_state, key, updates))
    return updates / (time.perf_counter() - start)


AGENT = Agent(name="drq", title="DrQ(ε)", config_class=DrQConfig,
              checkpoint_format=CHECKPOINT_FORMAT, train=train,
              check_checkpoint=check_checkpoint, policy_of=policy_of,
              training_progress=training_progress, train_env_seeds=train_env_seeds,
              steps_per_iteration=lambda config: config.num_envs)
