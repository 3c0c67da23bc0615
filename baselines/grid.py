"""``stori-jax grid``: the paper's protocol (games x presets x seeds, train, evaluate, the table
beside the paper's) as one Ray Tune experiment, on this machine's cores or on a Ray cluster.

Ray Tune does the work a grid needs and this module writes none of it itself: the trials and
their scheduling over the cluster's CPUs (``tune.Tuner`` over a ``tune.grid_search``, each trial
``tune.with_resources``), their checkpoints (``tune.report(..., checkpoint=...)``, restored with
``tune.get_checkpoint()``), retries of a trial whose process or node died
(``tune.FailureConfig``) and the restore of a stopped experiment (``tune.Tuner.restore``).

One trial is one (game, preset, seed): the agent's ``train`` (the code ``stori-jax train`` runs)
in parts of whole iterations, each part ending with a checkpoint reported to Tune, then
``evaluate`` + ``write_result`` (the code ``stori-jax eval`` runs); the random policy is only
evaluated.  Its files land in ``--out``/<game>-<preset>/<agent>-seed<S>/, as ``stori-jax train
--out`` and ``eval`` write them, so ``stori-jax table --out`` reads a grid's folder as any other;
Tune's own experiment (state, trial logs, checkpoints) lives in ``--out``/tune/.

A resumed run is bit-identical to an uninterrupted one (the agent's checkpoints hold the envs'
snapshots), so a trial interrupted, retried or moved to another node ends with the files that
``stori-jax train`` + ``eval`` give alone, on the same software and machine type.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import json
import logging
import math
import os
import sys
import tarfile
import tempfile
import time
from pathlib import Path

from baselines.agents import RANDOM, agent_names

TUNE_DIR = "tune"  # --out/tune: Tune's experiment (its state, trial logs and checkpoints)
SPEC_FILE = "grid.json"  # --out/grid.json: the grid's settings, checked when it is run again
RUN_ARCHIVE = "run.tar"  # a Tune checkpoint: the run folder, archived (the table reads
#                         episodes.csv wherever it lies below --out: an archive hides the copy)
PART_FILE = "part.json"  # beside it: how far the run had trained
DEFAULT_SEEDS = (0, 7, 13)  # the paper's
DEFAULT_STEPS = 100_000  # the paper's budget, agent steps
DEFAULT_OUT = Path("results") / "grid"
DEFAULT_PARTS = 4  # a trained run is trained (and checkpointed to Tune) in this many parts
DEFAULT_MAX_FAILURES = 3  # Tune retries a trial whose process died this many times
TABLE_EVERY_S = 10.0  # the table is rewritten at most this often as trials finish (and at the end)
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


# -- the grid's settings ----------------------------------------------------------------------

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


# -- one trial --------------------------------------------------------------------------------

def play_trial(trial: dict, report, checkpoint_dir: Path | None = None) -> dict:
    """Run one trial: train the agent (``stori-jax train``'s code) in ``trial['parts']`` parts,
    then evaluate its final checkpoint (``stori-jax eval``'s code); the random policy is only
    evaluated.  ``report(metrics, run_folder_or_None)`` is called after each part (with the run
    folder: a checkpoint) and once at the end.  ``checkpoint_dir``: the trial's last checkpoint
    reported to Tune, restored into the run folder where that is behind it.  Returns the
    final metrics."""
    from baselines.agents import get_agent
    from baselines.commands import agent_config, run_dir
    from baselines.evaluate import evaluate, result_path, write_result

    out = Path(trial["out"])
    run = run_dir(out, trial["game"], trial["preset"], trial["agent"], trial["seed"])
    metrics = dict(game=trial["game"], preset=trial["preset"], seed=trial["seed"],
                   run_dir=str(run))
    if trial["agent"] == RANDOM:
        policy, checkpoint = "random", None
    else:
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
        policy, checkpoint = "sampled", run / "checkpoint.pkl"
    path = result_path(run, policy)
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
    final = dict(metrics, phase="done", progress=1.0, eval_mean_return=result["mean_return"],
                 eval_std_return=result["std_return"], eval_episodes=result["episodes"],
                 eval_truncated=result["truncated"], eval_seconds=result["seconds"],
                 agent_steps=result.get("trained_agent_steps", 0))
    report(final, None)
    return final


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


OMP_NUM_THREAD_VARIABLE = "STORI_JAX_GRID_OMP_NUM_THREADS"  # the driver's OMP_NUM_THREADS


def keep_omp_as_the_driver_has_it() -> None:
    """OMP_NUM_THREADS as the grid's driver has it (unset, unless set there), not as Ray set it
    for the worker (the trial's CPUs): XLA's OpenMP-threaded CPU kernels round differently
    with another thread count, and a trial must compute what `stori-jax train` computes.  Done
    before this process first uses JAX (OpenMP reads the variable when it starts)."""
    wanted = os.environ.get(OMP_NUM_THREAD_VARIABLE)
    if wanted is None:  # not started by the grid's connect(): nothing known to restore
        return
    if wanted:
        os.environ["OMP_NUM_THREADS"] = wanted
    else:
        os.environ.pop("OMP_NUM_THREADS", None)


def tune_trial(config: dict) -> None:
    """The Tune trainable: :func:`play_trial` inside a Ray worker, its emulators held to the
    CPUs Ray reserved for the trial.  A ValueError (the trial cannot run as asked: it would
    fail again the same way) ends the trial with its message as its result, not as an error
    for Tune to retry; anything else (a crash, a lost node) is Tune's to retry from the last
    checkpoint."""
    keep_omp_as_the_driver_has_it()  # first: before anything imports JAX
    import ray
    from ray import tune

    from baselines.runs import CORES_VARIABLE

    trial = config["trial"]
    reserved = ray.get_runtime_context().get_assigned_resources().get("CPU", 1)
    os.environ[CORES_VARIABLE] = str(max(1, int(reserved)))
    node = ray.get_runtime_context().get_node_id()
    per_iteration = None

    def report(metrics: dict, run: Path | None) -> None:
        metrics = dict(metrics, node_id=node)
        if run is None:
            tune.report(metrics)
            return
        with tempfile.TemporaryDirectory(prefix="stori-jax-grid-") as folder:
            archive_run(run, Path(folder), metrics["agent_steps"], per_iteration)
            tune.report(metrics, checkpoint=tune.Checkpoint.from_directory(folder))

    try:
        if trial["agent"] != RANDOM:
            from baselines.agents import get_agent
            from baselines.commands import agent_config

            agent = get_agent(trial["agent"])
            per_iteration = agent.steps_per_iteration(agent_config(
                agent, trial["game"], trial["preset"], trial["seed"], trial["steps"],
                trial["overrides"]))
        checkpoint = tune.get_checkpoint()
        if checkpoint is None:
            play_trial(trial, report)
        else:
            with checkpoint.as_directory() as folder:
                play_trial(trial, report, Path(folder))
    except ValueError as error:
        tune.report(dict(game=trial["game"], preset=trial["preset"], seed=trial["seed"],
                         phase="failed", progress=1.0, node_id=node,
                         error=f"{type(error).__name__}: {error}"))


# -- the driver -------------------------------------------------------------------------------

@dataclasses.dataclass
class GridOutcome:
    """What a grid run did: per trial label, its final metrics (finished), its error (failed
    before or in the run), or nothing yet (unfinished: the grid was stopped)."""

    finished: dict
    failed: dict
    unfinished: list
    table: str | None
    table_notes: str  # the table's notes, as `stori-jax table` prints them
    table_error: str | None
    seconds: float
    resumed: bool


_SESSION = None  # the running grid's progress bar and table, for GridCallback (in the driver)


class GridProgress:
    """A progress bar over the grid's trials (fractions of trials as their parts finish, so
    its ETA moves before the first trial ends), failures as they come, and the table and
    learning curves rewritten as trials finish."""

    def __init__(self, out: Path, total: int, show: bool):
        self.out, self.total, self.show = out, total, show
        self.bar, self.done, self.last_table = None, {}, 0.0
        self.failed = 0
        # not a terminal (a log file, a Ray task's output): a line as each trial ends instead
        self.lines = not sys.stderr.isatty()

    def start(self, trials) -> None:
        from tqdm import tqdm

        for trial in trials:
            self.done[trial.trial_id] = _trial_progress(trial)
        self.bar = tqdm(total=max(self.total, len(trials)), initial=sum(self.done.values()),
                        unit="trial", desc="grid", disable=not self.show, dynamic_ncols=True,
                        file=io.StringIO() if self.lines else sys.stderr,
                        bar_format="{l_bar}{bar}| {n:.1f}/{total} trials "
                                   "[{elapsed}<{remaining}{postfix}]")
        self.bar.set_postfix_str(self._postfix(trials))

    def _postfix(self, trials) -> str:
        running = sum(t.status == "RUNNING" for t in trials)
        return f"running {running}" + (f", failed {self.failed}" if self.failed else "")

    def update(self, trial, trials, value: float | None = None, ended: bool = False) -> None:
        if self.bar is None:
            self.start(trials)
        self.done[trial.trial_id] = _trial_progress(trial) if value is None else value
        self.bar.n = sum(self.done.values())
        self.bar.set_postfix_str(self._postfix(trials), refresh=False)
        self.bar.refresh()
        if ended and self.lines and self.show:
            print(str(self.bar), file=sys.stderr, flush=True)

    def say(self, text: str) -> None:
        from tqdm import tqdm

        if self.bar is not None and self.show and not self.lines:
            tqdm.write(text, file=sys.stderr)
        else:
            print(text, file=sys.stderr, flush=True)

    def rebuild_table(self, force: bool = False) -> None:
        if not force and time.monotonic() - self.last_table < TABLE_EVERY_S:
            return
        self.last_table = time.monotonic()
        with contextlib.redirect_stderr(io.StringIO()):  # its notes: once, at the end
            try:
                table_of(self.out)
            except ValueError:
                pass

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _trial_progress(trial) -> float:
    if trial.status in ("TERMINATED", "ERROR"):
        return 1.0
    last = trial.last_result or {}
    return float(last.get("progress", 0.0))


def _trial_label(trial) -> str:
    return label(trial.config["trial"])


def _make_callback_class():
    """GridCallback as a ``tune.Callback`` (defined once Ray is importable).  It keeps no
    state of its own: Tune pickles a run's callbacks with the experiment and a restored run
    uses those, so it finds the running grid's :class:`GridProgress` in this process."""
    from ray import tune

    class GridCallback(tune.Callback):
        def on_step_begin(self, iteration, trials, **info):
            if _SESSION is not None and _SESSION.bar is None and trials:
                _SESSION.start(trials)

        def on_trial_result(self, iteration, trials, trial, result, **info):
            if _SESSION is not None:
                _SESSION.update(trial, trials, float(result.get("progress", 0.0)))

        def on_trial_complete(self, iteration, trials, trial, **info):
            if _SESSION is None:
                return
            error = (trial.last_result or {}).get("error")
            if error:
                _SESSION.failed += 1
                _SESSION.say(f"grid: {_trial_label(trial)} failed: {error}")
            _SESSION.update(trial, trials, 1.0, ended=True)
            _SESSION.rebuild_table()

        def on_trial_recover(self, iteration, trials, trial, **info):
            if _SESSION is not None:
                _SESSION.say(f"grid: {_trial_label(trial)}: its process stopped "
                             f"({_last_line(trial)}); Tune retries it from its last checkpoint "
                             f"(failure {trial.num_failures})")

        def on_trial_error(self, iteration, trials, trial, **info):
            if _SESSION is None:
                return
            _SESSION.failed += 1
            _SESSION.say(f"grid: {_trial_label(trial)} failed {trial.num_failures} times, the "
                         f"last: {_last_line(trial)} (running the grid again retries it)")
            _SESSION.update(trial, trials, 1.0, ended=True)

        def on_experiment_end(self, trials, **info):
            if _SESSION is not None:
                _SESSION.close()

    GridCallback.__module__ = __name__
    GridCallback.__qualname__ = "GridCallback"
    globals()["GridCallback"] = GridCallback  # pickled by reference: baselines.grid.GridCallback
    return GridCallback


def grid_callback_class():
    """:class:`GridCallback`, defined on first use (Ray is an optional extra)."""
    return globals().get("GridCallback") or _make_callback_class()


def _last_line(trial) -> str:
    """The last line of a trial's error (Tune keeps the traceback in its error file)."""
    text = None
    try:
        text = trial.get_error()
    except Exception:  # noqa: BLE001 - a missing or unreadable error file: say what we can
        pass
    lines = [line for line in str(text or "").splitlines() if line.strip()]
    return lines[-1].strip() if lines else "no error recorded"


def trial_dirname(trial) -> str:
    """Tune's folder of a trial: its game, preset, agent and seed (and Tune's id)."""
    t = trial.config["trial"]
    return f"{t['game']}-{t['preset']}-{t['agent']}-seed{t['seed']}-{trial.trial_id}"


def table_of(out: Path) -> str:
    """``stori-jax table``'s files for the grid's folder (table.md, table.json, curves)."""
    from baselines.table import build_table

    return build_table(out, out)[0]


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


def connect(address: str | None) -> bool:
    """Connect to Ray: a local instance on this machine's cores (``address`` None), or the
    cluster at ``address`` (``auto``, ``HOST:PORT``, or ``ray://HOST:PORT`` as a Ray Client,
    which hears its task's output).  Returns whether Ray was started or connected here (and is
    to be shut down); a Ray already initialised in this process is used as it is."""
    import ray

    if ray.is_initialized():
        return False
    # Ray starts its workers at niceness 15, below every other process: the trials are the
    # work here (as `stori-jax train` is), so they run at the usual priority.  And Ray sets
    # OMP_NUM_THREADS to a trial's CPUs where it is unset, which changes XLA's float rounding
    # on CPU (its OpenMP-threaded kernels reduce in another order): the trials get the
    # driver's setting back (OMP_NUM_THREAD_VARIABLE, read by tune_trial), so that they compute
    # exactly what `stori-jax train` run from the same shell computes
    env = {"RAY_worker_niceness": "0",
           OMP_NUM_THREAD_VARIABLE: os.environ.get("OMP_NUM_THREADS", "")}
    quiet = dict(log_to_driver=False, logging_level=logging.WARNING,
                 runtime_env={"env_vars": env})
    if address is None:
        from baselines.runs import cores

        ray.init(address="local", num_cpus=cores(), include_dashboard=False, **quiet)
    else:
        try:
            ray.init(address=address, **dict(quiet, log_to_driver=is_client(address)))
        except ConnectionError as error:
            raise ValueError(f"--address {address}: no Ray cluster answered ({error}); start "
                             "one (docs/cluster.md), or leave --address out to start Ray on "
                             "this machine") from None
    return True


def is_client(address: str | None) -> bool:
    """Whether ``address`` is a Ray Client's (``ray://HOST:PORT``)."""
    return address is not None and address.startswith("ray://")


def run_on_head(address: str, spec: GridSpec, out: Path, **settings) -> GridOutcome:
    """The grid driven from the cluster's head node, as ``--address auto`` there would drive
    it, for a Ray Client (``ray://``): Tune, its callbacks (progress, table) and the table live
    beside the cluster's storage, and this machine waits for the outcome (and hears the
    progress lines).  Ctrl-C here stops the grid there (run again to resume)."""
    import ray
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    connect(address)
    try:
        head = next(n["NodeID"] for n in ray.nodes()
                    if n["Alive"] and "node:__internal_head__" in n["Resources"])
        driver = ray.remote(num_cpus=0, max_retries=0)(run_grid).options(
            scheduling_strategy=NodeAffinitySchedulingStrategy(head, soft=False))
        pending = driver.remote(spec, out, **settings)
        try:
            return ray.get(pending)
        except KeyboardInterrupt:
            ray.cancel(pending)  # Tune there stops as after Ctrl-C, its state saved
            raise
    finally:
        ray.shutdown()


def _signal_handlers() -> dict:
    """The handlers Tune replaces (SIGINT, SIGUSR1): it restores them only when its own handler
    fires, so after a finished grid Ctrl-C would only stop a Tune run that is over."""
    import signal

    names = [n for n in ("SIGINT", "SIGUSR1") if hasattr(signal, n)]
    return {getattr(signal, n): signal.getsignal(getattr(signal, n)) for n in names}


def _restore_signal_handlers(handlers: dict) -> None:
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():  # signal.signal's rule
        for number, handler in handlers.items():
            if handler is not None:
                signal.signal(number, handler)


def run_grid(spec: GridSpec, out: Path, *, address: str | None = None,
             cpus_per_run: float = 1, gpus_per_run: float = 0,
             max_failures: int = DEFAULT_MAX_FAILURES, progress_bar: bool = True,
             callbacks=()) -> GridOutcome:
    """Run (or resume) the grid ``spec`` into ``out`` on Ray Tune; ``callbacks``: more
    ``tune.Callback`` objects for a fresh run (a resumed one keeps the first run's)."""
    global _SESSION
    tune = import_tune()
    from stori_jax.checks import check_int, check_real

    check_real("--cpus-per-run", cpus_per_run, 0)
    check_real("--gpus-per-run", gpus_per_run, 0)
    if cpus_per_run <= 0:
        raise ValueError(f"--cpus-per-run must be > 0, got {cpus_per_run}")
    check_int("--max-failures", max_failures, 0)
    if is_client(address) and not Path(out).is_absolute():
        raise ValueError(f"--out {out}: with a ray:// address, give the absolute path of the "
                         "grid's folder on the cluster's shared storage")
    out = Path(out) if is_client(address) else Path(out).resolve()
    trials, invalid = [], {}
    for game, preset, seed in spec.runs:
        trial = trial_config(spec, out, game, preset, seed)
        try:
            check_trial(trial)
        except ValueError as error:
            invalid[label(trial)] = f"{type(error).__name__}: {error}"
            continue
        trials.append(trial)
    if not trials:
        messages = sorted(set(invalid.values()))
        raise ValueError("no trial of the grid can run: " + (
            messages[0].partition(": ")[2] if len(messages) == 1 else "; ".join(
                f"{k}: {v}" for k, v in invalid.items())))
    if is_client(address):
        if callbacks:
            raise ValueError("callbacks run in the driver, on the head node for a ray:// "
                             "address: run the grid there (--address auto) to add some")
        return run_on_head(address, spec, out, cpus_per_run=cpus_per_run,
                           gpus_per_run=gpus_per_run, max_failures=max_failures,
                           progress_bar=progress_bar)
    resumed = check_spec(out, spec)
    experiment = out / TUNE_DIR
    out.mkdir(parents=True, exist_ok=True)
    if not resumed:
        (out / SPEC_FILE).write_text(json.dumps(spec.as_json(), indent=1))
    for name, error in invalid.items():
        print(f"grid: {name} cannot run: {error}", file=sys.stderr)

    started = time.perf_counter()
    handlers = _signal_handlers()  # Tune replaces SIGINT's and leaves its own behind
    started_ray = connect(address)
    session = GridProgress(out, len(trials), progress_bar)
    _SESSION = session
    # restoring after a stop, Tune warns of each trial that had reported nothing yet: the
    # outcome says which trials are unfinished
    logging.getLogger("ray.tune.analysis.experiment_analysis").setLevel(logging.ERROR)
    try:
        trainable = tune.with_resources(tune_trial, {"cpu": cpus_per_run, "gpu": gpus_per_run})
        restoring = tune.Tuner.can_restore(str(experiment))
        if restoring:
            tuner = tune.Tuner.restore(str(experiment), trainable, resume_errored=True)
        else:
            tuner = tune.Tuner(
                trainable,
                param_space={"trial": tune.grid_search(trials)},
                tune_config=tune.TuneConfig(reuse_actors=True,
                                            trial_dirname_creator=trial_dirname),
                run_config=tune.RunConfig(
                    storage_path=str(out), name=TUNE_DIR, verbose=0, log_to_file=True,
                    failure_config=tune.FailureConfig(max_failures=max_failures),
                    checkpoint_config=tune.CheckpointConfig(num_to_keep=1),
                    callbacks=[grid_callback_class()(), *callbacks]))
        with _environment(RAY_AIR_NEW_OUTPUT="0",  # Tune's own console output off (verbose=0)
                          # a checkpoint replaces the last (num_to_keep=1), so Tune saves its
                          # state each time: cheap here, and no reason for a warning
                          TUNE_WARN_EXCESSIVE_EXPERIMENT_CHECKPOINT_SYNC_THRESHOLD_S="0"):
            results = tuner.fit()
    finally:
        session.close()
        _SESSION = None
        if started_ray:
            import ray

            ray.shutdown()
        _restore_signal_handlers(handlers)
    finished, failed = {}, dict(invalid)
    for result in results:
        trial = (result.config or {}).get("trial")  # None: a trial stopped before it started
        if trial is None:
            continue
        name, metrics = label(trial), result.metrics or {}
        if result.error is not None:
            failed[name] = _error_line(result.error)
        elif metrics.get("error"):
            failed[name] = metrics["error"]
        elif metrics.get("phase") == "done":
            finished[name] = metrics
    unfinished = [label(t) for t in trials if label(t) not in finished | failed]
    table, table_error = None, None
    with contextlib.redirect_stderr(io.StringIO()) as notes:
        try:
            table = table_of(out)
        except ValueError as error:
            table_error = str(error)
    return GridOutcome(finished=finished, failed=failed, unfinished=unfinished, table=table,
                       table_notes=notes.getvalue(), table_error=table_error,
                       seconds=time.perf_counter() - started, resumed=restoring)


@contextlib.contextmanager
def _environment(**values):
    """Environment variables set for a while (those the user set are left as they are)."""
    added = [k for k in values if k not in os.environ]
    for k in added:
        os.environ[k] = values[k]
    try:
        yield
    finally:
        for k in added:
            os.environ.pop(k, None)


def _error_line(error) -> str:
    lines = [line for line in str(error).splitlines() if line.strip()]
    return lines[-1].strip() if lines else type(error).__name__


# -- the command ------------------------------------------------------------------------------

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


def __getattr__(name):
    if name == "GridCallback":  # a tune.Callback: defined on first use, Ray being optional
        return _make_callback_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
