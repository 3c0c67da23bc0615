"""Output folders a command makes: none is left behind empty when the command fails."""

from __future__ import annotations

import contextlib
from pathlib import Path


@contextlib.contextmanager
def removed_if_left_empty(out: Path):
    """Run the body (which may make ``out``); if it raises, Ctrl-C included, remove ``out`` and
    each parent of it that did not exist before, where they are still empty."""
    out = Path(out)
    created = [d for d in (out, *out.parents) if not d.exists()]  # the deepest first
    try:
        yield
    except BaseException:
        for folder in created:
            if folder.is_dir() and not any(folder.iterdir()):
                folder.rmdir()
        raise
