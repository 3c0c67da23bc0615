"""The Tune glue: the trainable (one trial in a Ray worker), the callback that feeds the
progress display, and the experiment (``tune.Tuner``, or its restore) that runs a grid's
trials.  Imports Ray: the command imports it once Ray is known to be installed."""

from __future__ import annotations

import contextlib
import json
import logging
import os
import sys
import tempfile
import time
from pathlib import Path

from ray import tune

from baselines.agents import RANDOM
from baselines.grid import cluster, progress
from baselines.grid.outcome import GridOutcome, grid_outcome
from baselines.grid.spec import (DEFAULT_MAX_FAILURES, SPEC_FILE, GridSpec, check_spec,
                                 check_trial, label, trial_config)
from baselines.grid.trial import archive_run, play_trial

TUNE_DIR = "tune"  # --out/tune: Tune's experiment (its state, trial logs and checkpoints)


def tune_trial(config: dict) -> None:
    """The Tune trainable: :func:`play_trial` inside a Ray worker, its emulators held to the
    CPUs Ray reserved for the trial.  A ValueError (the trial cannot run as asked: it would
    fail again the same way) ends the trial with its message as its result, not as an error
    for Tune to retry; anything else (a crash, a lost node) is Tune's to retry from the last
    checkpoint."""
    cluster.keep_omp_as_the_driver_has_it()  # first: before anything imports JAX
    import ray

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


class GridCallback(tune.Callback):
    """Feeds the running grid's :class:`~baselines.grid.progress.GridProgress` (found with
    :func:`~baselines.grid.progress.running`).  It keeps no state of its own: Tune pickles a
    run's callbacks with the experiment and a restored run uses those."""

    def on_step_begin(self, iteration, trials, **info):
        shown = progress.running()
        if shown is not None and shown.bar is None and trials:
            shown.start(trials)

    def on_trial_result(self, iteration, trials, trial, result, **info):
        shown = progress.running()
        if shown is not None:
            shown.update(trial, trials, float(result.get("progress", 0.0)))

    def on_trial_complete(self, iteration, trials, trial, **info):
        shown = progress.running()
        if shown is None:
            return
        error = (trial.last_result or {}).get("error")
        if error:
            shown.failed += 1
            shown.say(f"grid: {trial_label(trial)} failed: {error}")
        shown.update(trial, trials, 1.0, ended=True)
        shown.rebuild_table()

    def on_trial_recover(self, iteration, trials, trial, **info):
        shown = progress.running()
        if shown is not None:
            shown.say(f"grid: {trial_label(trial)}: its process stopped ({_last_line(trial)}); "
                      f"Tune retries it from its last checkpoint (failure {trial.num_failures})")

    def on_trial_error(self, iteration, trials, trial, **info):
        shown = progress.running()
        if shown is None:
            return
        shown.failed += 1
        shown.say(f"grid: {trial_label(trial)} failed {trial.num_failures} times, the last: "
                  f"{_last_line(trial)} (running the grid again retries it)")
        shown.update(trial, trials, 1.0, ended=True)

    def on_experiment_end(self, trials, **info):
        shown = progress.running()
        if shown is not None:
            shown.close()


def trial_label(trial) -> str:
    """A Tune trial's label: its game, preset and seed."""
    return label(trial.config["trial"])


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
    from stori_jax.checks import check_int, check_real

    check_real("--cpus-per-run", cpus_per_run, 0)
    check_real("--gpus-per-run", gpus_per_run, 0)
    if cpus_per_run <= 0:
        raise ValueError(f"--cpus-per-run must be > 0, got {cpus_per_run}")
    check_int("--max-failures", max_failures, 0)
    cluster.check_reachable(address)  # before anything is written (Ray would retry for minutes)
    if cluster.is_client(address) and not Path(out).is_absolute():
        raise ValueError(f"--out {out}: with a ray:// address, give the absolute path of the "
                         "grid's folder on the cluster's shared storage")
    out = Path(out) if cluster.is_client(address) else Path(out).resolve()
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
    if cluster.is_client(address):
        if callbacks:
            raise ValueError("callbacks run in the driver, on the head node for a ray:// "
                             "address: run the grid there (--address auto) to add some")
        return cluster.run_on_head(address, run_grid, spec, out, cpus_per_run=cpus_per_run,
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
    started_ray = cluster.connect(address)
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
                    callbacks=[GridCallback(), *callbacks]))
        with progress.showing(progress.GridProgress(out, len(trials), progress_bar)), \
                _environment(RAY_AIR_NEW_OUTPUT="0",  # Tune's console output off (verbose=0)
                             # a checkpoint replaces the last (num_to_keep=1), so Tune saves
                             # its state each time: cheap here, and no reason for a warning
                             TUNE_WARN_EXCESSIVE_EXPERIMENT_CHECKPOINT_SYNC_THRESHOLD_S="0"):
            results = tuner.fit()
    finally:
        if started_ray:
            import ray

            ray.shutdown()
        _restore_signal_handlers(handlers)
    return grid_outcome(results, trials, invalid, out, started=started, resumed=restoring)


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
