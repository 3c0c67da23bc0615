"""What a grid computes (:class:`GridSpec`, from the command's flags, checked) and its trials'
plain configs; the checks a trial passes before Ray starts; a grid folder's recorded spec."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

from baselines.agents import RANDOM, agent_names

SPEC_FILE = "grid.json"  # --out/grid.json: the grid's settings, checked when it is run again
DEFAULT_SEEDS = (0, 7, 13)  # the paper's
DEFAULT_STEPS = 100_000  # the paper's budget, agent steps
DEFAULT_OUT = Path("results") / "grid"
DEFAULT_PARTS = 4  # a trained run is trained (and checkpointed to Tune) in this many parts
DEFAULT_MAX_FAILURES = 3  # Tune retries a trial whose process died this many times (not a
#                           part of the spec: how the grid runs)


@dataclasses.dataclass(frozen=True)
class GridSpec:
    """What a grid computes: the same spec gives the same files, wherever and however often it
    runs (how it runs, the cluster and the resources of a trial, is not part of it)."""

    agent: str
    runs: tuple  # ((game, preset, seed), ...), in order
    steps: int | None  # agent steps of training; None for the random policy
    eval_episodes: int
    max_episode_frames: int
    overrides: tuple = ()  # --set FIELD=VALUE items, as `train` takes them
    parts: int = DEFAULT_PARTS  # training parts per run, each reported to Tune with a checkpoint

    def as_json(self) -> dict:
        return dict(dataclasses.asdict(self), runs=[list(r) for r in self.runs],
                    overrides=list(self.overrides))


def grid_spec(agent: str, *, games=None, presets=None, seeds=DEFAULT_SEEDS, steps=None,
              eval_episodes: int = 100, max_episode_frames: int | None = None, overrides=(),
              parts: int = DEFAULT_PARTS) -> GridSpec:
    """The :class:`GridSpec` of the command's flags, checked (a ValueError naming the flag)."""
    from stori_jax.checks import MAX_INT32, MAX_SEED, check_int
    from stori_jax.cli import selected_presets
    from stori_jax.builder import MAX_EPISODE_FRAMES

    trainable = agent_names()
    if agent != RANDOM and agent not in trainable:
        raise ValueError(f"--agent must be one of {trainable + [RANDOM]}, got {agent!r}")
    seeds = [check_int("--seeds", s, 0, MAX_SEED) for s in seeds]
    if not seeds:
        raise ValueError("--seeds needs at least one seed")
    repeated = sorted({s for s in seeds if seeds.count(s) > 1})
    if repeated:
        raise ValueError(f"--seeds gives {repeated} more than once (a seed would count twice)")
    check_int("--eval-episodes", eval_episodes, 1)
    check_int("--parts", parts, 1)
    if max_episode_frames is None:
        max_episode_frames = MAX_EPISODE_FRAMES
    check_int("--max-episode-frames", max_episode_frames, 1, MAX_INT32)
    if agent == RANDOM:
        if steps is not None:
            raise ValueError("--steps: the random policy is not trained (it is only evaluated)")
        if overrides:
            raise ValueError("--set: the random policy has no hyperparameters")
    else:
        steps = check_int("--steps", DEFAULT_STEPS if steps is None else steps, 1)
    pairs = selected_presets(games, presets)
    return GridSpec(agent=agent, runs=tuple((g, p, s) for g, p in pairs for s in seeds),
                    steps=steps, eval_episodes=eval_episodes,
                    max_episode_frames=max_episode_frames, overrides=tuple(overrides),
                    parts=parts)


def trial_config(spec: GridSpec, out: Path, game: str, preset: str, seed: int) -> dict:
    """What one trial needs (Tune's ``config`` of the trial): plain values only."""
    return dict(agent=spec.agent, game=game, preset=preset, seed=seed, steps=spec.steps,
                overrides=list(spec.overrides), eval_episodes=spec.eval_episodes,
                max_episode_frames=spec.max_episode_frames, parts=spec.parts, out=str(out))


def check_trial(trial: dict) -> None:
    """The checks ``stori-jax train`` / ``eval`` make before any work, for one trial: a
    ValueError (the trial cannot run) says why.  The driver makes them before Ray starts, so
    that a bad --set fails its trials once, and burns no retries."""
    from baselines.agents import get_agent
    from baselines.commands import agent_config
    from baselines.evaluate import EVAL_SEED_OFFSET, check_eval_seed
    from stori_jax.checks import MAX_SEED, check_int

    seed = trial["seed"]
    check_int("--seeds + 10000 (the evaluation seed)", seed + EVAL_SEED_OFFSET, 0, MAX_SEED)
    if trial["agent"] == RANDOM:
        return
    agent = get_agent(trial["agent"])
    config = agent_config(agent, trial["game"], trial["preset"], seed, trial["steps"],
                          trial["overrides"])
    check_eval_seed(agent.train_env_seeds(config.seed), config.seed,
                    config.seed + EVAL_SEED_OFFSET, "choose other --seeds")


def label(trial: dict) -> str:
    return f"{trial['game']} {trial['preset']} seed {trial['seed']}"


def check_spec(out: Path, spec: GridSpec) -> bool:
    """Whether ``out`` holds this grid already (run again: it resumes).  A folder that holds
    another grid, or files but no grid, is refused: a grid's run folders are its own."""
    path = out / SPEC_FILE
    if path.exists():
        try:
            recorded = json.loads(path.read_text())
        except ValueError as error:
            raise ValueError(f"{path} is not a grid's settings ({error})") from None
        wanted = spec.as_json()
        differ = [f"{k} {recorded.get(k)!r} there, {v!r} now" for k, v in wanted.items()
                  if recorded.get(k) != v]
        if differ:
            raise ValueError(f"--out {out} holds a grid of other settings ("
                             + "; ".join(differ) + "): run the same command to resume it, "
                             "or give another --out")
        return True
    if out.exists() and any(out.iterdir()):
        raise ValueError(f"--out {out} holds files but no {SPEC_FILE}: not a grid's folder (a "
                         "grid keeps its runs to itself); give a new or empty --out")
    return False
