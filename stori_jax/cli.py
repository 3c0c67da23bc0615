"""The stori-jax command line: run a preset with a random policy, suite over every preset,
show / record pictures of a preset, list what exists; and the commands of installed plugins
(:mod:`stori_jax.plugins`; the baselines add train, eval, table)."""

from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
from pathlib import Path

from stori_jax.checks import MAX_SEED, check_int
from stori_jax.config import GRANULARITIES
from stori_jax.plan import OBS_KINDS
from stori_jax.plugins import add_commands
from stori_jax.visual import AFTER_SWITCH, SHEET_STEPS, episode_step_cap


def _list_objects() -> int:
    from stori_jax.objects import listing
    from stori_jax.ram_events import NAMED_RAM_EVENTS

    games = listing()
    print(f"Object tables ({len(games)} games; obs='objects', info['objects'], "
          "ObservationMask('objects', 1, p, classes=...)):")
    for game, classes in games.items():
        print(f"  {game:<14} " + ", ".join(f"{name} x{slots}" if slots > 1 else name
                                             for name, slots in classes.items()))
    print("\nNamed RAM events (stori_jax.ram_event(game, name, prob)):")
    for (game, name), (what, _) in NAMED_RAM_EVENTS.items():
        print(f"  {game:<14} {name:<14} {what}")
    return 0


def _cmd_list(args) -> int:
    from stori_jax import STORI_GAMES, describe_preset, get_game, list_presets

    if args.objects:
        return _list_objects()
    from stori_jax.functional.masks import CROP_REGIONS, TORCH_MODE, TORCH_RADIUS

    print("Presets (game, name: definition):")
    for game, name in list_presets():
        print(f"  {game:<10} {name:<5} {describe_preset(game, name)}")
    print("\nCrop modes (every game): " + ", ".join(
        [f"{m} {'left right top bottom'.split()[m - 1]} half" for m in CROP_REGIONS]
        + [f"{TORCH_MODE} torch (radius {TORCH_RADIUS})"]))
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
    import stori_jax
    from stori_jax.suite import play

    check_int("--steps", args.steps, 1)
    try:
        env = stori_jax.make(args.game, args.preset, num_envs=args.num_envs, seed=args.seed,
                             num_workers=args.num_workers, obs=args.obs,
                             granularity=args.granularity)
    except ValueError as error:  # make's rules, worded with the command's flags
        raise ValueError(re.sub(r"\b(num_envs|num_workers|seed)\b",
                                lambda m: "--" + m.group(1).replace("_", "-"),
                                str(error))) from None
    print(f"{env}")
    with env:
        obs, _ = env.reset()
        stats = play(env, obs, args.seed, max_steps=args.steps,
                            progress=None if args.quiet else f"{args.game} {args.preset or '3.1'}")
    env_steps = args.steps * env.num_envs
    mean = stats["mean_return"]
    print(f"episodes finished : {stats['episodes']}")
    print(f"mean return       : {'n/a (no episode finished)' if mean is None else f'{mean:.2f}'}")
    print(f"events fired      : {stats['events_fired']}")
    print(f"corrupted actions : {stats['corrupted_actions']} of {stats['action_draws']} "
          f"({stats['corrupted_fraction']:.2f}; one draw per "
          f"{'emulator frame' if env.plan.per_frame else 'agent step'} played; a replacement "
          "may be the intended action itself)")
    print(f"concept switches  : {stats['concept_switches']}")
    print(f"masked obs        : {stats['masked_obs']} of {env_steps}")
    rate, timed = stats["env_steps_per_s"], stats["timed_agent_steps"] * env.num_envs
    print("env steps / s     : " + ("n/a (one agent step, which compiles: not timed)"
                                    if rate is None else
                                    f"{rate:.0f} ({timed} steps in {_seconds(stats['elapsed_s'])} s, "
                                    "after the first agent step, which compiles)"))
    return 0


def _seconds(s: float) -> str:
    return f"{s:.1f}" if s >= 1 else f"{s:.3g}"


