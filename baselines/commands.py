"""``stori-jax train AGENT``, ``stori-jax eval`` and ``stori-jax table``: the baselines' command
line, which :mod:`baselines.plugin` adds to ``stori-jax``.  Every agent of
:mod:`baselines.agents` is served by the same code."""

from __future__ import annotations

import dataclasses
import shlex
import sys
from pathlib import Path

from baselines.agents import agent_names, get_agent, load_checkpoint
from baselines.evaluate import CHECKPOINT_POLICIES, EVAL_NUM_ENVS
from stori_jax.builder import MAX_EPISODE_FRAMES


def add_parsers(sub) -> None:
    train = sub.add_parser("train", help="train a baseline agent on a preset")
    train.set_defaults(handler=cmd_train)
    train.add_argument("agent", choices=agent_names(), help="the algorithm")
    train.add_argument("--game", required=True, help="Breakout, Boxing, Gopher or BankHeist")
    train.add_argument("--preset", default="3.1", help="paper preset (default 3.1)")
    train.add_argument("--seed", type=int, default=0, help="training seed (default 0)")
    train.add_argument("--steps", type=int, default=100_000,
                       help="agent steps in total (default 100000)")
    train.add_argument("--out", type=Path, default=None,
                       help="run directory (default results/train/<game>-<preset>/<agent>-seed<S>)")
    train.add_argument("--resume", action="store_true",
                       help="continue from the run directory's checkpoint.pkl")
    train.add_argument("--set", dest="overrides", action="append", default=[],
                       metavar="FIELD=VALUE",
                       help="any hyperparameter of the agent but game, preset, seed and steps "
                            "(their own flags), e.g. network=nips")
    train.add_argument("--eval-episodes", type=int, default=0,
                       help="evaluate the final policy for this many episodes (default 0: "
                            "not now; stori-jax eval does it later)")
    train.add_argument("--force", action="store_true",
                       help="with --eval-episodes: replace an existing eval-sampled.json")
    train.add_argument("--quiet", action="store_true", help="no progress bar")

    ev = sub.add_parser("eval", help="the evaluation protocol: N episodes of a checkpoint's "
                                     "policy (or the random policy) on its preset")
    ev.set_defaults(handler=cmd_eval)
    ev.add_argument("--checkpoint", type=Path, default=None,
                    help="a trained agent's checkpoint.pkl")
    ev.add_argument("--random", action="store_true", help="the uniformly random policy instead "
                                                          "(needs --game and --preset)")
    ev.add_argument("--game", default=None, help="with --random: the game")
    ev.add_argument("--preset", default=None, help="with --random: the paper preset")
    ev.add_argument("--seed", type=int, default=None,
                    help="training seed the result is filed under (default: the checkpoint's; "
                         "0 for --random)")
    ev.add_argument("--episodes", type=int, default=100,
                    help="whole episodes to play (default 100, the paper's protocol)")
    ev.add_argument("--policy", choices=list(CHECKPOINT_POLICIES), default=None,
                    help="how a checkpoint acts (default sampled)")
    ev.add_argument("--eval-seed", type=int, default=None,
                    help="environment seed of the evaluation (default: training seed + 10000)")
    ev.add_argument("--num-envs", type=int, default=EVAL_NUM_ENVS,
                    help=f"envs the episodes are split over (default {EVAL_NUM_ENVS}, as the "
                         "recorded evaluations)")
    ev.add_argument("--max-episode-frames", type=int, default=MAX_EPISODE_FRAMES,
                    help="emulator frames after which an episode is cut off (truncated; "
                         f"default {MAX_EPISODE_FRAMES}, 30 minutes of play, as in training)")
    ev.add_argument("--out", type=Path, default=None,
                    help="directory for eval-<policy>.json (default: the checkpoint's, or "
                         "results/train/<game>-<preset>/random-seed<S>)")
    ev.add_argument("--force", action="store_true",
                    help="replace an existing eval-<policy>.json in --out")
    ev.add_argument("--quiet", action="store_true", help="no progress bar")

    table = sub.add_parser("table", help="aggregate evaluations into the paper's table and plot "
                                         "learning curves")
    table.set_defaults(handler=cmd_table)
    table.add_argument("results_dir", type=Path,
                       help="a folder of runs (<game>-<preset>/<agent>-seed<S>/eval-*.json)")
    table.add_argument("--out", type=Path, default=None, help="default: RESULTS_DIR")
    table.add_argument("--policy", choices=list(CHECKPOINT_POLICIES), default="sampled",
                       help="which evaluation of the trained agents the table shows "
                            "(default sampled)")


