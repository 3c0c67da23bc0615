"""PPO's defaults (CleanRL's Atari PPO: Nature CNN, 8 envs x 128 steps, 4 epochs x 4 minibatches)
on Boxing 3.1 for a million agent steps, seeds 0, 7 and 13: does the agent learn Boxing at all,
and when?  Each run trains in stages; the checkpoint at the end of each stage (102,400, 256,000,
512,000 and 768,000 agent steps) is copied aside and evaluated by the paper's protocol (100
episodes, sampled policy, eval seed = seed + 10000, 20 envs) as the final one is, so the
evaluations trace the onset of learning.  A stage stops the run with a checkpoint, as an
interruption would, and the next resumes it exactly as if it had never stopped, so the script
can be stopped and started again (on this 2-core CPU a seed takes about 80 min).

    python baselines/run_long.py [--seeds 0 7 13] [--out DIR]

Writes DIR/runs/seed<S>/ (config, logs, summary, eval-sampled.json; checkpoint.pkl is not
committed), DIR/by-step/<agent steps>/seed<S>/eval-sampled.json, DIR/onset.md and onset.png (the
evaluations by agent steps, beside the random policy's and the paper's agents' at 100k), and
DIR/table.md, table.json and curves-Boxing.png (default DIR: baselines/results/boxing-1M).
"""

from __future__ import annotations

import argparse
import json
import shutil
from collections import defaultdict
from pathlib import Path

import numpy as np

BASELINES = Path(__file__).resolve().parent
REPOSITORY = BASELINES.parent
OUT = BASELINES / "results" / "boxing-1M"
GAME, PRESET, TOTAL_STEPS = "Boxing", "3.1", 1_000_000
SEEDS = (0, 7, 13)
STAGES = (100, 250, 500, 750)  # iterations (x 1024 agent steps) whose checkpoints are evaluated
EVAL_EPISODES = 100


def _named(path: Path) -> str:
    """``path`` as the result files name it: from the repository root where it lies inside."""
    path = Path(path).resolve()
    return str(path.relative_to(REPOSITORY)) if path.is_relative_to(REPOSITORY) else str(path)


def evaluate_once(checkpoint: Path, out_dir: Path, *, episodes: int, num_envs: int,
                  progress: bool) -> dict | None:
    """Evaluate ``checkpoint`` (sampled policy) into ``out_dir``/eval-sampled.json unless that
    file exists; returns the new result, or None when there was one already."""
    from baselines.evaluate import evaluate, result_path, write_result
    from baselines.ppo import load_checkpoint

    if result_path(out_dir, "sampled").exists():
        return None
    config = load_checkpoint(checkpoint)["config"]
    result = evaluate(config["game"], config["preset"], policy="sampled", episodes=episodes,
                      num_envs=num_envs, checkpoint=checkpoint, progress=progress)
    result["checkpoint"] = _named(checkpoint)
    write_result(result, out_dir)
    return result


def train_in_stages(config, run: Path, by_step: Path, stages=STAGES, *,
                    episodes: int = EVAL_EPISODES, num_envs: int | None = None,
                    progress: bool = True) -> None:
    """Train ``config`` into ``run``, stopping after each of ``stages`` (iterations) to copy the
    checkpoint to ``by_step``/<agent steps>/seed<S>/ and evaluate it there, then to the end and
    evaluate the final checkpoint in ``run``.  Stages and evaluations already done are skipped;
    a stage whose checkpoint the run has trained past (the run went on without this script)
    is refused, since it can no longer be evaluated."""
    from baselines.evaluate import EVAL_NUM_ENVS, result_path
    from baselines.ppo import load_checkpoint, train

    num_envs = EVAL_NUM_ENVS if num_envs is None else num_envs
    bad = [s for s in stages if not 0 < s < config.num_iterations]
    if bad or list(stages) != sorted(set(stages)):
        raise ValueError(f"stages must be increasing iterations between 1 and "
                         f"{config.num_iterations - 1} (the run's last but one), got "
                         f"{list(stages)}")
    checkpoint = run / "checkpoint.pkl"
    for stage in stages:
        aside = by_step / str(stage * config.batch_size) / f"seed{config.seed}"
        if result_path(aside, "sampled").exists():
            continue
        if not (aside / "checkpoint.pkl").exists():
            done = load_checkpoint(checkpoint)["iteration"] if checkpoint.exists() else 0
            if done > stage:
                raise ValueError(f"{run} has trained {done} iterations, past the stage at "
                                 f"iteration {stage} whose checkpoint {aside} does not hold; "
                                 "start the run again in an empty directory")
            train(config, run, resume=checkpoint.exists(), progress=progress,
                  stop_after=stage)
            aside.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(checkpoint, aside / "checkpoint.tmp")
            (aside / "checkpoint.tmp").replace(aside / "checkpoint.pkl")
        evaluate_once(aside / "checkpoint.pkl", aside, episodes=episodes, num_envs=num_envs,
                      progress=progress)
    if not (run / "summary.json").exists():
        train(config, run, resume=checkpoint.exists(), progress=progress)
    evaluate_once(checkpoint, run, episodes=episodes, num_envs=num_envs, progress=progress)