def check_out(flag: str, path: Path, *, directory: bool) -> None:
    """Fail before any work starts if ``path`` cannot be the output ``directory`` (or file):
    it, or the nearest of its parents that exists, is the wrong kind of thing, or nothing can
    be written there."""
    path = Path(path)
    kind = "directory" if directory else "file"
    if path.exists():
        if path.is_dir() != directory:
            raise ValueError(f"{flag} {path} exists and is not a {kind}")
        if directory:
            _check_writable(flag, path, path)
        else:
            try:  # replaced by the command: it must open for writing (nothing is changed here)
                open(path, "r+b").close()
            except OSError as e:
                raise ValueError(f"{flag} {path}: cannot write it ({e.strerror or e})") from None
        return
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise ValueError(f"{flag} {path}: {parent} is a file, not a directory")
            _check_writable(flag, path, parent)
            return


def _check_writable(flag: str, path: Path, directory: Path) -> None:
    """Something can be created in ``directory`` (tried: a temporary folder, removed at once)."""
    try:
        tempfile.TemporaryDirectory(dir=directory).cleanup()
    except OSError as e:
        raise ValueError(f"{flag} {path}: cannot write in {directory} "
                         f"({e.strerror or e})") from None


def selected_presets(games, presets):
    """The paper's (game, preset) pairs that ``--games`` and ``--presets`` choose (None: all);
    a ValueError naming the flag for an unknown game or a preset none of the games has."""
    from stori_jax import list_presets
    from stori_jax.presets import canonical_game, spelt_as_the_paper

    # an unknown game -> a ValueError naming the allowed ones; 'bank_heist' -> 'BankHeist'
    try:
        wanted = {canonical_game(g) for g in games or []}
    except ValueError as e:
        raise ValueError(f"--games: {e}") from None
    in_games = [(g, n) for g, n in list_presets() if not games or g in wanted]
    allowed = list(dict.fromkeys(n for _, n in in_games))
    unknown = [n for n in presets or [] if spelt_as_the_paper(n) not in allowed]
    if unknown:
        named = list(dict.fromkeys(g for g, _ in in_games))  # the games as the paper spells them
        raise ValueError(f"--presets: unknown {unknown}; allowed"
                         f"{' for ' + ' '.join(named) if games else ''}: {allowed}")
    presets = presets and [spelt_as_the_paper(n) for n in presets]
    chosen = [(g, n) for g, n in in_games if not presets or n in presets]
    if not chosen:
        raise ValueError(f"no paper preset matches --games {games} --presets {presets}")
    return chosen


def _cmd_suite(args) -> int:
    from stori_jax.builder import FRAME_SKIP, check_memory
    from stori_jax.suite import default_out, run_suite

    for name, value in (("--episodes", args.episodes), ("--num-envs", args.num_envs),
                        ("--max-steps", args.max_steps)):
        check_int(name, value, 1)
    if args.seed is not None:
        check_int("--seed", args.seed, 0, MAX_SEED)
    check_memory(args.num_envs, FRAME_SKIP, flag="--num-envs")  # before any preset runs
    if args.out is None:  # the default is checked as a given --out is
        args.out = default_out()
        check_out("--out (default)", args.out, directory=True)
    else:
        check_out("--out", args.out, directory=True)
    games, seed, trained = args.games, 0 if args.seed is None else args.seed, None
    if args.checkpoint is not None:  # a checkpoint plays its own game, on eval's seed
        from stori_jax.plugins import trained_policy

        trained = trained_policy(args.checkpoint)
        games = games or [trained.game]
        if args.seed is None:
            seed = trained.eval_seed
    out = run_suite(selected_presets(games, args.presets), episodes=args.episodes,
                    num_envs=args.num_envs, max_steps=args.max_steps, seed=seed,
                    out=args.out, gallery=not args.no_gallery, progress=not args.quiet,
                    trained=trained, checkpoint=args.checkpoint)
    print((out / "table.md").read_text())
    print(f"wrote {out}/table.md, {out}/results.json" + ("" if args.no_gallery
                                                         else f" and {out}/gallery/"))
    return 0


