"""Scripts the tests run in a subprocess (``python script.py`` puts the script's folder first on
``sys.path``) import this checkout's packages, not whichever checkout the environment installed:
a copy of the repository tested with a shared virtual environment tests itself.

One JAX compilation cache serves a whole test run: the xdist workers and every subprocess the
tests start (a training run, a CLI command) load what another process of the run compiled
instead of compiling it again.  It lives in this run's pytest temporary folder (pytest keeps
the last few); its keys hold the compiled program and JAX's version, so an entry is only ever
loaded for the very computation that wrote it.

XLA compiles the run's programs for speed of compilation (``FAST_COMPILE_FLAGS``, unless
``XLA_FLAGS`` sets any of them): optimisation level 0, the CPU's older elemental emitters in
place of its fusion emitters, one codegen thread a program: a quarter of the compile time, which
is most of a short test's.  They change how fast a program runs, not what it computes: the
pinned digests, recorded with XLA's defaults, hold bit for bit, and the recorded training runs
replay within their tolerances.  A jaxlib that does not know a flag would abort on it: the
flags are tried once in a subprocess first, and left out if that fails."""

import importlib.util
import os
from pathlib import Path

import pytest

ROOT = str(Path(__file__).resolve().parents[1])
os.environ["PYTHONPATH"] = os.pathsep.join(
    [ROOT] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p and p != ROOT])

CACHE_SETTINGS = {
    "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0",  # every compilation is worth sharing
    "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "-1",
    # a size bound turns on JAX's file lock: two processes compiling the same program at once
    # never read a half-written entry
    "JAX_COMPILATION_CACHE_MAX_SIZE": str(2 ** 32),
}


FAST_COMPILE_FLAGS = {
    "--xla_backend_optimization_level": "0",
    "--xla_cpu_use_fusion_emitters": "false",
    "--xla_cpu_parallel_codegen_split_count": "1",
}


def _compile_fast() -> None:
    flags = os.environ.get("XLA_FLAGS", "")
    if any(name in flags for name in FAST_COMPILE_FLAGS):
        return  # the user's choice
    fast = f"{flags} " + " ".join(f"{k}={v}" for k, v in FAST_COMPILE_FLAGS.items())
    import subprocess
    import sys

    probe = subprocess.run([sys.executable, "-c", "import jax; jax.jit(lambda x: x + 1)(1)"],
                           env={**os.environ, "XLA_FLAGS": fast.strip()}, capture_output=True,
                           timeout=120)
    if probe.returncode == 0:
        os.environ["XLA_FLAGS"] = fast.strip()


@pytest.hookimpl(trylast=True)  # after pytest's own tmp_path set-up
def pytest_configure(config):
    """Set the run's compilation cache up in the controlling process, before any JAX import and
    before the xdist workers start (they inherit the environment).  A cache the user chose is
    left alone; without ``filelock`` (JAX's lock needs it) there is none."""
    if hasattr(config, "workerinput"):  # the controlling process set the environment up
        return
    _compile_fast()
    if "JAX_COMPILATION_CACHE_DIR" in os.environ:
        return
    if importlib.util.find_spec("filelock") is None:
        return
    cache = config._tmp_path_factory.getbasetemp() / "jax-compilation-cache"
    cache.mkdir(exist_ok=True)
    os.environ["JAX_COMPILATION_CACHE_DIR"] = str(cache)
    for name, value in CACHE_SETTINGS.items():
        os.environ.setdefault(name, value)


@pytest.fixture(autouse=True)
def python_handles_ctrl_c():
    """Every test starts with Python's own SIGINT handler, unblocked: a library a test ran in the
    same process (Ray's Tune and its helpers) may leave its own behind, and the Ctrl-C tests
    (os.kill(os.getpid(), SIGINT)) then saw no KeyboardInterrupt, depending on test order."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    handler = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        if handler is not None:
            signal.signal(signal.SIGINT, handler)


RERUN_AFTER_A_CRASH: set[str] = set()


def _how_the_worker_ended(report) -> str:
    """The dead xdist worker's exit status in words (a signal's name when one killed it) and the
    machine's available memory: what tells a segfault from an OOM kill from an exit."""
    import signal

    popen = getattr(getattr(getattr(getattr(report, "node", None), "gateway", None), "_io", None),
                    "popen", None)
    try:
        code = popen.wait(timeout=5) if popen is not None else None
    except Exception:  # still running, or no longer ours to wait for
        code = None
    ended = ("exit status unknown" if code is None else f"exit code {code}" if code >= 0
             else f"killed by {signal.Signals(-code).name}")
    try:
        with open("/proc/meminfo") as meminfo:
            available = next(line.split()[1] for line in meminfo
                             if line.startswith("MemAvailable"))
        return f"{ended}, {int(available) // 1024} MiB of memory available"
    except (OSError, StopIteration):
        return ended


@pytest.hookimpl(optionalhook=True)  # an xdist hook: a run without xdist has no such hook
def pytest_handlecrashitem(crashitem, report, sched):
    """A test whose xdist worker died is run once more, in the fresh worker xdist starts, and the
    run says so (``R`` and a line naming the test and how the worker ended); a second death
    fails it."""
    ended = _how_the_worker_ended(report)
    again = crashitem not in RERUN_AFTER_A_CRASH
    RERUN_AFTER_A_CRASH.add(crashitem)
    print(f"\n[conftest] the worker running {crashitem} died ({ended}); "
          + ("running it again in a fresh worker" if again else "it died there too: failed"),
          flush=True)
    if again:
        sched.mark_test_pending(crashitem)
        report.outcome = "rerun"


def pytest_report_teststatus(report):
    if report.outcome == "rerun":
        return "rerun", "R", "RERUN"
