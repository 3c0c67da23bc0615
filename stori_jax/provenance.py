"""What made a result: the software versions and the code's commit, recorded beside it.

Runs reproduce bit for bit only with the same JAX and ale-py (and, for training, the same
machine): ``software()`` goes into every result file the commands write (evaluations, training
summaries, suite results, benchmarks), so a published number can be matched to its software.
"""

from __future__ import annotations

import importlib.metadata
import platform
import subprocess
from pathlib import Path

PACKAGES = ("stori-jax", "jax", "jaxlib", "ale-py", "numpy", "flax", "optax", "envpool")
PACKAGE_DIR = Path(__file__).resolve().parent
# the code, relative to the checkout: a change elsewhere (results, docs) leaves it clean
CODE_PATHS = ("stori_jax", "envpool_bridge", "baselines", "benchmarks", "pyproject.toml",
              ":!baselines/results", ":!benchmarks/results", ":!*.md")


def package_versions() -> dict:
    """Installed version of each of PACKAGES (None where it is not installed)."""
    versions = {}
    for name in PACKAGES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def _git(*args: str) -> str | None:
    try:  # no optional locks: a status must not hold the index while the user commits
        done = subprocess.run(["git", "--no-optional-locks", "-C", str(PACKAGE_DIR), *args],
                              capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired):  # no git here
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def code_commit() -> str | None:
    """The git commit of the stori_jax code in use, with '+dirty' where tracked code (CODE_PATHS)
    differs from it; None where the package is not in its own git checkout (an installed wheel)."""
    top = _git("rev-parse", "--show-toplevel")
    if top is None or Path(top).resolve() / "stori_jax" != PACKAGE_DIR:
        return None  # not a checkout of this project (a site-packages inside another repo)
    commit = _git("rev-parse", "HEAD")
    if commit is None:
        return None
    changes = _git("-C", top, "status", "--porcelain", "--untracked-files=no", "--", *CODE_PATHS)
    return commit + ("+dirty" if changes else "")


def software() -> dict:
    """Python, the machine's architecture, the code's commit and the package versions."""
    return dict(python=platform.python_version(), machine=platform.machine(),
                commit=code_commit(), packages=package_versions())
