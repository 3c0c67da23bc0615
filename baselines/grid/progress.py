"""What a running grid shows: a progress bar over its trials (fractions of trials as their parts
finish, so its ETA moves before the first trial ends), failures as they come, and the table and
learning curves rewritten as trials finish.  :func:`showing` makes a :class:`GridProgress` the
running grid's, for the Tune callback (:mod:`baselines.grid.tuning`) to find."""

from __future__ import annotations

import contextlib
import io
import sys
import time
from pathlib import Path

TABLE_EVERY_S = 10.0  # the table is rewritten at most this often as trials finish (and at the end)

_RUNNING = None  # the running grid's GridProgress (in the driver), while :func:`showing` it


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


@contextlib.contextmanager
def showing(shown: GridProgress):
    """``shown`` is the running grid's (:func:`running`) for a while, and closed after."""
    global _RUNNING
    _RUNNING = shown
    try:
        yield shown
    finally:
        shown.close()
        _RUNNING = None


def running() -> GridProgress | None:
    """The running grid's progress display in this process (the driver's), if any."""
    return _RUNNING


def table_of(out: Path) -> str:
    """``stori-jax table``'s files for the grid's folder (table.md, table.json, curves)."""
    from baselines.table import build_table

    return build_table(out, out)[0]
