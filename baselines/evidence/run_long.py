"""PPO's defaults (CleanRL's Atari PPO: Nature CNN, 8 envs x 128 steps, 4 epochs x 4 minibatches)
on Boxing 3.1 for a million agent steps, seeds 0, 7 and 13: does the agent learn Boxing at all,
and when?  Each run trains in stages (STAGES); the checkpoint at the end of each stage is copied
aside and evaluated by the paper's protocol (run_evidence.py's: sampled policy, eval seed =
seed + 10000) as the final one is, so the evaluations trace the onset of learning.  A stage stops
the run with a checkpoint, as an interruption would, and the next resumes it exactly as if it
had never stopped, so the script can be stopped and started again (on this 2-core CPU a seed
takes about an hour, and each evaluation about two minutes).

    python baselines/evidence/run_long.py [--seeds 0 7 13] [--out DIR]

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

from baselines.evidence.run_evidence import EVAL_EPISODES, RESULTS, results_name

OUT = RESULTS / "boxing-1M"
REPOSITORY = RESULTS.parents[1]  # checkpoints are named from here, as in boxing-probes/
GAME, PRESET, TOTAL_STEPS = "Boxing", "3.1", 1_000_000
SEEDS = (0, 7, 13)
STAGES = (100, 250, 500, 750)  # iterations (x 1024 agent steps) whose checkpoints are evaluated


def long_config(seed: int):
    """The runs' config: PPOConfig's defaults on Boxing 3.1 for TOTAL_STEPS."""
    from baselines.ppo import PPOConfig

    return PPOConfig(game=GAME, preset=PRESET, seed=seed, total_steps=TOTAL_STEPS)


def evaluate_once(config, checkpoint: Path, out_dir: Path, *, episodes: int, num_envs: int,
                  progress: bool) -> dict | None:
    """Evaluate ``checkpoint`` of a run of ``config`` (sampled policy) into
    ``out_dir``/eval-sampled.json unless that file exists; returns the new result, or None when
    there was one already."""
    from baselines.evaluate import evaluate, result_path, write_result

    if result_path(out_dir, "sampled").exists():
        return None
    result = evaluate(config.game, config.preset, policy="sampled", episodes=episodes,
                      num_envs=num_envs, checkpoint=checkpoint, progress=progress)
    result["checkpoint"] = results_name(checkpoint, REPOSITORY)
    write_result(result, out_dir)
    return result


def _iterations_done(run: Path) -> int:
    """How far the run in ``run`` has trained: its checkpoint's iteration (0 for no run, or
    one stopped before its first checkpoint, which starts again).  A finished run whose
    checkpoint is gone is refused (:func:`baselines.runs.check_no_finished_run`)."""
    from baselines.ppo import load_checkpoint
    from baselines.runs import check_no_finished_run

    if (run / "checkpoint.pkl").exists():
        return load_checkpoint(run / "checkpoint.pkl")["iteration"]
    check_no_finished_run(run, elsewhere="give run_long.py an empty --out")
    return 0


def train_in_stages(config, run: Path, by_step: Path, stages=STAGES, *,
                    episodes: int = EVAL_EPISODES, num_envs: int | None = None,
                    progress: bool = True) -> None:
    """Train ``config`` into ``run``, stopping after each of ``stages`` (iterations) to copy the
    checkpoint to ``by_step``/<agent steps>/seed<S>/ and evaluate it there, then to the end and
    evaluate the final checkpoint in ``run``.  Stages and evaluations already done are skipped;
    a stage whose checkpoint the run has trained past (the run went on without this script)
    is refused, since it can no longer be evaluated."""
    from baselines.evaluate import EVAL_NUM_ENVS, result_path
    from baselines.ppo import train

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
            done = _iterations_done(run)
            if done > stage:
                raise ValueError(f"{run} has trained {done} iterations, past stage {stage}, "
                                 f"and {aside / 'checkpoint.pkl'} is missing: that stage can "
                                 "no longer be evaluated; give --out an empty directory to "
                                 "train the run again")
            train(config, run, resume=done > 0, progress=progress, stop_after=stage)
            aside.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(checkpoint, aside / "checkpoint.tmp")
            (aside / "checkpoint.tmp").replace(aside / "checkpoint.pkl")
        evaluate_once(config, aside / "checkpoint.pkl", aside, episodes=episodes,
                      num_envs=num_envs, progress=progress)
    if not (run / "summary.json").exists():
        train(config, run, resume=_iterations_done(run) > 0, progress=progress)
    evaluate_once(config, checkpoint, run, episodes=episodes, num_envs=num_envs,
                  progress=progress)


def evaluations_by_step(out: Path) -> dict[int, dict[int, dict]]:
    """Every evaluation below ``out``, as {agent steps its checkpoint had trained: {training
    seed: result}}.  Each must be of a run of this script (Boxing 3.1, sampled policy,
    TOTAL_STEPS) and one of its kind; others are refused, naming the file and the field."""
    expected = dict(game=GAME, preset=PRESET, policy="sampled", run_total_steps=TOTAL_STEPS)
    found = defaultdict(dict)
    for path in sorted(Path(out).rglob("eval-*.json")):
        result = json.loads(path.read_text())
        for field in ("train_seed", "trained_agent_steps", "mean_return", "std_return",
                      "episodes", *expected):
            if field not in result:
                raise ValueError(f"{path} lacks {field} (an evaluation of an older or "
                                 "another kind)")
        for field, value in expected.items():
            if result[field] != value:
                raise ValueError(f"{path}: {field} is {result[field]!r}, not {value!r} as in "
                                 f"this script's runs")
        steps, seed = result["trained_agent_steps"], result["train_seed"]
        if seed in found[steps]:
            raise ValueError(f"{path}: a second evaluation of seed {seed} at {steps} agent "
                             f"steps (the other: {found[steps][seed]['path']})")
        found[steps][seed] = dict(result, path=str(path))
    if not found:
        raise ValueError(f"no evaluations below {out}: run the script first")
    return dict(sorted(found.items()))


def random_evaluations(seeds) -> dict[int, dict]:
    """The random policy's recorded evaluations on Boxing 3.1 (run_evidence.py's), by seed."""
    from baselines.evidence.run_evidence import run_dir

    found = {}
    for seed in seeds:
        path = run_dir(GAME, PRESET, "random", seed) / "eval-random.json"
        if path.exists():
            found[seed] = json.loads(path.read_text())
    return found


def _over_seeds(means: list[float], of: int) -> str:
    """Mean ± std (ddof 1) of the seeds' means, saying how many seeds where some are missing."""
    if len(means) < 2:
        return "-"
    text = f"{np.mean(means):.2f} ± {np.std(means, ddof=1):.2f}"
    return text if len(means) == of else f"{text} ({len(means)} of {of} seeds)"


