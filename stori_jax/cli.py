"""The ``stori-jax`` command line: ``run`` a preset with a random policy, ``list`` what exists."""

from __future__ import annotations

import argparse
import sys
import time


def _cmd_list(args) -> int:
    from stori_jax import STORI_GAMES, describe_preset, get_game, list_presets
    from stori_jax.functional.masks import CROP_REGIONS, TORCH_MODE

    print("Presets (game, name: definition):")
    for game, name in list_presets():
        print(f"  {game:<10} {name:<5} {describe_preset(game, name)}")
    print("\nCrop modes (every game): " + ", ".join(
        [f"{m} {'left right top bottom'.split()[m - 1]} half" for m in CROP_REGIONS]
        + [f"{TORCH_MODE} torch (radius 75)"]))
    for game in STORI_GAMES:
        spec = get_game(game)
        print(f"\n{game} ({spec.num_actions} actions)")
        for title, table in (("blackout", spec.blackout_modes), ("ram", spec.ram_obs_modes),
                             ("event (2.1)", spec.event_modes)):
            print(f"  {title} modes:")
            for mode, entry in table.items():
                print(f"    {mode:>2}  {entry.name}")
        print("  labels (type 0): " + ", ".join(spec.labels))
    return 0


def _cmd_run(args) -> int:
    import jax
    import numpy as np
    from tqdm import tqdm

    import stori_jax

    env = stori_jax.make(args.game, args.preset, num_envs=args.num_envs, seed=args.seed,
                         num_workers=args.num_workers, obs=args.obs,
                         granularity=args.granularity)
    print(f"{env}")
    key = jax.random.PRNGKey(args.seed)
    episodes, returns = 0, []
    events = corrupted = switches = masked = 0
    with env:
        obs, info = env.reset()
        previous_concept = np.zeros(env.num_envs, np.int32)
        start = time.perf_counter()
        for _ in tqdm(range(args.steps), desc=f"{args.game} {args.preset or '3.1'}",
                      unit="step", disable=args.quiet):
            key, k = jax.random.split(key)
            actions = jax.random.randint(k, (env.num_envs,), 0, env.num_actions)
            obs, reward, terminated, truncated, info = env.step(actions)
            done = np.asarray(terminated | truncated)
            episodes += int(done.sum())
            returns.extend(np.asarray(info["episode_return"])[done].tolist())
            events += int(np.asarray(info["event_fired"]).sum())
            corrupted += int(np.asarray(info["action_corrupted"]).sum())
            masked += int(np.asarray(info["obs_masked"]).sum())
            concept = np.asarray(info["concept"])
            switches += int((concept != previous_concept).sum())
            previous_concept = np.where(done, 0, concept)
        elapsed = time.perf_counter() - start
    env_steps = args.steps * env.num_envs
    mean_return = f"{np.mean(returns):.2f}" if returns else "n/a (no episode finished)"
    print(f"episodes finished : {episodes}")
    print(f"mean return       : {mean_return}")
    print(f"events fired      : {events}")
    print(f"corrupted actions : {corrupted}")
    print(f"concept switches  : {switches}")
    print(f"masked obs        : {masked} of {env_steps}")
    print(f"env steps / s     : {env_steps / elapsed:.0f} ({env_steps} steps in {elapsed:.1f} s, "
          "including compilation)")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="stori-jax", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="print games, presets and modes")
    run = sub.add_parser("run", help="run a random policy on a preset and print a summary")
    run.add_argument("game", help="Breakout, Boxing, Gopher, BankHeist (or any ale-py game)")
    run.add_argument("preset", nargs="?", default=None, help="paper preset, e.g. 2.1 or 3.2A")
    run.add_argument("--steps", type=int, default=500, help="agent steps per env")
    run.add_argument("--num-envs", type=int, default=8)
    run.add_argument("--num-workers", type=int, default=None)
    run.add_argument("--seed", type=int, default=0)
    run.add_argument("--obs", default=None, choices=["raw", "atari84", "dreamer64", "ram"])
    run.add_argument("--granularity", default=None, choices=["frame", "step"])
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.command == "list":
            return _cmd_list(args)
        if args.steps < 1:
            raise ValueError(f"--steps must be >= 1, got {args.steps}")
        return _cmd_run(args)
    except ValueError as e:
        print(f"stori-jax: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("stori-jax: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
