"""Where one DrQ(ε) iteration's time goes, measured in one run on one machine: the jitted update
whole (as training runs it) and its stages compiled alone (replay sampling + n-step
transitions, the two augmentations, the loss's forward and backward, the optimizer), acting,
adding to the replay, one env step of the batch, and whole training iterations at the
config's replay ratio (acting, the env step overlapping the updates, the replay write).  Each
figure is the median over ``--repeats`` timed calls after a compile.  Writes JSON, a markdown
table and a PNG.

    python benchmarks/drq_iteration.py [--game Boxing] [--preset 3.1] [--replay-ratio 0.25]
                                       [--repeats 20] [--out DIR]
"""

from __future__ import annotations

import argparse
import datetime
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax

from baselines import drq
from stori_jax.provenance import software
from _checks import (options_in_name, output_directory, require_at_least_one,  # on sys.path
                     stori_game_and_preset)
from ppo_rollout import plot

RESULTS = Path(__file__).resolve().parent / "results"


def median_ms(fn, repeats: int) -> float:
    """The median wall time of ``fn()`` (which blocks until its result is ready), in ms, after
    one untimed call (the compile)."""
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times))


def filled_replay(m, config, key):
    """A replay of random frames, long enough to sample from."""
    rows = 4 * config.sequence_length
    frames = jax.random.randint(key, (config.num_envs, rows, 84, 84), 0, 256).astype(jnp.uint8)
    batch = dict(jax.tree.map(lambda x: jnp.broadcast_to(x, (config.num_envs, rows) + x.shape),
                              drq.empty_row()), frame=frames)
    return m.buffer.add(m.buffer.init(drq.empty_row()), batch)


def stages(config: drq.DrQConfig, num_actions: int, repeats: int) -> dict[str, float]:
    """ms per call of the update and each of its stages, compiled alone."""
    m = drq.machinery(config, num_actions)
    key = jax.random.PRNGKey(0)
    params = m.network.init(key, jnp.zeros((1, 84, 84, 4), jnp.uint8))
    state = drq.TrainState(params, params, m.optimizer.init(params), jnp.int32(0))
    replay = filled_replay(m, config, key)
    q_fn = m.network.apply
    shared = config.target_update_period == 1

    sample = jax.jit(lambda r, k: drq.n_step_transitions(
        m.buffer.sample(r, k).experience, config.n_step, config.gamma))
    batch = sample(replay, key)

    def both_augmented(b, k):
        k1, k2 = jax.random.split(k)
        return b._replace(
            obs=drq.augment(b.obs.astype(jnp.float32), k1, config.augment_pad,
                            config.intensity_scale),
            next_obs=drq.augment(b.next_obs.astype(jnp.float32), k2, config.augment_pad,
                                 config.intensity_scale))

    augment = jax.jit(both_augmented)
    augmented = augment(batch, key)
    forward = jax.jit(lambda p, b: drq.td_loss(q_fn, p, p, b, shared)[0])
    grad = jax.jit(jax.grad(lambda p, b: drq.td_loss(q_fn, p, p, b, shared)[0]))
    grads = grad(params, augmented)

    def optimizer_step(s, g):
        updates, opt_state = m.optimizer.update(g, s.opt_state, s.params)
        return optax.apply_updates(s.params, updates), opt_state

    optimize = jax.jit(optimizer_step)
    obs = jnp.zeros((config.num_envs, 84, 84, 4), jnp.uint8)
    actions = jnp.zeros((config.num_envs,), jnp.int32)
    flags = jnp.zeros((config.num_envs,), bool)
    rewards = jnp.zeros((config.num_envs,), jnp.float32)
    ready = jax.block_until_ready
    add_state = dict(replay=filled_replay(m, config, key))

    def add():  # the replay is donated: keep the new one
        add_state["replay"] = ready(m.add(add_state["replay"], obs, actions, rewards, flags,
                                          flags, flags))

    return {
        "update (1 gradient update, as trained)": median_ms(
            lambda: ready(m.update(state, replay, key, 1)), repeats),
        "  replay sample + n-step transitions": median_ms(lambda: ready(sample(replay, key)),
                                                         repeats),
        "  augmentation (both stacks)": median_ms(lambda: ready(augment(batch, key)), repeats),
        "  loss forward (2 network passes: s, s')": median_ms(
            lambda: ready(forward(params, augmented)), repeats),
        "  loss forward + backward": median_ms(lambda: ready(grad(params, augmented)), repeats),
        "  optimizer (Adam) + apply": median_ms(lambda: ready(optimize(state, grads)), repeats),
        "act (epsilon-greedy, the batch)": median_ms(
            lambda: ready(m.act(params, obs, key, np.float32(0.1))), repeats),
        "add to the replay": median_ms(add, repeats),
    }


