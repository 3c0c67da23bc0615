"""The parts of ``stori-jax grid`` that need no Ray: a trial's spec and run import none."""

from __future__ import annotations

import subprocess
import sys


def test_a_trials_spec_and_run_import_no_ray():
    code = ("import sys, baselines.grid.spec, baselines.grid.trial, baselines.grid.outcome, "
            "baselines.grid.cli; print(sorted(m for m in sys.modules if m.split('.')[0] == "
            "'ray'))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    assert done.stdout.strip() == "[]"