def onset_table(by_step: dict[int, dict[int, dict]], random: dict[int, dict],
                seeds=SEEDS) -> str:
    """Markdown: a row per agent steps trained, a column per seed (the mean return of its
    episodes ± their std; "-" where not evaluated yet), then the mean ± std of the seeds'
    means; the random policy last."""
    lines = ["| agent steps | " + " | ".join(f"seed {s}" for s in seeds)
             + " | mean ± std over seeds |", "|---" * (len(seeds) + 2) + "|"]
    rows = [(f"{steps:,}", results) for steps, results in by_step.items()]
    for label, results in rows + [("random policy", random)]:
        cells = [f"{results[s]['mean_return']:.2f} ± {results[s]['std_return']:.2f}"
                 if s in results else "-" for s in seeds]
        means = [results[s]["mean_return"] for s in seeds if s in results]
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {_over_seeds(means, len(seeds))} |")
    episodes = sorted({r["episodes"] for results in by_step.values() for r in results.values()})
    return "\n".join(lines) + (
        f"\n\nA seed's cell: the mean return of its {'/'.join(map(str, episodes))} evaluation "
        "episodes ± their std. The last column: the mean ± std (ddof 1) of the seeds' means.\n")


def plot_onset(by_step: dict[int, dict[int, dict]], random: dict[int, dict], path: Path,
               seeds=SEEDS) -> Path:
    """Each seed's evaluation return by agent steps trained, the mean over ``seeds`` where all
    are evaluated, the random policy's level and the paper's DreamerV3 and STORM after 100k
    agent steps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    from baselines.table import PAPER_AGENT_STEPS, PAPER_RESULTS, steps_label

    fig, ax = plt.subplots(figsize=(6, 3.8))
    for i, seed in enumerate(seeds):
        points = [(n, r[seed]["mean_return"]) for n, r in by_step.items() if seed in r]
        if points:
            ax.plot(*zip(*points), "o-", lw=0.8, alpha=0.6, color=f"C{i}", label=f"seed {seed}")
    complete = [n for n, r in by_step.items() if all(s in r for s in seeds)]
    if complete:
        ax.plot(complete, [np.mean([by_step[n][s]["mean_return"] for s in seeds])
                           for n in complete], "k-", lw=1.8, label="mean over seeds")
    if random:
        ax.axhline(np.mean([r["mean_return"] for r in random.values()]), color="grey", ls="--",
                   label="random policy")
    dreamer, _, storm, _ = PAPER_RESULTS[(GAME, PRESET)]
    ax.plot([PAPER_AGENT_STEPS], [dreamer], "s", color="C3", label="DreamerV3 at 100k (paper)")
    ax.plot([PAPER_AGENT_STEPS], [storm], "^", color="C4", label="STORM at 100k (paper)")
    ax.set_xlabel("agent steps trained")
    ax.set_xlim(0, max(max(by_step), PAPER_AGENT_STEPS) * 1.05)
    ax.xaxis.set_major_formatter(FuncFormatter(steps_label))
    ax.set_ylabel("evaluation return (mean of episodes)")
    ax.set_title(f"PPO (CleanRL's defaults) on {GAME} {PRESET}")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_onset(out: Path, seeds=SEEDS) -> str:
    """``out``/onset.md and onset.png from the evaluations below ``out``; returns the table."""
    by_step = evaluations_by_step(out)
    random = random_evaluations(seeds)
    text = onset_table(by_step, random, seeds)
    (out / "onset.md").write_text(text)
    plot_onset(by_step, random, out / "onset.png", seeds)
    return text


def main() -> None:
    from baselines.table import build_table

    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", nargs="+", type=int, choices=SEEDS, default=SEEDS,
                        help="train and evaluate only these seeds (default: all)")
    parser.add_argument("--out", type=Path, default=OUT,
                        help=f"results directory (default {results_name(OUT, REPOSITORY)})")
    args = parser.parse_args()
    for seed in args.seeds:
        train_in_stages(long_config(seed), args.out / "runs" / f"seed{seed}",
                        args.out / "by-step")
    text, _ = build_table(args.out / "runs", args.out)
    print(text + "\n" + write_onset(args.out))


if __name__ == "__main__":
    main()
