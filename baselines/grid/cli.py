"""``stori-jax grid``: its flags, the run, and the report of what the grid did."""

from __future__ import annotations

import sys
from pathlib import Path

from baselines.agents import RANDOM, agent_names
from baselines.grid.cluster import is_client
from baselines.grid.outcome import GridOutcome
from baselines.grid.spec import (DEFAULT_MAX_FAILURES, DEFAULT_OUT, DEFAULT_PARTS,
                                 DEFAULT_SEEDS, DEFAULT_STEPS, GridSpec, grid_spec)

INSTALL = ("stori-jax grid runs on Ray Tune, an optional extra: pip install -e \".[ray]\" in a "
           "checkout of stori-jax, or pip install \"ray[tune,client]>=2.40\"")
INTERRUPTED = 130


def import_tune():
    """``ray.tune``, or a clear error saying how to install it."""
    try:
        from ray import tune
    except ImportError as error:
        raise ValueError(f"{INSTALL} ({error})") from None
    return tune


def add_parser(sub) -> None:
    grid = sub.add_parser(
        "grid", help="the paper's protocol (games x presets x seeds: train, evaluate, table) "
                     "as one Ray Tune experiment, on this machine's cores or a Ray cluster; "
                     "run it again to resume")
    grid.set_defaults(handler=cmd_grid)
    grid.add_argument("--agent", required=True, choices=agent_names() + [RANDOM],
                      help="the algorithm, or random (the uniformly random policy: evaluated "
                           "only)")
    grid.add_argument("--games", nargs="+", default=None,
                      help="default: Breakout Boxing Gopher BankHeist")
    grid.add_argument("--presets", nargs="+", default=None,
                      help="default: every paper preset of each game")
    grid.add_argument("--seeds", nargs="+", type=int, default=list(DEFAULT_SEEDS),
                      help="training seeds (default 0 7 13, the paper's)")
    grid.add_argument("--steps", type=int, default=None,
                      help=f"agent steps of training per run (default {DEFAULT_STEPS}; not for "
                           "random)")
    grid.add_argument("--eval-episodes", type=int, default=100,
                      help="evaluation episodes per run (default 100, the paper's protocol)")
    grid.add_argument("--max-episode-frames", type=int, default=None,
                      help="evaluation episodes are cut off after this many emulator frames "
                           "(default 108000, as eval)")
    grid.add_argument("--set", dest="overrides", action="extend", nargs="+", default=[],
                      metavar="FIELD=VALUE",
                      help="hyperparameters as train takes them (--set a=1 b=2, or --set a=1 "
                           "--set b=2)")
    grid.add_argument("--out", type=Path, default=DEFAULT_OUT,
                      help=f"the grid's folder (default {DEFAULT_OUT}): runs in "
                           "<game>-<preset>/<agent>-seed<S>/, table.md, curves, Tune's "
                           "experiment in tune/; on a cluster, storage every node mounts at "
                           "this path")
    grid.add_argument("--address", default=None,
                      help="a running Ray cluster: auto (the one this machine belongs to), "
                           "HOST:PORT of its head, or ray://HOST:PORT (Ray Client: the grid is "
                           "driven from the head; --out is the cluster's path) (default: start "
                           "Ray here, on this machine's cores; docs/cluster.md)")
    grid.add_argument("--cpus-per-run", type=float, default=1,
                      help="CPUs Ray reserves per trial; its emulator workers use as many "
                           "(default 1)")
    grid.add_argument("--gpus-per-run", type=float, default=0,
                      help="GPUs Ray reserves per trial (default 0)")
    grid.add_argument("--parts", type=int, default=DEFAULT_PARTS,
                      help="a trained run is trained in this many parts, each checkpointed to "
                           f"Tune: a lost trial loses at most one (default {DEFAULT_PARTS})")
    grid.add_argument("--max-failures", type=int, default=DEFAULT_MAX_FAILURES,
                      help="times Tune retries a trial whose process or node died, from its "
                           f"last checkpoint (default {DEFAULT_MAX_FAILURES})")
    grid.add_argument("--quiet", action="store_true", help="no progress bar")


def cmd_grid(args) -> int:
    from stori_jax.cli import check_out

    import_tune()  # before anything: say how to install it
    from baselines.grid.tuning import run_grid

    spec = grid_spec(args.agent, games=args.games, presets=args.presets, seeds=args.seeds,
                     steps=args.steps, eval_episodes=args.eval_episodes,
                     max_episode_frames=args.max_episode_frames, overrides=args.overrides,
                     parts=args.parts)
    if not is_client(args.address):  # a ray:// grid's folder is the cluster's, not here
        check_out("--out", args.out, directory=True)
    outcome = run_grid(spec, args.out, address=args.address, cpus_per_run=args.cpus_per_run,
                       gpus_per_run=args.gpus_per_run, max_failures=args.max_failures,
                       progress_bar=not args.quiet)
    return report_outcome(outcome, spec, Path(args.out))


def report_outcome(outcome: GridOutcome, spec: GridSpec, out: Path) -> int:
    """Print the table and what the grid did; the exit code (0: every trial finished; 1: some
    failed; 130: stopped, to be resumed)."""
    if outcome.table is not None:
        print(outcome.table)
        sys.stderr.write(outcome.table_notes)
        print(f"wrote {out}/table.md, table.json and curves-<game>.png")
    elif outcome.table_error:
        print(f"grid: no table yet: {outcome.table_error}", file=sys.stderr)
    total = len(spec.runs)
    print(f"grid: {len(outcome.finished)} of {total} trials finished"
          + (f", {len(outcome.failed)} failed" if outcome.failed else "")
          + (f", {len(outcome.unfinished)} unfinished" if outcome.unfinished else "")
          + f" ({'resumed; ' if outcome.resumed else ''}{outcome.seconds:.0f} s)")
    for name, error in outcome.failed.items():
        print(f"grid: failed: {name}: {error}", file=sys.stderr)
    if outcome.unfinished:
        print("grid: stopped before every trial finished: run the same command again to "
              "resume (finished trials are not run again; the others continue from their "
              "last checkpoints)", file=sys.stderr)
        return INTERRUPTED
    return 1 if outcome.failed else 0