def env_and_iteration(config: drq.DrQConfig, repeats: int) -> dict[str, float]:
    """ms of one env step of the batch (random actions), and of whole training iterations
    (:func:`drq.train`'s loop body: act, send, the updates due, recv, add)."""
    env = drq.make_env(config)
    try:
        m = drq.machinery(config, env.num_actions)
        key = jax.random.PRNGKey(0)
        obs, _ = env.reset()
        params = m.network.init(key, obs)
        state = drq.TrainState(params, params, m.optimizer.init(params), jnp.int32(0))
        replay = filled_replay(m, config, key)
        rng = np.random.default_rng(0)
        e = config.num_envs
        out = {"env step (the batch, random actions)": median_ms(
            lambda: jax.block_until_ready(env.step(rng.integers(0, env.num_actions, e))[0]),
            repeats)}
        loop = dict(obs=obs, state=state, replay=replay, step=10_000)

        def iteration():
            step = loop["step"]
            actions = m.act(loop["state"].params, loop["obs"], key, np.float32(0.1))
            env.send(actions)
            due = drq.updates_due(config, step + e) - drq.updates_due(config, step)
            if due:
                loop["state"], sums = m.update(loop["state"], loop["replay"], key, due)
            next_obs, reward, terminated, truncated, info = env.recv()
            flags = np.zeros(e, bool)
            loop["replay"] = m.add(loop["replay"], loop["obs"], actions, reward, flags, flags,
                                   flags)
            loop["obs"], loop["step"] = next_obs, step + e
            jax.block_until_ready((loop["state"], loop["replay"]))

        per_iteration = median_ms(iteration, repeats)
        out[f"training iteration ({e} agent steps, replay ratio {config.replay_ratio:g})"] = (
            per_iteration)
        out["training agent steps/s"] = 1e3 * e / per_iteration
        return out
    finally:
        env.close()


def markdown(config: drq.DrQConfig, results: dict) -> str:
    lines = [f"DrQ(ε) on {config.game} {config.preset}: network {config.network}, batch "
             f"{config.batch_size}, {config.num_envs} envs, replay ratio "
             f"{config.replay_ratio:g}; median ms per call", "",
             "| stage | ms |", "|---|---|"]
    for name, value in results.items():
        if name != "training agent steps/s":
            lines.append(f"| {name} | {value:.1f} |")
    lines.append(f"\nTraining: {results['training agent steps/s']:.1f} agent steps/s")
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--game", default="Boxing")
    parser.add_argument("--preset", default="3.1")
    parser.add_argument("--replay-ratio", type=float, default=0.25,
                        help="gradient updates per agent step (default 0.25, as the recorded "
                             "run)")
    parser.add_argument("--repeats", type=int, default=20, help="timed calls per figure")
    parser.add_argument("--out", type=Path, default=RESULTS, help="directory for the results")
    args = parser.parse_args(argv)
    require_at_least_one(parser, repeats=args.repeats)
    if not args.replay_ratio > 0:
        parser.error(f"--replay-ratio: must be > 0, got {args.replay_ratio}")
    output_directory(parser, args.out)
    game, args.preset = stori_game_and_preset(parser, args.game, args.preset)
    config = drq.DrQConfig(game=game, preset=args.preset, replay_ratio=args.replay_ratio)
    made_with = software()
    results = stages(config, 18, args.repeats)
    results.update(env_and_iteration(config, args.repeats))
    text = markdown(config, results)
    print(text)
    stem = f"drq-iteration-{datetime.date.today().isoformat()}-{game}-{args.preset}" + \
        options_in_name(parser, args, {"replay_ratio": "rr", "repeats": "repeats"})
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{stem}.json").write_text(json.dumps(dict(
        config={**vars(args), "out": str(args.out)}, software=made_with, results=results),
        indent=1))
    (args.out / f"{stem}.md").write_text(text)
    plot([(name.strip(), value) for name, value in results.items()
          if name != "training agent steps/s"], args.out / f"{stem}.png",
         title=text.splitlines()[0], xlabel="ms per call")
    print(f"wrote {args.out / stem}.json, .md and .png")


if __name__ == "__main__":
    main()
