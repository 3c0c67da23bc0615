"""Cost per step of each JAX-side stage, in ms, on whatever device JAX uses here.

    python benchmarks/jax_stages.py                 # B = 32 (this machine's CPU)
    python benchmarks/jax_stages.py --sizes 256 1024  # e.g. on a GPU host

Stages, on real-sized inputs (B environments, two 210x160x3 screens each):
copy of the two screens into JAX, per-frame blackout mask, torch mask, max-pool, luma + area
resize to 84x84, frame stack, mask + max-pool + atari84 in one jit, and `before_step`
(the draws) of a type-1 preset.  Writes benchmarks/results/jax-stages-<date>-<host>.{json,md}.
"""

from __future__ import annotations

import argparse
import datetime
import json
import socket
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from _checks import (fits_in_memory, options_in_name, output_directory,  # on sys.path
                     require_at_least_one)

HERE = Path(__file__).resolve().parent


def timed(fn, *args, repeats=30):
    jax.block_until_ready(fn(*args))
    best = []
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(repeats):
            out = fn(*args)
        jax.block_until_ready(out)
        best.append((time.perf_counter() - t0) / repeats * 1e3)
    return float(np.median(best))


def stages(b: int) -> dict:
    """Each stage's name and a thunk that times it (ms per call) at batch size ``b``."""
    import stori_jax
    from stori_jax import functional as F
    from stori_jax.core import before_step, initial_state
    from stori_jax.plan import compile_plan

    rng = np.random.default_rng(0)
    host = rng.integers(0, 256, (2, b, 210, 160, 3), dtype=np.uint8)
    frames = jnp.asarray(host)
    keys = F.env_keys(jax.random.PRNGKey(0), b)
    hidden, fill = F.region_mask(stori_jax.get_game("Breakout").blackout_modes[10].regions)
    pair = jnp.moveaxis(frames, 0, 1)

    def blackout(keys, pair):
        apply, _ = F.draw_mask_decisions(keys, prob=1.0, per_frame=True, torch=False)
        return F.apply_masks(pair, apply, hidden=hidden, fill=fill)

    def torch(keys, pair):
        apply, centres = F.draw_mask_decisions(keys, prob=1.0, per_frame=True, torch=True)
        return F.apply_masks(pair, apply, centres=centres)

    def mask_pool_atari84(keys, pair):
        return F.atari84_frame(F.max_pool(blackout(keys, pair)))

    screen = jnp.maximum(frames[0], frames[1])
    frame84 = F.atari84_frame(screen)
    stack = F.reset_stack(frame84)
    new_episode = jnp.zeros(b, bool)
    game = stori_jax.get_game("Breakout")
    plan = compile_plan(stori_jax.preset("Breakout", "1"), game, num_envs=b, frame_skip=4,
                        obs="atari84", noop_max=0)
    state = initial_state(plan, 0)
    actions = jnp.zeros(b, jnp.int32)
    return {
        "copy two screens into JAX": lambda: timed(lambda h: jnp.asarray(h), host),
        "blackout mask (per frame)": lambda: timed(jax.jit(blackout), keys, pair),
        "torch mask (per frame)": lambda: timed(jax.jit(torch), keys, pair),
        "max-pool": lambda: timed(jax.jit(F.max_pool), pair),
        "luma + area resize 84x84": lambda: timed(jax.jit(F.atari84_frame), screen),
        "frame stack": lambda: timed(jax.jit(F.push_frame), stack, frame84, new_episode),
        "mask + max-pool + atari84": lambda: timed(jax.jit(mask_pool_atari84), keys, pair),
        "before_step draws (type 1)": lambda: timed(lambda s, a: before_step(plan, s, a),
                                                    state, actions),
    }


def measure(sizes: list[int]) -> dict[int, dict[str, float]]:
    """Every stage at every batch size, with a progress bar over the (size, stage) pairs."""
    from tqdm import tqdm

    results = {}
    with tqdm(desc="JAX stages", unit="stage") as bar:
        for b in sizes:
            results[b] = {}
            runs = stages(b)
            bar.total = len(sizes) * len(runs)
            for name, run in runs.items():
                bar.set_postfix_str(f"B={b} {name}")
                results[b][name] = run()
                bar.update()
    return results


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[32],
                        help="batch sizes B (default 32)")
    parser.add_argument("--out", type=Path, default=HERE / "results",
                        help="directory for the results (default benchmarks/results)")
    args = parser.parse_args(argv)
    require_at_least_one(parser, sizes=args.sizes)
    fits_in_memory(parser, "--sizes", args.sizes)
    output_directory(parser, args.out)
    from stori_jax.provenance import software

    device = str(jax.devices()[0])
    meta = dict(date=datetime.date.today().isoformat(), host=socket.gethostname(),
                device=device, software=software())
    results = measure(args.sizes)
    lines = [f"# JAX-side cost per step (ms), {meta['date']} on {meta['host']} ({device})", "",
             "| stage | " + " | ".join(f"B = {b}" for b in args.sizes) + " |",
             "|---|" + "---|" * len(args.sizes)]
    for stage in results[args.sizes[0]]:
        lines.append(f"| {stage} | " + " | ".join(f"{results[b][stage]:.3f}"
                                                  for b in args.sizes) + " |")
    table = "\n".join(lines) + "\n"
    args.out.mkdir(parents=True, exist_ok=True)
    stem = args.out / (f"jax-stages-{meta['date']}-{meta['host']}"
                       + options_in_name(parser, args, {"sizes": "B"}))
    Path(f"{stem}.json").write_text(json.dumps(dict(meta=meta, results=results), indent=1))
    Path(f"{stem}.md").write_text(table)
    print(table)
    print(f"wrote {stem}.json and .md")


if __name__ == "__main__":
    main()
