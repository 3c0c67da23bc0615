"""The backend protocol: what :class:`stori_jax.Env` asks of the emulators, whoever runs
them (``subproc``: this package's worker processes; ``envpool``: envpool's threads).

One step: the env writes the step's inputs into ``views`` (executed actions per frame, event
uniforms, render bits, no-ops, the envs to reset first), calls ``send_step()``, then
``recv()``, which returns the outputs (frames, RAM, reward, flags, ...; see
``stori_jax.backends.layout``) as arrays valid until the next send.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np


class Backend(Protocol):
    name: str  # as make() takes it: "subproc" or "envpool"
    frames_layout: str  # how recv()'s frames are laid out: "pair", "pooled" or "pooled_chw"
    can_time_out: bool  # recv(timeout=...) is honoured
    can_snapshot: bool  # snapshot() / restore() work
    views: dict[str, np.ndarray]  # the step's inputs (written by the env) and outputs

    @property
    def closed(self) -> bool: ...

    @property
    def pending(self) -> bool:
        """A command was sent and its result not yet taken (e.g. its wait was interrupted)."""

    @property
    def half_stepped(self) -> bool:
        """A step was interrupted inside emulation: only a reset continues."""

    def send_reset(self, seed: int | None = None) -> None:
        """Reset every emulator; with ``seed``, first restart each as a new env of that seed."""

    def send_step(self) -> None:
        """Step every emulator with the inputs in ``views``."""

    def recv(self, timeout: float | None = None) -> dict[str, np.ndarray]:
        """Wait for the whole command in flight; :meth:`outputs` (``WorkersLateError`` past
        ``timeout``, the command still pending)."""

    def outputs(self) -> dict[str, np.ndarray]:
        """The last command's outputs by name (frames in ``frames_layout``)."""

    def snapshot(self) -> list[dict]:
        """Every emulator's state, picklable (ValueError where ``can_snapshot`` is False)."""

    def restore_differences(self, states: list[dict]) -> list[str]:
        """How ``states`` differ from these emulators in what a restore cannot change."""

    def restore(self, states: list[dict]) -> None:
        """Put every emulator back in a state of :meth:`snapshot`."""

    def close(self) -> None:
        """Release the emulators; in a process forked from the owner, only this copy's
        handles."""
