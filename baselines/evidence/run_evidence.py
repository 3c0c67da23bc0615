"""The runs behind baselines/results/: PPO at 100k agent steps, seeds 0, 7 and 13, on Breakout
and Boxing under 3.1 and two perturbed presets each, then the paper's evaluation protocol
(100 episodes, eval seeds apart from training seeds) for PPO and the random policy, and the
table.  Runs already finished are skipped, so the script can be stopped and started again.

    python baselines/evidence/run_evidence.py [--stage train|eval|table|all] [--only Boxing-3.1 ...]
                                     [--seeds 0 7 13]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parents[1] / "results"
RUNS = [("Breakout", "3.1"), ("Breakout", "1"), ("Breakout", "3.2C"),
        ("Boxing", "3.1"), ("Boxing", "1"), ("Boxing", "3.2B")]
SEEDS = (0, 7, 13)
# This 2-core CPU trains the Nature CNN at ~20 GFLOP/s: 4 epochs of it over 100k steps take
# ~9 min per run.  The recorded runs use the 3x cheaper Mnih-2013 torso, 16 envs x 64 steps.
# Breakout: 2 epochs of 8 minibatches (as many gradient steps per iteration as the defaults).
# Boxing: that light update leaves the policy uniform after 100k steps (entropy ln 18), and so
# did 4x the learning rate, 4 epochs, or gamma 0.9 (results/boxing-probes/README.md).  10 epochs
# of 16 minibatches (10x the gradient steps, on minibatches of 64; 6.3-11 min a run) did best on
# seed 0, the most this CPU affords for 9 runs.  On all three seeds, random shifts
# (augment_shift=4), gamma 0.95, the Nature-CNN defaults and the Nature CNN under this update
# did no better, nor on seed 13 did action_head="factored" (same README).
EVIDENCE_HYPERPARAMETERS = dict(network="nips", update_epochs=2, num_minibatches=8,
                                num_envs=16, num_steps=64, total_steps=100_000)
GAME_HYPERPARAMETERS = {"Breakout": EVIDENCE_HYPERPARAMETERS,
                        "Boxing": dict(EVIDENCE_HYPERPARAMETERS, update_epochs=10,
                                       num_minibatches=16)}


def results_name(path: Path, root: Path = RESULTS) -> str:
    """``path`` as recorded results name a checkpoint: from ``root`` where it lies inside (the
    name then holds in any checkout), else in full."""
    path = Path(path).resolve()
    return str(path.relative_to(root)) if path.is_relative_to(root) else str(path)


def run_dir(game: str, preset: str, agent: str, seed: int) -> Path:
    from baselines.commands import run_dir as layout

    return layout(RESULTS / "runs", game, preset, agent, seed)


def stage_train(runs=RUNS, seeds=SEEDS) -> None:
    from baselines.ppo import PPOConfig, env_only_sps, train

    for seed in seeds:
        for game, preset in runs:
            out = run_dir(game, preset, "ppo", seed)
            if (out / "summary.json").exists():
                continue
            config = PPOConfig(game=game, preset=preset, seed=seed,
                               **GAME_HYPERPARAMETERS[game])
            train(config, out, resume=(out / "checkpoint.pkl").exists())
            summary = json.loads((out / "summary.json").read_text())
            summary["env_only_sps"] = env_only_sps(config, agent_steps=4096)
            summary["train_to_env_only"] = summary["train_sps"] / summary["env_only_sps"]
            (out / "summary.json").write_text(json.dumps(summary, indent=1))
            print(f"{game} {preset} seed {seed}: {summary['train_sps']:.0f} train SPS, "
                  f"{summary['env_only_sps']:.0f} env-only SPS", flush=True)


EVAL_EPISODES = 100


def stage_eval(runs=RUNS, seeds=SEEDS) -> None:
    """Sampled-policy evaluation of every PPO run, and the random policy, same protocol."""
    from baselines.evaluate import EVAL_NUM_ENVS, evaluate, write_result

    for seed in seeds:
        for game, preset in runs:
            jobs = [("ppo", "sampled", run_dir(game, preset, "ppo", seed) / "checkpoint.pkl"),
                    ("random", "random", None)]
            for agent, policy, checkpoint in jobs:
                out = run_dir(game, preset, agent, seed)
                if (out / f"eval-{policy}.json").exists() or (
                        checkpoint is not None and not checkpoint.exists()):
                    continue
                result = evaluate(game, preset, policy=policy, episodes=EVAL_EPISODES,
                                  seed=seed, num_envs=EVAL_NUM_ENVS, checkpoint=checkpoint)
                if checkpoint is not None:  # file the checkpoint as the repository names it
                    result["checkpoint"] = results_name(checkpoint)
                write_result(result, out)
                print(f"{game} {preset} seed {seed} {policy}: {result['mean_return']:.2f}",
                      flush=True)


def speed_table() -> str:
    """Training SPS beside the SPS of the same envs stepped without learning, per preset
    (median over seeds; both measured in the same process, one after the other)."""
    lines = ["| game | preset | training SPS | env-only SPS | ratio | seeds |",
             "|---|---|---|---|---|---|"]
    for game, preset in RUNS:
        summaries = [json.loads(p.read_text()) for seed in SEEDS
                     if (p := run_dir(game, preset, "ppo", seed) / "summary.json").exists()]
        summaries = [s for s in summaries if "env_only_sps" in s]
        if not summaries:
            continue
        train = float(np.median([s["train_sps"] for s in summaries]))
        env_only = float(np.median([s["env_only_sps"] for s in summaries]))
        ratio = float(np.median([s["train_to_env_only"] for s in summaries]))
        lines.append(f"| {game} | {preset} | {train:.0f} | {env_only:.0f} | {ratio:.2f} | "
                     f"{len(summaries)} |")
    return "\n".join(lines) + "\n"


def stage_table() -> None:
    from baselines.table import build_table

    text, _ = build_table(RESULTS / "runs", RESULTS)
    speed = speed_table()
    (RESULTS / "speed.md").write_text(speed)
    print(text + "\n" + speed)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--stage", default="all", choices=["train", "eval", "table", "all"])
    parser.add_argument("--only", nargs="+", metavar="GAME-PRESET",
                        help="train and evaluate only these runs, e.g. Boxing-3.1 (default: all)")
    parser.add_argument("--seeds", nargs="+", type=int, choices=SEEDS, default=SEEDS,
                        help="train and evaluate only these seeds (default: all)")
    args = parser.parse_args()
    names = {f"{game}-{preset}": (game, preset) for game, preset in RUNS}
    unknown = sorted(set(args.only or ()) - set(names))
    if unknown:
        parser.error(f"--only: unknown runs {unknown}; the runs are {list(names)}")
    runs = [names[n] for n in args.only] if args.only else RUNS
    if args.stage in ("train", "all"):
        stage_train(runs, args.seeds)
    if args.stage in ("eval", "all"):
        stage_eval(runs, args.seeds)
    if args.stage in ("table", "all"):
        stage_table()


if __name__ == "__main__":
    main()
