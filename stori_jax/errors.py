"""The exceptions stori-jax raises beside ``ValueError`` (bad input) and ``TimeoutError``.

Also importable as ``stori_jax.<Name>`` and from the modules that raised them before this
module existed (``stori_jax.backends.subproc``)."""

from __future__ import annotations


class EnvClosedError(RuntimeError):
    """The environment was used after ``close()`` (or a worker's death closed it)."""


class WorkerError(RuntimeError):
    """An emulator worker process died or failed; the environment is closed."""


class InterruptedStepError(RuntimeError):
    """A step was interrupted inside emulation in the calling process; the env needs
    ``reset()``."""


class ConcurrentUseError(RuntimeError):
    """A call of an env while another call of the same env runs in another thread (an env
    serves one call at a time)."""


class EnvStateError(RuntimeError):
    """A call the env's lifecycle does not allow now (e.g. ``send`` before ``reset``); the
    message says what to call instead."""


class WorkersLateError(TimeoutError):
    """Workers did not reply within a ``recv`` timeout; the command stays in flight."""

    def __init__(self, what: str, workers: list[int], pids: list[int]):
        self.what, self.workers, self.pids = what, workers, pids
        super().__init__(f"emulator worker(s) {workers} (pids {pids}) did not finish {what}")
