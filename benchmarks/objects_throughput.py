"""The object modes' speed, in one run on one machine: per game, ``obs="objects"`` beside
``obs="raw"`` (3.1), and hidden objects (ObservationMask "objects", p = 1) beside the game's
3.1, both ``atari84``.  The rows are measured in turns (every row once, then again, ...), the
median kept, so a slow moment of the shared machine touches them all.  Writes JSON, a markdown
table and a PNG.

    python benchmarks/objects_throughput.py [--games Breakout Pong] [--batch 32]
                                            [--steps 100] [--repeats 3] [--out DIR]
"""

from __future__ import annotations

import argparse
import datetime
import json
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

import stori_jax
import stori_jax.objects
from stori_jax import Config, ObservationMask
from stori_jax.provenance import software
from _checks import (fits_in_memory, options_in_name, output_directory,  # on sys.path
                     require_at_least_one)
from ppo_rollout import plot

RESULTS = Path(__file__).resolve().parent / "results"
HIDDEN = {"Breakout": ("Ball",), "Pong": ("Ball",)}  # the class each game's row hides


def variants(game: str) -> dict[str, dict]:
    """Row name -> make() keywords of the rows of ``game``."""
    classes = HIDDEN.get(game, (stori_jax.objects.objects_layout(game)[0][0],))
    hide = Config(observation=ObservationMask("objects", 1, 1.0, classes=classes))
    return {"3.1 raw": dict(obs="raw"), "objects": dict(obs="objects"),
            "3.1 atari84": dict(obs="atari84"),
            f"hide {'+'.join(classes)} atari84": dict(obs="atari84", config=hide)}


def timed(env, steps: int) -> float:
    """Agent steps per second (summed over the batch) of ``steps`` random steps."""
    rng = np.random.default_rng(0)
    actions = [rng.integers(0, env.num_actions, env.num_envs) for _ in range(steps)]
    start = time.perf_counter()
    for a in actions:
        out = env.step(a)
    out[0].block_until_ready()
    return steps * env.num_envs / (time.perf_counter() - start)


def measure(game: str, batch: int, steps: int, repeats: int) -> dict[str, float]:
    envs = {name: stori_jax.make(game, num_envs=batch, seed=0, **kw)
            for name, kw in variants(game).items()}
    try:
        for env in envs.values():
            env.reset()
            timed(env, 5)  # compile
        rates = {name: [] for name in envs}
        for _ in tqdm(range(repeats), desc=game, leave=False):
            for name, env in envs.items():
                rates[name].append(timed(env, steps))
        return {name: float(np.median(r)) for name, r in rates.items()}
    finally:
        for env in envs.values():
            env.close()


def markdown(batch: int, steps: int, results: dict) -> str:
    lines = [f"B = {batch}, frame skip 4, {steps} random steps a turn; agent steps/s summed "
             "over the batch (median of the turns)", "",
             "| game | row | steps/s | ratio | to |", "|---|---|---|---|---|"]
    for game, rates in results.items():
        names = list(rates)
        for name, base in zip(names, [None, names[0], None, names[2]]):
            ratio = f"{rates[name] / rates[base]:.2f}" if base else ""
            lines.append(f"| {game} | {name} | {rates[name]:.0f} | {ratio} | {base or ''} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--games", nargs="+", default=["Breakout", "Pong"],
                        help="games with object tables (default Breakout Pong)")
    parser.add_argument("--batch", type=int, default=32, help="envs per batch (default 32)")
    parser.add_argument("--steps", type=int, default=100, help="agent steps a turn (default 100)")
    parser.add_argument("--repeats", type=int, default=3, help="turns, the median kept (default 3)")
    parser.add_argument("--out", type=Path, default=RESULTS, help="directory for the results")
    args = parser.parse_args(argv)
    require_at_least_one(parser, batch=args.batch, steps=args.steps, repeats=args.repeats)
    fits_in_memory(parser, "--batch", [args.batch])
    output_directory(parser, args.out)
    covered = stori_jax.objects.covered_games()
    bad = [g for g in args.games if g not in covered]
    if bad:
        parser.error(f"--games: {bad[0]!r} has no object table; allowed: {list(covered)}")
    made_with = software()
    results = {game: measure(game, args.batch, args.steps, args.repeats) for game in args.games}
    text = markdown(args.batch, args.steps, results)
    print(text)
    stem = f"objects-{datetime.date.today().isoformat()}" + options_in_name(
        parser, args, {"games": "", "batch": "B", "steps": "steps", "repeats": "repeats"})
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{stem}.json").write_text(json.dumps(dict(
        config={**vars(args), "out": str(args.out)}, software=made_with, results=results),
        indent=1))
    (args.out / f"{stem}.md").write_text(text)
    plot([(f"{game} {name}", rate) for game, rates in results.items()
          for name, rate in rates.items()], args.out / f"{stem}.png", title=text.splitlines()[0])
    print(f"wrote {args.out / stem}.json, .md and .png")


if __name__ == "__main__":
    main()