def evaluations_by_step(out: Path) -> dict[int, dict[int, dict]]:
    """Every PPO evaluation below ``out``, as {agent steps its checkpoint had trained: {training
    seed: result}}; two evaluations of one checkpoint's steps and seed are refused."""
    found = defaultdict(dict)
    for path in sorted(Path(out).rglob("eval-sampled.json")):
        result = json.loads(path.read_text())
        steps, seed = result.get("trained_agent_steps"), result["train_seed"]
        if not isinstance(steps, int):
            raise ValueError(f"{path} does not record how far its checkpoint had trained "
                             "(trained_agent_steps)")
        if seed in found[steps]:
            raise ValueError(f"{path}: a second evaluation of seed {seed} at {steps} agent "
                             f"steps (the other: {found[steps][seed]['path']})")
        found[steps][seed] = dict(result, path=str(path))
    return dict(sorted(found.items()))


def random_evaluations(seeds) -> dict[int, dict]:
    """The random policy's recorded evaluations on Boxing 3.1 (run_evidence.py's), by seed."""
    from baselines.run_evidence import run_dir

    found = {}
    for seed in seeds:
        path = run_dir(GAME, PRESET, "random", seed) / "eval-random.json"
        if path.exists():
            found[seed] = json.loads(path.read_text())
    return found


def _over_seeds(means: list[float]) -> str:
    if len(means) < 2:
        return "-"
    return f"{np.mean(means):.2f} ± {np.std(means, ddof=1):.2f}"


def onset_table(by_step: dict[int, dict[int, dict]], random: dict[int, dict]) -> str:
    """Markdown: a row per agent steps trained, a column per seed (the mean return of its 100
    episodes ± their std), then the mean ± std of the seeds' means; the random policy last."""
    seeds = sorted({seed for results in by_step.values() for seed in results} | set(random))
    lines = ["| agent steps | " + " | ".join(f"seed {s}" for s in seeds)
             + " | mean ± std over seeds |", "|---" * (len(seeds) + 2) + "|"]
    rows = [(f"{steps:,}", results) for steps, results in by_step.items()]
    for label, results in rows + [("random policy", random)]:
        cells = [f"{results[s]['mean_return']:.2f} ± {results[s]['std_return']:.2f}"
                 if s in results else "-" for s in seeds]
        means = [results[s]["mean_return"] for s in seeds if s in results]
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {_over_seeds(means)} |")
    return "\n".join(lines) + "\n"


def plot_onset(by_step: dict[int, dict[int, dict]], random: dict[int, dict], path: Path) -> Path:
    """Each seed's evaluation return by agent steps trained, their mean, the random policy's
    level and the paper's DreamerV3 and STORM after 100k agent steps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    from baselines.table import PAPER_AGENT_STEPS, PAPER_RESULTS, steps_label

    steps = np.array(list(by_step))
    seeds = sorted({seed for results in by_step.values() for seed in results})
    fig, ax = plt.subplots(figsize=(6, 3.8))
    for i, seed in enumerate(seeds):
        points = [(n, r[seed]["mean_return"]) for n, r in by_step.items() if seed in r]
        ax.plot(*zip(*points), "o-", lw=0.8, alpha=0.6, color=f"C{i}", label=f"seed {seed}")
    complete = [n for n in steps if all(s in by_step[n] for s in seeds)]
    ax.plot(complete, [np.mean([by_step[n][s]["mean_return"] for s in seeds]) for n in complete],
            "k-", lw=1.8, label="mean over seeds")
    if random:
        ax.axhline(np.mean([r["mean_return"] for r in random.values()]), color="grey", ls="--",
                   label="random policy")
    dreamer, _, storm, _ = PAPER_RESULTS[(GAME, PRESET)]
    ax.plot([PAPER_AGENT_STEPS], [dreamer], "s", color="C3", label="DreamerV3 at 100k (paper)")
    ax.plot([PAPER_AGENT_STEPS], [storm], "^", color="C4", label="STORM at 100k (paper)")
    ax.set_xlabel("agent steps trained")
    ax.set_xlim(0, max(steps.max(), PAPER_AGENT_STEPS) * 1.05)
    ax.xaxis.set_major_formatter(FuncFormatter(steps_label))
    ax.set_ylabel("evaluation return (100 episodes)")
    ax.set_title(f"PPO (CleanRL's defaults) on {GAME} {PRESET}")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_onset(out: Path) -> str:
    """``out``/onset.md and onset.png from the evaluations below ``out``; returns the table."""
    by_step = evaluations_by_step(out)
    random = random_evaluations(sorted({s for r in by_step.values() for s in r}))
    text = onset_table(by_step, random)
    (out / "onset.md").write_text(text)
    plot_onset(by_step, random, out / "onset.png")
    return text


def main() -> None:
    from baselines.ppo import PPOConfig
    from baselines.table import build_table

    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", nargs="+", type=int, choices=SEEDS, default=SEEDS,
                        help="train and evaluate only these seeds (default: all)")
    parser.add_argument("--out", type=Path, default=OUT,
                        help=f"results directory (default {_named(OUT)})")
    args = parser.parse_args()
    for seed in args.seeds:
        config = PPOConfig(game=GAME, preset=PRESET, seed=seed, total_steps=TOTAL_STEPS)
        train_in_stages(config, args.out / "runs" / f"seed{seed}", args.out / "by-step")
    text, _ = build_table(args.out / "runs", args.out)
    print(text + "\n" + write_onset(args.out))


if __name__ == "__main__":
    main()
