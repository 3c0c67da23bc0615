"""What a grid run did (:class:`GridOutcome`): which trials finished, counted from the evaluation
files in its folder (a grid stopped by Ctrl-C has finished the trials it evaluated, whether or
not Tune heard them end), which failed and why, which are unfinished; and its table."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import time
from pathlib import Path

from baselines.grid.progress import table_of
from baselines.grid.spec import label
from baselines.grid.trial import evaluated


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


def grid_outcome(results, trials: list, invalid: dict, out: Path, *, started: float,
                 resumed: bool) -> GridOutcome:
    """What the grid did: Tune's ``results`` (its ResultGrid, or [] where Tune never started)
    for ``trials``, beside ``invalid`` (label -> why a trial was refused before Ray started),
    and the files under ``out``: a trial whose evaluation file is in its run folder has
    finished.  ``started``: ``time.perf_counter()`` when the grid started."""
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
    for trial in trials:  # evaluated, though Tune did not hear it end (stopped by Ctrl-C)
        name = label(trial)
        metrics = None if name in finished else evaluated(trial)
        if metrics is not None:
            finished[name] = metrics
            failed.pop(name, None)
    unfinished = [label(t) for t in trials if label(t) not in finished | failed]
    table, table_error = None, None
    with contextlib.redirect_stderr(io.StringIO()) as notes:
        try:
            table = table_of(out)
        except ValueError as error:
            table_error = str(error)
    return GridOutcome(finished=finished, failed=failed, unfinished=unfinished, table=table,
                       table_notes=notes.getvalue(), table_error=table_error,
                       seconds=time.perf_counter() - started, resumed=resumed)


def _error_line(error) -> str:
    lines = [line for line in str(error).splitlines() if line.strip()]
    return lines[-1].strip() if lines else type(error).__name__