def _config_for(args):
    import json

    import stori_jax
    from stori_jax.presets import canonical_preset

    if args.preset is not None and args.config is not None:
        raise ValueError("give a PRESET or --config FILE (a reference-format JSON), not both")
    if args.preset is None and args.config is None:  # as `run`: 3.1, for any ale-py game
        return "3.1", stori_jax.Config()
    if args.preset is not None:
        name = canonical_preset(args.game, args.preset)
        return name, stori_jax.preset(args.game, name)
    path = Path(args.config)
    if not path.is_file():
        raise ValueError(f"--config {path}: " + ("is a directory, not a JSON file"
                                                 if path.is_dir() else "no such file"))
    try:
        reference = json.loads(path.read_text(), object_pairs_hook=_object_without_repeats)
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"--config {path} is not valid JSON: {e}") from None
    except _RepeatedKey as e:
        raise ValueError(f"--config {path} gives the key {e} twice in one object (JSON keeps "
                         "the last, which would silently replace the first)") from None
    if not isinstance(reference, dict):
        raise ValueError(f"--config {path} must hold a JSON object (a reference-format "
                         f"config), got {type(reference).__name__}")
    return path.stem, stori_jax.config_from_reference(reference, game=args.game)


class _RepeatedKey(Exception):
    pass


def _object_without_repeats(pairs: list) -> dict:
    """A JSON object's dict (json's object_pairs_hook), refusing a key given twice."""
    seen = set()
    for key, _ in pairs:
        if key in seen:
            raise _RepeatedKey(repr(key))
        seen.add(key)
    return dict(pairs)


PICTURE_SUFFIX = {"show": ".png", "record": ".gif"}  # what each command writes


def _picture_out(args, steps_flag: str, steps: int | None):
    """(name, config, output path) of ``show`` / ``record``, every argument checked before
    anything runs."""
    if steps is not None:
        check_int(steps_flag, steps, 1)
    check_int("--seed", args.seed, 0, MAX_SEED)
    suffix = PICTURE_SUFFIX[args.command]
    if args.out is not None:
        check_out("--out", args.out, directory=False)
        if Path(args.out).suffix.lower() != suffix:
            raise ValueError(f"--out {args.out}: {args.command} writes a "
                             f"{suffix[1:].upper()}; give a path ending in {suffix}")
    name, config = _config_for(args)
    return name, config, args.out or Path(f"{args.game}-{name}{suffix}")


def _cmd_show(args) -> int:
    from stori_jax.visual import contact_sheet

    name, config, out = _picture_out(args, "--steps", args.steps)
    path = contact_sheet(args.game, name, config, out, steps=args.steps, seed=args.seed,
                         progress=True)
    print(f"wrote {path}")
    return 0


def _cmd_record(args) -> int:
    from stori_jax.visual import record_episode

    name, config, out = _picture_out(args, "--max-steps", args.max_steps)
    path = record_episode(args.game, name, config, out, max_steps=args.max_steps, seed=args.seed,
                          progress=True)
    print(f"wrote {path}")
    return 0


