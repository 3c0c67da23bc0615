"""Connecting to Ray: a local Ray on this machine's cores, or a running cluster by address (its
head checked first to accept connections); driving the grid from the head for a Ray Client;
and the environment a trial's Ray worker gets back from the driver."""

from __future__ import annotations

import logging
import os
import socket

OMP_NUM_THREAD_VARIABLE = "STORI_JAX_GRID_OMP_NUM_THREADS"  # the driver's OMP_NUM_THREADS
CONNECT_TIMEOUT_S = 5.0  # how long the head at --address has to accept a connection


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


def check_reachable(address: str | None, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """A ValueError naming ``address`` (``HOST:PORT`` or ``ray://HOST:PORT``) unless something
    there accepts a TCP connection within ``timeout`` seconds: Ray itself would retry for
    minutes.  None (a local Ray) and ``auto`` are Ray's to find."""
    if address is None or address == "auto":
        return
    host, colon, port = address.removeprefix("ray://").rpartition(":")
    if not colon or not host or not port.isdigit():
        raise ValueError(f"--address {address}: give auto, HOST:PORT or ray://HOST:PORT")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as error:
        raise ValueError(f"--address {address}: nothing accepts connections at {host}:{port} "
                         f"({error}); start a Ray cluster there (docs/cluster.md), or leave "
                         "--address out to start Ray on this machine") from None


def is_client(address: str | None) -> bool:
    """Whether ``address`` is a Ray Client's (``ray://HOST:PORT``)."""
    return address is not None and address.startswith("ray://")


def run_on_head(address: str, run_grid, *args, **kwargs):
    """``run_grid(*args, **kwargs)`` on the cluster's head node, as ``--address auto`` there
    would drive the grid, for a Ray Client (``ray://``): Tune, its callbacks (progress, table)
    and the table live beside the cluster's storage, and this machine waits for the outcome
    (and hears the progress lines).  Ctrl-C here stops the grid there (run again to resume)."""
    import ray
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    connect(address)
    try:
        head = next(n["NodeID"] for n in ray.nodes()
                    if n["Alive"] and "node:__internal_head__" in n["Resources"])
        driver = ray.remote(num_cpus=0, max_retries=0)(run_grid).options(
            scheduling_strategy=NodeAffinitySchedulingStrategy(head, soft=False))
        pending = driver.remote(*args, **kwargs)
        try:
            return ray.get(pending)
        except KeyboardInterrupt:
            ray.cancel(pending)  # Tune there stops as after Ctrl-C, its state saved
            raise
    finally:
        ray.shutdown()
