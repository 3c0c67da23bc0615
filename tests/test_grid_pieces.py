"""The parts of ``stori-jax grid`` that need no Ray: a trial's spec and run import none, and
what a stopped grid reports finished is what its folder holds."""

from __future__ import annotations

import shutil
import subprocess
import sys
import time
from pathlib import Path

from baselines.commands import run_dir
from baselines.grid.cli import INTERRUPTED, report_outcome
from baselines.grid.outcome import grid_outcome
from baselines.grid.spec import grid_spec, trial_config

RECORDED = Path(__file__).resolve().parents[1] / "baselines" / "results" / "grid-2026-11-29"


def test_a_trials_spec_and_run_import_no_ray():
    code = ("import sys, baselines.grid.spec, baselines.grid.trial, baselines.grid.outcome, "
            "baselines.grid.cli; print(sorted(m for m in sys.modules if m.split('.')[0] == "
            "'ray'))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    assert done.stdout.strip() == "[]"


def test_a_stopped_grid_counts_the_trials_its_folder_holds_evaluations_of(tmp_path, capsys):
    """Stopped by Ctrl-C after two of four trials had written their evaluations (and a table
    row), it said '0 of 4 trials finished': Tune had not heard them end."""
    spec = grid_spec("random", games=["Breakout"], presets=["2.2", "3.2A"], seeds=[0, 7],
                     eval_episodes=5)
    trials = [trial_config(spec, tmp_path, *run) for run in spec.runs]
    for game, preset, seed in spec.runs[:2]:  # Breakout 2.2, seeds 0 and 7: evaluated
        run = run_dir(tmp_path, game, preset, "random", seed)
        run.mkdir(parents=True)
        shutil.copy(run_dir(RECORDED / "random", game, preset, "random", seed)
                    / "eval-random.json", run)
    outcome = grid_outcome([], trials, {}, tmp_path, started=time.perf_counter(),
                           resumed=False)  # Tune returned no result of them
    assert sorted(outcome.finished) == ["Breakout 2.2 seed 0", "Breakout 2.2 seed 7"]
    assert outcome.unfinished == ["Breakout 3.2A seed 0", "Breakout 3.2A seed 7"]
    assert outcome.finished["Breakout 2.2 seed 7"]["phase"] == "done"
    assert report_outcome(outcome, spec, tmp_path) == INTERRUPTED
    out = capsys.readouterr().out
    assert "grid: 2 of 4 trials finished, 2 unfinished" in out
    assert "| Breakout | 2.2 | 1.10 ± 0.42 |" in out  # the table row the two make
