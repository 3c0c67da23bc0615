"""Where PPO's training time goes, measured in one run on one machine: stepping the envs with
random actions (no network), PPO's rollout with agent compute overlapping emulation (two
half-batches stepped in turn, as baselines/ppo.py does), the same rollout without overlap (one
batch on as many emulator workers as the two halves have: choose, then step), and the jitted
update, with the game's evidence hyperparameters
(``GAME_HYPERPARAMETERS`` in baselines/evidence/run_evidence.py).  Writes JSON, a markdown table and a PNG.

    python benchmarks/ppo_rollout.py [--game Breakout] [--preset 3.1] [--network nips] [--repeats 3] [--out DIR]
"""

from __future__ import annotations

import argparse
import datetime
import json
import time
from pathlib import Path

import jax
import numpy as np

import stori_jax
from baselines import ppo
from baselines.networks import NETWORKS
from stori_jax.provenance import software
from baselines.evidence.run_evidence import EVIDENCE_HYPERPARAMETERS, GAME_HYPERPARAMETERS
from _checks import (options_in_name, output_directory, require_at_least_one,  # on sys.path
                     stori_game_and_preset)

RESULTS = Path(__file__).resolve().parent / "results"


def sequential_rollout(env, act_fn, params, obs, key, num_steps: int):
    """One batch: choose every env's action, then step them all (no overlap)."""
    for _ in range(num_steps):
        key, k = jax.random.split(key)
        action, _, _ = act_fn(params, obs, k)
        obs = env.step(action)[0]
    return jax.block_until_ready(obs)


def median_rate(fn, steps: int, repeats: int) -> float:
    rates = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        rates.append(steps / (time.perf_counter() - start))
    return float(np.median(rates))


def measure(config: ppo.PPOConfig, repeats: int) -> dict:
    from tqdm import tqdm

    with tqdm(total=4, desc="PPO stages", unit="stage") as bar:  # the four `done` calls
        return measure_stages(config, repeats, bar)


def measure_stages(config: ppo.PPOConfig, repeats: int, bar) -> dict:
    steps = config.batch_size

    def done(stage: str) -> None:
        bar.set_postfix_str(f"measured {stage}")
        bar.update()

    results = dict(env_only=float(np.median([ppo.env_only_sps(config, steps)
                                             for _ in range(repeats)])))
    done("env only")
    envs = ppo.make_envs(config)
    try:
        network = ppo.make_network(config, envs[0].num_actions)
        act_fn = jax.jit(lambda p, o, k: ppo.act(network, p, o, k))
        obs = [env.reset()[0] for env in envs]
        params = network.init(jax.random.PRNGKey(0), obs[0])
        optimizer = ppo.make_optimizer(config)
        opt_state = optimizer.init(params)
        update = ppo.make_update(network, optimizer, config)
        key = jax.random.PRNGKey(1)
        state = dict(obs=obs, key=key, rollout=None)

        def overlapped():
            rollout, state["obs"], state["key"] = ppo.collect(
                envs, act_fn, params, state["obs"], state["key"], config.num_steps, [], 0)
            state["rollout"] = jax.block_until_ready(rollout)

        overlapped()  # compile
        results["rollout_overlapped"] = median_rate(overlapped, steps, repeats)
        done("overlapped rollout")

        def one_update():
            out = update(params, opt_state, state["rollout"], jax.numpy.concatenate(
                state["obs"]), jax.random.PRNGKey(2))
            jax.block_until_ready(out)

        one_update()  # compile
        results["update_per_s"] = median_rate(one_update, steps, repeats)
        done("update")
    finally:
        for env in envs:
            env.close()
    # as many emulator workers as the two halves have together: the ratio is the overlap's
    workers = 2 * ppo.workers_per_half(config.num_envs // 2)
    with stori_jax.make(config.game, config.preset, num_envs=config.num_envs, seed=0,
                        obs="atari84", num_workers=workers, inline_envs=0) as env:
        obs, _ = env.reset()

        def run():
            sequential_rollout(env, act_fn, params, obs, key, config.num_steps)

        run()
        results["rollout_sequential"] = median_rate(run, steps, repeats)
        done("sequential rollout")
    rollout_s = steps / results["rollout_overlapped"]
    update_s = steps / results["update_per_s"]
    results["training_sps_model"] = steps / (rollout_s + update_s)
    return results


def stage_rates(r: dict) -> list[tuple[str, float]]:
    return [("env only (random actions, two halves)", r["env_only"]),
            ("PPO rollout, agent overlapping emulation", r["rollout_overlapped"]),
            ("PPO rollout, choose then step (no overlap)", r["rollout_sequential"]),
            ("PPO update alone (agent steps consumed/s)", r["update_per_s"]),
            ("training = rollout + update", r["training_sps_model"])]


def markdown(config: ppo.PPOConfig, r: dict) -> str:
    env_only, rows = r["env_only"], stage_rates(r)
    lines = [f"{config.game} {config.preset}, {config.num_envs} envs x {config.num_steps} steps, "
             f"network {config.network}, {config.update_epochs} epochs x "
             f"{config.num_minibatches} minibatches", "",
             "| stage | agent steps/s | / env only |", "|---|---|---|"]
    lines += [f"| {name} | {rate:.0f} | {rate / env_only:.2f} |" for name, rate in rows]
    lines.append(f"\nOverlap speed-up of the rollout: "
                 f"{r['rollout_overlapped'] / r['rollout_sequential']:.2f}x")
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--game", default="Breakout")
    parser.add_argument("--preset", default="3.1")
    parser.add_argument("--network", default="nips", choices=list(NETWORKS))
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=RESULTS, help="directory for the results")
    args = parser.parse_args(argv)
    require_at_least_one(parser, repeats=args.repeats)
    output_directory(parser, args.out)
    game, args.preset = stori_game_and_preset(parser, args.game, args.preset)
    config = ppo.PPOConfig(game=game, preset=args.preset,
                           **{**GAME_HYPERPARAMETERS.get(game, EVIDENCE_HYPERPARAMETERS),
                              "network": args.network})
    made_with = software()  # when the run starts
    results = measure(config, args.repeats)
    text = markdown(config, results)
    print(text)
    day = datetime.date.today().isoformat()
    stem = f"ppo-rollout-{day}-{game}-{args.preset}-{args.network}" + options_in_name(
        parser, args, {"repeats": "repeats"})  # a preset has dots: no with_suffix
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{stem}.json").write_text(json.dumps(dict(
        config={**vars(args), "out": str(args.out)},
        software=made_with, results=results), indent=1))
    (args.out / f"{stem}.md").write_text(text)
    plot(stage_rates(results), args.out / f"{stem}.png", title=text.splitlines()[0])
    print(f"wrote {args.out / stem}.json, .md and .png")


def plot(rows: list[tuple[str, float]], path: Path, title: str,
         xlabel: str = "agent steps / s") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3))
    names, rates = zip(*rows)
    ax.barh(range(len(rows)), rates, color="tab:blue")
    ax.set_yticks(range(len(rows)), names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel(xlabel)
    ax.set_title(title, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
