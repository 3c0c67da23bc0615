"""The paper's evaluation protocol: a fixed number of whole episodes (100 by default) of a
policy on its preset, from evaluation seeds apart from the training seeds.

Policies: a trained agent's checkpoint, acting ``sampled`` (from its distribution, or the
agent's own exploration) or ``greedy`` (argmax), or the uniformly ``random`` policy, the
baseline every table shows beside the agents.

Episodes are shared out over the envs in fixed quotas (env i plays its first quota[i] episodes),
so the sample does not favour short episodes, and a seed gives the same returns every time.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from stori_jax.checks import check_int
from stori_jax.presets import canonical_preset
from stori_jax.suite import episode_quotas

CHECKPOINT_POLICIES = ("sampled", "greedy")  # how a trained policy acts
POLICIES = CHECKPOINT_POLICIES + ("random",)
EVAL_SEED_OFFSET = 10_000  # evaluation seed = training seed + this, unless given
EVAL_NUM_ENVS = 20  # envs of an evaluation (the recorded evaluations used this many)
STEPS_SHOWN_EVERY = 250  # the progress bar shows the agent steps played every this many steps


def stori_game(name: str) -> str:
    """``name`` spelt as the STORI game it names; other games are refused (the baselines train
    and evaluate on the paper's presets)."""
    import stori_jax

    allowed = (f"game must be one of the STORI games {list(stori_jax.STORI_GAMES)} (the "
               "baselines play the paper's presets)")
    try:
        game = stori_jax.get_game(name).name
    except ValueError:  # not even an ale-py game: name only the games allowed here
        raise ValueError(f"unknown game {name!r}: {allowed}") from None
    if game not in stori_jax.STORI_GAMES:
        raise ValueError(f"{allowed}, got {name!r}")
    return game


def check_eval_seed(train_env_seeds, train_seed: int, eval_seed: int, advice: str) -> None:
    """Refuse an evaluation seed that is one of the training envs' own ``train_env_seeds``
    (the evaluation would replay training's episodes); ``advice`` says what to do instead."""
    if eval_seed in train_env_seeds:
        raise ValueError(f"eval seed {eval_seed} is one of the training envs' seeds "
                         f"{list(train_env_seeds)} (training seed {train_seed}): "
                         f"the evaluation would replay training's episodes; {advice}")


def evaluate(game: str, preset: str, *, policy: str, episodes: int = 100,
             seed: int | None = None, eval_seed: int | None = None,
             num_envs: int = EVAL_NUM_ENVS, checkpoint: Path | None = None,
             max_episode_frames: int = 108_000, progress: bool = True) -> dict:
    """Play ``episodes`` episodes; returns a dict with every return and their mean and std.

    ``seed`` is the training seed the result is filed under (the table's seed column): a
    checkpoint's own (another is refused), 0 for the random policy unless given. ``eval_seed``
    defaults to that seed + EVAL_SEED_OFFSET."""
    import jax
    import stori_jax
    from baselines.runs import workers_within_cores
    from stori_jax.provenance import software
    from tqdm import tqdm

    made_with = software()  # before the episodes, not whatever is installed when they end
    if policy not in POLICIES:
        raise ValueError(f"policy must be one of {list(POLICIES)}, got {policy!r}")
    if (policy == "random") != (checkpoint is None):
        raise ValueError("give a checkpoint for the 'sampled' and 'greedy' policies, and none "
                         "for 'random'")
    episodes, num_envs = check_int("episodes", episodes, 1), check_int("num_envs", num_envs, 1)
    game = stori_game(game)  # one spelling per game (and preset) in the results
    preset = canonical_preset(game, preset)
    num_envs = min(num_envs, episodes)
    trained = {}  # how far the checkpoint's run had trained (a table notes other budgets)
    agent_name = "random"
    if checkpoint is not None:
        from baselines.agents import load_checkpoint

        agent, ckpt = load_checkpoint(checkpoint)
        agent_name = agent.name
        config, choose = agent.policy_of(ckpt, policy)
        trained = agent.training_progress(ckpt)
        if (config.game, config.preset) != (game, preset):
            raise ValueError(f"checkpoint {checkpoint} was trained on {config.game} "
                             f"{config.preset}, not {game} {preset}")
        if seed is not None and seed != config.seed:
            raise ValueError(f"seed {seed} differs from the training seed {config.seed} of "
                             f"checkpoint {checkpoint} (to evaluate on other seeds, give "
                             "eval_seed)")
        seed = config.seed
        eval_seed = seed + EVAL_SEED_OFFSET if eval_seed is None else eval_seed
        check_eval_seed(agent.train_env_seeds(seed), seed, eval_seed, "choose another "
                        f"--eval-seed (by default the training seed + {EVAL_SEED_OFFSET})")
    else:
        from stori_jax.suite import random_policy

        seed = 0 if seed is None else check_int("seed", seed, 0)
        eval_seed = seed + EVAL_SEED_OFFSET if eval_seed is None else eval_seed
        choose = random_policy(stori_jax.get_game(game).num_actions)

    quotas = episode_quotas(episodes, num_envs)
    returns = [[] for _ in range(num_envs)]
    lengths = [[] for _ in range(num_envs)]
    cut_off = 0  # counted episodes cut off at max_episode_frames before the game ended
    key = stori_jax.agent_key(eval_seed)  # not the env's own key chain
    start, agent_steps = time.perf_counter(), 0
    with stori_jax.make(game, preset, num_envs=num_envs, seed=eval_seed, obs="atari84",
                        max_episode_frames=max_episode_frames,
                        **workers_within_cores(num_envs)) as env:  # a grid trial's share of cores
        obs, _ = env.reset()
        bar = tqdm(total=episodes, unit="episode", disable=not progress,
                   desc=f"eval {policy} {game} {preset}")
        while any(len(r) < q for r, q in zip(returns, quotas)):
            key, k = jax.random.split(key)
            obs, _, terminated, truncated, info = env.step(choose(obs, k))
            agent_steps += num_envs
            if agent_steps % (STEPS_SHOWN_EVERY * num_envs) == 0:  # long episodes show progress
                bar.set_postfix_str(f"{agent_steps} agent steps")
            terminated, truncated = np.asarray(terminated), np.asarray(truncated)
            done = np.flatnonzero(terminated | truncated)
            if done.size:
                ret, length = np.asarray(info["episode_return"]), np.asarray(info["episode_length"])
                for i in done:
                    if len(returns[i]) < quotas[i]:
                        returns[i].append(float(ret[i]))
                        lengths[i].append(int(length[i]))
                        cut_off += bool(truncated[i] and not terminated[i])  # the game
                        #                         may end on the very step that reaches the cap
                        bar.update()
        bar.close()
    flat = [r for env_returns in returns for r in env_returns]
    return dict(game=game, preset=preset, agent=agent_name,
                policy=policy, train_seed=seed, eval_seed=eval_seed, episodes=episodes,
                num_envs=num_envs, max_episode_frames=max_episode_frames,
                checkpoint=None if checkpoint is None else str(checkpoint), **trained,
                mean_return=float(np.mean(flat)), std_return=float(np.std(flat)),
                returns=flat, lengths=[n for env_lengths in lengths for n in env_lengths],
                truncated=cut_off,
                agent_steps=agent_steps, seconds=time.perf_counter() - start,
                software=made_with)


def result_path(out_dir: Path, policy: str) -> Path:
    """Where an evaluation of ``policy`` is filed: ``out_dir``/eval-<policy>.json."""
    return Path(out_dir) / f"eval-{policy}.json"


def write_result(result: dict, out_dir: Path) -> Path:
    """``out_dir``/eval-<policy>.json, the file ``stori-jax table`` collects."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = result_path(out_dir, result["policy"])
    partial = path.with_suffix(".tmp")  # an interruption leaves no truncated result behind
    partial.write_text(json.dumps(result, indent=1))
    partial.replace(path)
    return path