INTERRUPTED = 130  # the exit code of a command stopped by Ctrl-C, as a shell reports SIGINT
GAME_HELP = "Breakout, Boxing, Gopher, BankHeist (or any ale-py game, without a preset)"
PRESET_HELP = "paper preset, e.g. 2.1 or 3.2A (`stori-jax list` shows them)"
SEED_HELP = "environment seed (default 0)"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="stori-jax", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    listing = sub.add_parser("list", help="print games, presets and modes")
    listing.add_argument("--objects", action="store_true",
                         help="the games with object tables, their classes, the named RAM events")
    run = sub.add_parser("run", help="run a random policy on a preset and print a summary")
    run.add_argument("game", help=GAME_HELP)
    run.add_argument("preset", nargs="?", default=None,
                     help=PRESET_HELP + "; default 3.1, no stochasticity")
    run.add_argument("--steps", type=int, default=500, help="agent steps per env (default 500)")
    run.add_argument("--num-envs", type=int, default=8, help="envs stepped together (default 8)")
    run.add_argument("--num-workers", type=int, default=None,
                     help="emulator worker processes (default: from the machine's cores)")
    run.add_argument("--seed", type=int, default=0, help=SEED_HELP)
    run.add_argument("--obs", default=None, choices=list(OBS_KINDS),
                     help="observation (default atari84; ram for type 0)")
    run.add_argument("--granularity", default=None, choices=list(GRANULARITIES),
                     help="perturbations per emulator frame or per agent step (default: the "
                          "preset's, frame)")
    run.add_argument("--quiet", action="store_true", help="no progress bar")

    suite = sub.add_parser("suite", help="every paper preset with a random agent (or a "
                                         "trained checkpoint's): table, JSON, gallery")
    suite.add_argument("--games", nargs="+", default=None, help="a subset of the games")
    suite.add_argument("--presets", nargs="+", default=None, help="a subset of preset names")
    suite.add_argument("--episodes", type=int, default=8, help="episodes per preset (default 8)")
    suite.add_argument("--num-envs", type=int, default=8,
                       help="envs stepped together (default 8)")
    suite.add_argument("--max-steps", type=int, default=2500,
                       help="agent steps per preset at most, if episodes are long (default 2500)")
    suite.add_argument("--seed", type=int, default=None,
                       help="environment seed (default 0; with --checkpoint the eval seed "
                            "`stori-jax eval` gives it: never one of its training envs' seeds)")
    suite.add_argument("--checkpoint", type=Path, default=None,
                       help="play a trained agent's checkpoint's policy (sampled) instead of the "
                            "random one; it plays its own game's presets (the gallery shows "
                            "random play)")
    suite.add_argument("--out", type=Path, default=None,
                       help="default results/suite-<date>; an earlier suite run's files there "
                            "are replaced")
    suite.add_argument("--no-gallery", action="store_true", help="no contact sheets")
    suite.add_argument("--quiet", action="store_true", help="no progress bars")

    for command, helptext in (("show", "PNG contact sheet: the preset beside its 3.1 twin"),
                              ("record", "animated GIF of an episode with per-step overlay")):
        p = sub.add_parser(command, help=helptext)
        p.add_argument("game", help=GAME_HELP)
        p.add_argument("preset", nargs="?", default=None,
                       help=PRESET_HELP + "; or --config; default 3.1")
        p.add_argument("--config", default=None, help="a reference-format JSON file instead")
        p.add_argument("--seed", type=int, default=0, help=SEED_HELP)
        suffix = PICTURE_SUFFIX[command][1:]
        p.add_argument("--out", type=Path, default=None,
                       help=f"file to write, ending in .{suffix} (default <game>-<preset>.{suffix}, "
                            f"or <game>-<config file name>.{suffix})")
        if command == "show":
            p.add_argument("--steps", type=int, default=None,
                           help="agent steps to play (or until the episode ends); the sheet "
                                f"shows moments spread over them (default {SHEET_STEPS}; a 2.2 "
                                f"preset's T + {AFTER_SWITCH} if longer, so that it reaches "
                                f"concept 2, at most an episode's {episode_step_cap()} steps)")
        else:
            p.add_argument("--max-steps", type=int, default=1000,
                           help="agent steps at most, if the episode is longer (default 1000)")
    add_commands(sub)  # the plugins' (the baselines: train, eval, table)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.command == "list":
            return _cmd_list(args)
        if args.command == "suite":
            return _cmd_suite(args)
        if args.command == "show":
            return _cmd_show(args)
        if args.command == "record":
            return _cmd_record(args)
        if hasattr(args, "handler"):  # a plugin's command
            return args.handler(args)
        check_int("--steps", args.steps, 1)
        check_int("--seed", args.seed, 0, MAX_SEED)
        return _cmd_run(args)
    except BrokenPipeError:
        # the reader went away (`stori-jax list | head`): stop quietly, and let no later write
        # to stdout (Python's own flush at exit included) fail again
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except (ValueError, OSError) as e:  # bad input, or a path that cannot be read or written
        print(f"stori-jax: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("stori-jax: interrupted", file=sys.stderr)
        return INTERRUPTED


def entry() -> None:
    """The ``stori-jax`` console script: :func:`main`'s exit code.  After Ctrl-C, with every env
    closed by then, it leaves without Python's shutdown: JAX/XLA (0.10) can crash there with a
    segfault when the interrupt landed during a compilation, instead of exiting with 130."""
    code = main()
    if code == INTERRUPTED:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":
    entry()