def _parse_overrides(items: list[str]) -> dict[str, str]:
    overrides = {}
    for item in items:
        name, sep, value = item.partition("=")
        name, value = name.strip(), value.strip()
        if not sep or not name:
            raise ValueError(f"--set takes FIELD=VALUE, got {item!r}")
        if name in overrides:
            raise ValueError(f"--set {name} given twice ({overrides[name]!r} and {value!r})")
        overrides[name] = value
    return overrides


FLAGS = {"game": "--game", "preset": "--preset", "seed": "--seed", "total_steps": "--steps"}


def agent_config(agent, game: str, preset: str, seed: int, steps: int, overrides: list[str]):
    """The ``agent``'s config of a run: game, preset, seed and steps from their flags, every
    other hyperparameter from ``--set FIELD=VALUE`` items; errors name the flag."""
    parsed = _parse_overrides(overrides)
    settable = sorted(f.name for f in dataclasses.fields(agent.config_class)
                      if f.name not in FLAGS)
    for name in parsed:
        if name in FLAGS:
            raise ValueError(f"set {name} with {FLAGS[name]}, not --set")
        if name not in settable:
            raise ValueError(f"unknown {agent.title} hyperparameter {name!r}; --set takes "
                             f"{settable}")
    try:
        return agent.config_class.from_overrides(  # checked once, --steps with the --set values
            agent.config_class(game=game, preset=preset, seed=seed),
            {**parsed, "total_steps": str(steps)})
    except ValueError as error:  # name the flag the user gave, not the config field
        message = str(error)
        for name, flag in FLAGS.items():
            if message.startswith(name + " "):
                raise ValueError(flag + message[len(name):]) from None
        raise


def run_dir(root: Path, game: str, preset: str, agent: str, seed: int) -> Path:
    """Where a run's files live: ``root``/<game>-<preset>/<agent>-seed<seed>."""
    return Path(root) / f"{game}-{preset}" / f"{agent}-seed{seed}"


DEFAULT_ROOT = Path("results") / "train"


def check_no_result(path: Path, force: bool, elsewhere: str = "another --out"):
    """An earlier evaluation is replaced only with --force (one may have cost an hour)."""
    if path.exists() and not force:
        raise ValueError(f"{path} already holds an evaluation: pass --force to replace it, "
                         f"or {elsewhere}")


