"""software(): what made a result, recorded in every result file the commands write."""

import shutil
import subprocess

import jax
import pytest

from stori_jax import provenance


def test_software_names_the_packages_and_the_code():
    found = provenance.software()
    assert found["packages"]["jax"] == jax.__version__
    assert set(found["packages"]) == set(provenance.PACKAGES)
    assert found["python"].count(".") == 2 and found["machine"]
    repo = provenance.PACKAGE_DIR.parent
    if shutil.which("git") and (repo / ".git").exists():  # this checkout: its HEAD
        head = subprocess.run(["git", "-C", str(repo), "rev-parse", "HEAD"], check=True,
                              capture_output=True, text=True).stdout.strip()
        assert found["commit"].removesuffix("+dirty") == head
    else:  # an installed package, or no git
        assert found["commit"] is None


# every kind of tracked file: code (stori_jax, envpool_bridge, baselines, benchmarks,
# pyproject.toml), whose change makes the commit '+dirty', and results and docs, which do not
CODE_FILES = ("stori_jax/core.py", "stori_jax/backends/envpool.py", "baselines/ppo.py",
              "benchmarks/throughput.py", "pyproject.toml")
NOT_CODE_FILES = ("baselines/results/table.json", "benchmarks/results/run.json", "README.md",
                  "baselines/README.md", "stori_jax/notes.md")
CHECKOUT_FILES = CODE_FILES + NOT_CODE_FILES


@pytest.fixture
def checkout(tmp_path, monkeypatch):
    """A git checkout holding a stori_jax folder, standing in for this package's."""
    package = tmp_path / "repo" / "stori_jax"
    for name in CHECKOUT_FILES:
        (package.parent / name).parent.mkdir(parents=True, exist_ok=True)
        (package.parent / name).write_text("1\n")
    monkeypatch.setattr(provenance, "PACKAGE_DIR", package.resolve())
    if shutil.which("git") is None:
        return None
    git = ["git", "-C", str(package.parent), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run(git + ["init", "-q"], check=True)
    subprocess.run(git + ["add", "."], check=True)
    subprocess.run(git + ["commit", "-q", "-m", "c"], check=True)
    head = subprocess.run(git + ["rev-parse", "HEAD"], check=True, capture_output=True,
                          text=True).stdout.strip()
    return package, head


def test_the_commit_is_the_checkouts_and_says_when_tracked_files_changed(checkout):
    if checkout is None:  # no git on this machine: no commit to record
        assert provenance.code_commit() is None
        return
    package, head = checkout
    assert provenance.code_commit() == head
    (package / "notes.txt").write_text("untracked files do not count\n")
    for name in NOT_CODE_FILES:  # results and docs are not the code
        (package.parent / name).write_text("2\n")
        assert provenance.code_commit() == head, name
    for name in CODE_FILES:  # each alone marks the commit dirty
        subprocess.run(["git", "-C", str(package.parent), "checkout", "-q", "--", "."],
                       check=True)
        (package.parent / name).write_text("2\n")
        assert provenance.code_commit() == head + "+dirty", name


def test_a_package_outside_its_own_checkout_has_no_commit(tmp_path, monkeypatch):
    """A wheel installed in a virtual environment that lies inside some other git checkout:
    that checkout's commit is not the code's."""
    other = tmp_path / "other"
    package = other / ".venv" / "site-packages" / "stori_jax"
    package.mkdir(parents=True)
    monkeypatch.setattr(provenance, "PACKAGE_DIR", package.resolve())
    if shutil.which("git") is not None:
        subprocess.run(["git", "-C", str(other), "init", "-q"], check=True)
    assert provenance.code_commit() is None


def test_the_packages_that_make_a_run_reproduce_are_all_recorded():
    """The module's own promise: JAX (jax and its jaxlib) and ale-py, beside numpy and the
    package itself, each at the version installed."""
    import ale_py
    import jaxlib
    import numpy

    packages = provenance.package_versions()
    assert {"stori-jax", "jax", "jaxlib", "ale-py", "numpy"} <= set(packages)
    assert packages["ale-py"] == ale_py.__version__
    assert packages["jaxlib"] == jaxlib.__version__
    assert packages["numpy"] == numpy.__version__


def test_a_package_that_is_not_installed_is_recorded_as_none(monkeypatch):
    import importlib.metadata

    real = importlib.metadata.version

    def version(name):
        if name == "envpool":
            raise importlib.metadata.PackageNotFoundError(name)
        return real(name)

    monkeypatch.setattr(importlib.metadata, "version", version)
    packages = provenance.package_versions()
    assert packages["envpool"] is None
    assert packages["jax"] == jax.__version__
    assert all(packages[name] for name in ("stori-jax", "jaxlib", "ale-py", "numpy"))
