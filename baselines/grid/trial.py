"""One trial of a grid, run: the agent trained in parts (each ending with the run folder for a
checkpoint), then its final checkpoint evaluated; the random policy only evaluated.  No Ray:
the caller's ``report`` hands each part to Tune (:mod:`baselines.grid.tuning`)."""

from __future__ import annotations

import csv
import json
import math
import tarfile
from pathlib import Path

from baselines.agents import RANDOM

RUN_ARCHIVE = "run.tar"  # a Tune checkpoint: the run folder, archived (the table reads
#                         episodes.csv wherever it lies below --out: an archive hides the copy)
PART_FILE = "part.json"  # beside it: how far the run had trained


def play_trial(trial: dict, report, checkpoint_dir: Path | None = None) -> dict:
    """Run one trial: train the agent (``stori-jax train``'s code) in ``trial['parts']`` parts,
    then evaluate its final checkpoint (``stori-jax eval``'s code); the random policy is only
    evaluated.  ``report(metrics, run_folder_or_None)`` is called after each part (with the run
    folder: a checkpoint) and once at the end.  ``checkpoint_dir``: the trial's last checkpoint
    reported to Tune, restored into the run folder where that is behind it.  Returns the
    final metrics."""
    from baselines.agents import get_agent
    from baselines.commands import agent_config
    from baselines.evaluate import evaluate, write_result

    run, policy, path = trial_files(trial)
    metrics = dict(game=trial["game"], preset=trial["preset"], seed=trial["seed"],
                   run_dir=str(run))
    checkpoint = None
    if trial["agent"] != RANDOM:
        agent = get_agent(trial["agent"])
        config = agent_config(agent, trial["game"], trial["preset"], trial["seed"],
                              trial["steps"], trial["overrides"])
        if checkpoint_dir is not None:
            restore_run(run, Path(checkpoint_dir), agent)
        per_iteration = agent.steps_per_iteration(config)
        iterations = -(-config.total_steps // per_iteration)
        bounds = part_bounds(iterations, trial["parts"])
        done = trained_iterations(run, agent, per_iteration)
        stops = [b for b in bounds if b > done]
        if not stops and not (run / "summary.json").exists():
            stops = bounds[-1:]  # trained, stopped before its summary: train writes it
        for stop in stops:
            summary = agent.train(config, run, resume=(run / "checkpoint.pkl").exists(),
                                  progress=False, stop_after=stop)
            report(dict(metrics, phase="train", progress=progress(stop, bounds),
                        agent_steps=summary["agent_steps"], train_sps=summary["train_sps"],
                        train_seconds=summary["train_seconds"],
                        recent_return=recent_return(run)), run)
        checkpoint = run / "checkpoint.pkl"
    wanted = dict(game=trial["game"], preset=trial["preset"], policy=policy,
                  train_seed=trial["seed"], episodes=trial["eval_episodes"],
                  max_episode_frames=trial["max_episode_frames"])
    result = reusable_result(path, wanted, checkpoint)
    if result is None:
        result = evaluate(trial["game"], trial["preset"], policy=policy,
                          episodes=trial["eval_episodes"], seed=trial["seed"],
                          checkpoint=checkpoint, max_episode_frames=trial["max_episode_frames"],
                          progress=False)
        write_result(result, run)
    final = final_metrics(trial, run, result)
    report(final, None)
    return final


def trial_files(trial: dict) -> tuple[Path, str, Path]:
    """The trial's run folder under its --out, its evaluation's policy, and the evaluation's
    file (``stori-jax train --out`` and ``eval``'s layout)."""
    from baselines.commands import run_dir
    from baselines.evaluate import result_path

    run = run_dir(Path(trial["out"]), trial["game"], trial["preset"], trial["agent"],
                  trial["seed"])
    policy = "random" if trial["agent"] == RANDOM else "sampled"
    return run, policy, result_path(run, policy)


def final_metrics(trial: dict, run: Path, result: dict) -> dict:
    """A finished trial's metrics (its last report to Tune), from its evaluation ``result``."""
    return dict(game=trial["game"], preset=trial["preset"], seed=trial["seed"],
                run_dir=str(run), phase="done", progress=1.0,
                eval_mean_return=result["mean_return"], eval_std_return=result["std_return"],
                eval_episodes=result["episodes"], eval_truncated=result["truncated"],
                eval_seconds=result["seconds"], agent_steps=result.get("trained_agent_steps", 0))


def evaluated(trial: dict) -> dict | None:
    """The trial's final metrics if its evaluation file is in its run folder (the trial has
    finished, whether or not Tune heard it); None without one, or one that cannot be read."""
    run, _, path = trial_files(trial)
    try:
        return final_metrics(trial, run, json.loads(path.read_text()))
    except (OSError, ValueError, KeyError, TypeError):
        return None


def part_bounds(iterations: int, parts: int) -> list[int]:
    """The iterations after which a run of ``iterations`` stops, in ``parts`` parts as even as
    whole iterations allow (fewer parts than iterations are never made)."""
    parts = min(parts, iterations)
    return sorted({math.ceil(iterations * k / parts) for k in range(1, parts + 1)})


def progress(stop: int, bounds: list[int]) -> float:
    """A trial's share of its work done after training to iteration ``stop``: each training
    part and the evaluation one share each."""
    return (bounds.index(stop) + 1) / (len(bounds) + 1)


def trained_iterations(run: Path, agent, per_iteration: int) -> int:
    """Iterations the run folder's checkpoint has trained (0 without one; -1 for a checkpoint
    that cannot be read or is not the agent's: the trial's Tune checkpoint replaces it)."""
    from baselines.runs import read_checkpoint

    path = run / "checkpoint.pkl"
    if not path.exists():
        return 0
    try:
        payload = agent.check_checkpoint(read_checkpoint(path), path)
    except ValueError:
        return -1
    return agent.training_progress(payload).get("trained_agent_steps", 0) // per_iteration


def restore_run(run: Path, checkpoint_dir: Path, agent) -> bool:
    """Put the trial's last checkpoint reported to Tune (``checkpoint_dir``: the run folder's
    archive) into the run folder, unless the folder has trained as far already (on shared
    storage it has: the archive is a copy of it, taken when the part ended).  Returns whether
    it did.  A folder that lost its files (another node's disk, a damaged checkpoint) is
    rebuilt from the archive; training then resumes from it as ``train --resume`` does."""
    part = json.loads((checkpoint_dir / PART_FILE).read_text())
    if trained_iterations(run, agent, part["per_iteration"]) >= part["iterations"]:
        return False
    if run.exists():
        for path in run.iterdir():  # the archive holds all the run needs, and nothing stale
            if path.is_file():
                path.unlink()
    run.mkdir(parents=True, exist_ok=True)
    with tarfile.open(checkpoint_dir / RUN_ARCHIVE) as tar:
        tar.extractall(run, filter="data")
    return True


def archive_run(run: Path, into: Path, agent_steps: int, per_iteration: int) -> None:
    """``into``/run.tar (the run folder's files) and part.json: a checkpoint for Tune."""
    with tarfile.open(into / RUN_ARCHIVE, "w") as tar:
        for path in sorted(run.iterdir()):
            if path.is_file() and not path.name.endswith(".tmp"):
                tar.add(path, arcname=path.name)
    (into / PART_FILE).write_text(json.dumps(dict(
        agent_steps=agent_steps, per_iteration=per_iteration,
        iterations=agent_steps // per_iteration)))


def recent_return(run: Path, last: int = 20) -> float | None:
    """Mean return of the run's last ``last`` training episodes (episodes.csv), if any."""
    try:
        with open(run / "episodes.csv", newline="") as f:
            returns = [float(r["return"]) for r in csv.DictReader(f)][-last:]
    except (OSError, KeyError, ValueError):
        return None
    return sum(returns) / len(returns) if returns else None


def reusable_result(path: Path, wanted: dict, checkpoint: Path | None) -> dict | None:
    """An evaluation the trial already wrote (it ended before Tune heard it finish): reused
    when it is the evaluation asked for, of the checkpoint's training; None when there is
    none.  Another evaluation there is an error (eval does not replace one without --force)."""
    if not path.exists():
        return None
    try:
        result = json.loads(path.read_text())
    except (OSError, ValueError):
        return None  # an unreadable file: the evaluation is made again and replaces it
    if checkpoint is not None:
        from baselines.agents import load_checkpoint

        agent, payload = load_checkpoint(checkpoint)
        wanted = dict(wanted, **agent.training_progress(payload))
    differ = {k: (result.get(k), v) for k, v in wanted.items() if result.get(k) != v}
    if differ:
        raise ValueError(f"{path} holds another evaluation ("
                         + "; ".join(f"{k} {a!r} there, {b!r} here" for k, (a, b)
                                     in differ.items())
                         + "): move it away, or run the grid into another --out")
    return result