def cmd_train(args) -> int:
    from baselines.evaluate import (EVAL_SEED_OFFSET, check_eval_seed, evaluate, result_path,
                                    write_result)
    from baselines.runs import check_no_finished_run, check_no_run_here
    from stori_jax.checks import check_int
    from stori_jax.cli import check_out
    from stori_jax.folders import removed_if_left_empty

    check_int("--eval-episodes", args.eval_episodes, 0)
    agent = get_agent(args.agent)
    config = agent_config(agent, args.game, args.preset, args.seed, args.steps, args.overrides)
    out = args.out or run_dir(DEFAULT_ROOT, config.game, config.preset, agent.name, config.seed)
    check_out("--out", out, directory=True)
    if args.resume and not (out / "checkpoint.pkl").exists():
        check_no_finished_run(out, "--resume: ",  # a finished run's checkpoint is gone
                              elsewhere=f"stori-jax train {agent.name} ... --out DIR")
        raise ValueError(f"--resume: {out} holds no checkpoint.pkl (a run stopped before its "
                         "first checkpoint has nothing to continue): run without --resume")
    if not args.resume:  # train() checks it too: here, before the evaluation's checks
        check_no_run_here(out, agent.name)
    if args.force and not args.eval_episodes:
        raise ValueError("--force replaces an evaluation: it needs --eval-episodes")
    if args.eval_episodes:  # checked before training, not after it
        check_eval_seed(agent.train_env_seeds(config.seed), config.seed,
                        config.seed + EVAL_SEED_OFFSET,
                        "train without --eval-episodes, then run stori-jax eval --checkpoint "
                        f"{out}/checkpoint.pkl --eval-seed S")
        check_no_result(result_path(out, "sampled"), args.force,
                        "train without --eval-episodes, then run stori-jax eval --checkpoint "
                        f"{out}/checkpoint.pkl --out DIR")
    per_iteration = agent.steps_per_iteration(config)
    trained = -(-config.total_steps // per_iteration) * per_iteration
    if trained != config.total_steps:
        print(f"stori-jax: --steps {config.total_steps} rounds up to {trained} agent steps, whole "
              f"iterations of {per_iteration} agent steps", file=sys.stderr)
    try:
        with removed_if_left_empty(out):  # a run stopped before writing anything leaves nothing
            summary = agent.train(config, out, resume=args.resume, progress=not args.quiet)
    except KeyboardInterrupt:
        if (out / "checkpoint.pkl").exists():
            print(f"stori-jax: the last checkpoint is in {out}; continue with the same command "
                  "and --resume", file=sys.stderr)
        raise
    trained_now = summary["agent_steps_now"]
    if trained_now == 0:
        print(f"nothing to train: {out} holds a finished run of {summary['agent_steps']} agent "
              "steps (a run trains to its --steps; a longer one starts in another --out)")
    else:
        resumed = (f"resumed at agent step {summary['agent_steps'] - trained_now}, trained "
                   f"{trained_now}; the run: " if trained_now < summary["agent_steps"]
                   else "trained ")
        print(f"{resumed}{summary['agent_steps']} agent steps in "
              f"{summary['train_seconds']:.0f} s ({summary['train_sps']:.0f} steps/s); wrote "
              f"{out}/config.json, log.csv, episodes.csv, checkpoint.pkl, summary.json")
    if args.eval_episodes:
        result = evaluate(config.game, config.preset, policy="sampled", seed=config.seed,
                          episodes=args.eval_episodes, checkpoint=out / "checkpoint.pkl",
                          progress=not args.quiet)
        print(f"eval: {describe_result(result)}; wrote {write_result(result, out)}")
        print_truncated(result)
    return 0


def describe_result(result: dict) -> str:
    """One line of an evaluation's outcome, as `eval` and `train --eval-episodes` print it."""
    episodes = result["episodes"]
    return (f"{result['game']} {result['preset']} {result['policy']}: mean return "
            f"{result['mean_return']:.2f} ± {result['std_return']:.2f} (std over {episodes} "
            f"episode{'s' * (episodes != 1)}, eval seed {result['eval_seed']})")


def game_flag(name: str) -> str:
    """:func:`stori_game` of --game's value, its errors naming the flag."""
    from baselines.evaluate import stori_game

    try:
        return stori_game(name)
    except ValueError as error:
        message = str(error)
        raise ValueError("--" + message if message.startswith("game ")
                         else f"--game: {message}") from None


def cmd_eval(args) -> int:
    import stori_jax
    from baselines.evaluate import (EVAL_SEED_OFFSET, evaluate, result_path, stori_game,
                                    write_result)
    from stori_jax.checks import MAX_INT32, MAX_SEED, check_int
    from stori_jax.cli import check_out
    from stori_jax.builder import FRAME_SKIP, check_memory
    from stori_jax.presets import canonical_preset

    if args.random == (args.checkpoint is not None):
        raise ValueError("give either --checkpoint PATH or --random (with --game and --preset)")
    for flag, value, minimum, maximum in (("--seed", args.seed, 0, MAX_SEED),
                                          ("--eval-seed", args.eval_seed, 0, MAX_SEED),
                                          ("--episodes", args.episodes, 1, None),
                                          ("--num-envs", args.num_envs, 1, None),
                                          ("--max-episode-frames", args.max_episode_frames, 1,
                                           MAX_INT32)):
        if value is not None:
            check_int(flag, value, minimum, maximum)
    envs = min(args.num_envs, args.episodes)  # evaluate() steps no more envs than episodes
    check_memory(envs, FRAME_SKIP, flag="--num-envs" if envs == args.num_envs else "--episodes")
    if args.random:
        if args.game is None or args.preset is None:
            raise ValueError("--random needs --game and --preset")
        if args.policy is not None:
            raise ValueError("--policy applies to checkpoints only (--random plays the random "
                             "policy)")
        game = game_flag(args.game)  # one spelling per game (and preset) in the run folders
        preset, seed, policy = canonical_preset(game, args.preset), args.seed or 0, "random"
        out = args.out or run_dir(DEFAULT_ROOT, game, preset, "random", seed)
        checkpoint = None
    else:
        config = load_checkpoint(args.checkpoint)[1]["config"]
        game = args.game if args.game is None else game_flag(args.game)
        # the training seed labels the result (and the table's seed column): it is the checkpoint's
        for flag, value, trained in (("--game", game, stori_game(config["game"])),
                                     ("--preset", args.preset, config["preset"]),
                                     ("--seed", args.seed, config["seed"])):
            if flag == "--preset" and value is not None:  # the checkpoint's game is the one
                try:
                    value = canonical_preset(config["game"], value)
                except ValueError as error:
                    raise ValueError(f"--preset: {error}") from None
            if value is not None and value != trained:
                hint = {"--seed": " (to evaluate on other seeds, give --eval-seed)",
                        "--preset": " (eval plays a checkpoint on the preset it was trained "
                                    "on; stori-jax suite --checkpoint "
                                    f"{shlex.quote(str(args.checkpoint))} --games "
                                    f"{config['game']} --presets {value} plays its sampled "
                                    "policy on others, in the suite's table, not this one's)"}
                raise ValueError(f"{flag} {value} differs from the checkpoint's {trained}"
                                 + hint.get(flag, ""))
        game, preset, policy = config["game"], config["preset"], args.policy or "sampled"
        seed = config["seed"]
        out, checkpoint = args.out or args.checkpoint.parent, args.checkpoint
    check_out("--out", out, directory=True)
    check_no_result(result_path(out, policy), args.force)
    if args.eval_seed is None:  # the default eval seed must be a valid seed too
        check_int("--seed + 10000 (the default --eval-seed)", seed + EVAL_SEED_OFFSET, 0,
                  MAX_SEED)
    if policy == "greedy" and stori_jax.preset(game, preset).is_deterministic():
        print(f"note: {game} {preset} has no randomness once the policy is greedy, so every "
              "episode plays the same (sampled evaluation varies)")
    result = evaluate(game, preset, policy=policy, episodes=args.episodes, seed=seed,
                      eval_seed=args.eval_seed, num_envs=args.num_envs, checkpoint=checkpoint,
                      max_episode_frames=args.max_episode_frames, progress=not args.quiet)
    print(f"{describe_result(result)}; wrote {write_result(result, out)}")
    print_truncated(result)
    return 0


def print_truncated(result: dict) -> None:
    """Say so when episodes were cut off at the frame cap (a policy that never starts play, say
    one that never presses FIRE in Breakout, plays each episode to the cap)."""
    if result["truncated"]:
        print(f"note: {result['truncated']} of {result['episodes']} episodes were cut off at "
              f"{result['max_episode_frames']} frames (truncated; --max-episode-frames "
              "sets the cap)")


def cmd_table(args) -> int:
    from baselines.table import build_table
    from stori_jax.cli import check_out

    if args.out is not None:
        check_out("--out", args.out, directory=True)
    text, paths = build_table(args.results_dir, args.out, ppo_policy=args.policy)
    print(text)
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0



