"""A rollout of a JAX policy two ways, in one run on one machine: ``stori_jax.rollout`` (a
Python loop: the jitted policy, then ``env.step``, every step) and one compiled
``jax.lax.scan`` over ``env.xla()``'s step with the policy inside it.  Both give the same
trajectory (tests/test_env_xla.py); this measures what the compiled loop saves.  Writes JSON, a
markdown table and a PNG.

    python benchmarks/xla_rollout.py [--game Breakout] [--preset 3.1] [--sizes 8 32]
                                     [--steps 128] [--repeats 3] [--out DIR]
"""

from __future__ import annotations

import argparse
import datetime
import json
from pathlib import Path

import jax
import jax.numpy as jnp
from tqdm import tqdm

import stori_jax
from baselines import ppo
from stori_jax.provenance import software
from _checks import (fits_in_memory, options_in_name, output_directory,  # on sys.path
                     require_at_least_one, stori_game_and_preset)
from ppo_rollout import median_rate, plot

RESULTS = Path(__file__).resolve().parent / "results"


def measure(game: str, preset: str, num_envs: int, steps: int, repeats: int) -> dict:
    with stori_jax.make(game, preset, num_envs=num_envs, seed=0) as env:
        network = ppo.make_network(ppo.PPOConfig(network="nips"), env.num_actions)
        obs, _ = env.reset()
        params = network.init(jax.random.PRNGKey(0), obs)

        def policy(params, obs, key):
            return ppo.act(network, params, obs, key)[0]

        state = dict(obs=obs)

        def python_loop():  # continues from the last observation, as the compiled loop does
            traj = stori_jax.rollout(env, policy, params, jax.random.PRNGKey(1), steps,
                                     obs=state["obs"])
            state["obs"] = jax.block_until_ready(traj).last_obs

        python_loop()  # compile
        python = median_rate(python_loop, steps * num_envs, repeats)

        obs, _ = env.reset()
        handle, step = env.xla()

        def body(carry, key):
            handle, obs = carry
            actions = policy(params, obs, key)
            handle, out = step(handle, actions)
            return (handle, out[0]), (obs, actions) + out[1:]

        scanned = jax.jit(lambda carry, keys: jax.lax.scan(body, carry, keys))
        scan_state = dict(carry=(handle, jnp.asarray(obs)))  # the env was reset: start afresh

        def compiled_loop():
            keys = jax.random.split(jax.random.PRNGKey(1), steps)
            scan_state["carry"], traj = scanned(scan_state["carry"], keys)
            jax.block_until_ready(traj)

        compiled_loop()  # compile
        compiled = median_rate(compiled_loop, steps * num_envs, repeats)
    return dict(num_envs=num_envs, python_loop=python, compiled_scan=compiled,
                ratio=compiled / python)


def markdown(game: str, preset: str, steps: int, rows: list[dict]) -> str:
    lines = [f"{game} {preset}, atari84, Mnih-2013 policy, {steps} steps a rollout; agent "
             "steps/s summed over the batch", "",
             "| B | stori_jax.rollout (Python loop) | lax.scan over env.xla() | ratio |",
             "|---|---|---|---|"]
    lines += [f"| {r['num_envs']} | {r['python_loop']:.0f} | {r['compiled_scan']:.0f} | "
              f"{r['ratio']:.2f} |" for r in rows]
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--game", default="Breakout", help="a STORI game (default Breakout)")
    parser.add_argument("--preset", default="3.1", help="its preset (default 3.1)")
    parser.add_argument("--sizes", type=int, nargs="+", default=[8, 32],
                        help="batch sizes B (default 8 32)")
    parser.add_argument("--steps", type=int, default=128,
                        help="agent steps per timed rollout (default 128)")
    parser.add_argument("--repeats", type=int, default=3,
                        help="timed rollouts per B and way, the median kept (default 3)")
    parser.add_argument("--out", type=Path, default=RESULTS, help="directory for the results")
    args = parser.parse_args(argv)
    require_at_least_one(parser, sizes=args.sizes, steps=args.steps, repeats=args.repeats)
    fits_in_memory(parser, "--sizes", args.sizes)
    output_directory(parser, args.out)
    args.game, args.preset = stori_game_and_preset(parser, args.game, args.preset)
    made_with = software()  # when the run starts
    rows = [measure(args.game, args.preset, b, args.steps, args.repeats)
            for b in tqdm(args.sizes, desc="batch sizes")]
    text = markdown(args.game, args.preset, args.steps, rows)
    print(text)
    day = datetime.date.today().isoformat()
    stem = f"xla-rollout-{day}-{args.game}-{args.preset}" + options_in_name(  # dots: no
        parser, args, {"sizes": "B", "steps": "steps", "repeats": "repeats"})  # with_suffix
    path = {ext: args.out / f"{stem}.{ext}" for ext in ("json", "md", "png")}
    args.out.mkdir(parents=True, exist_ok=True)
    path["json"].write_text(json.dumps(dict(
        config={**vars(args), "out": str(args.out)},
        software=made_with, results=rows), indent=1))
    path["md"].write_text(text)
    bars = [(f"B={r['num_envs']}, {name}", r[key]) for r in rows
            for name, key in (("Python loop", "python_loop"), ("lax.scan over xla", "compiled_scan"))]
    plot(bars, path["png"], title=text.splitlines()[0])
    print(f"wrote {args.out / stem}.json, .md and .png")


if __name__ == "__main__":
    main()
