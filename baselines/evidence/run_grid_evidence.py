"""The evidence behind ``stori-jax grid`` (baselines/results/grid-<date>/): two real grids on
this machine, each timed as the grid command and as the same trials run serially, one after
another in one process with the same code (:func:`baselines.grid.trial.play_trial`, as ``stori-jax
train`` + ``eval`` alone would run them), and the two compared file by file.

- ``random``: the random policy on all 24 paper presets x seeds 0, 7, 13, 5 evaluation
  episodes each (the paper's protocol plays 100; 5 keep both runs, grid and serial, within
  the half hour this shared 2-core machine could give them).
- ``ppo``: PPO on Breakout 3.1 and 1 x seeds 0, 7, 13 at 8,192 agent steps (the recorded
  runs' Breakout settings, ``network=nips num_envs=16 num_steps=64 update_epochs=2
  num_minibatches=8``), trained in 2 parts, 10 evaluation episodes.

    python baselines/evidence/run_grid_evidence.py [--only random ppo] [--work DIR] [--date YYYY-MM-DD]

The machine's load (1-minute load average, sampled every 5 s) is recorded beside each time:
other work on the same cores slows either run.  The grid's outputs (tables, curves, the
evaluations and the PPO runs' logs; no checkpoints) are copied into the results folder with
timing.json.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parents[1] / "results"
GRIDS = {
    "random": dict(agent="random", games=None, presets=None, seeds=(0, 7, 13), steps=None,
                   eval_episodes=5, overrides=(), parts=4),
    "ppo": dict(agent="ppo", games=["Breakout"], presets=["3.1", "1"], seeds=(0, 7, 13),
                steps=8192, eval_episodes=10, parts=2,
                overrides=("network=nips", "num_envs=16", "num_steps=64", "update_epochs=2",
                           "num_minibatches=8")),
}
KEPT = ("eval-*.json", "config.json", "log.csv", "episodes.csv", "summary.json")  # per run


def command(name: str, out: Path) -> list[str]:
    """The ``stori-jax grid`` command line of grid ``name``."""
    g = GRIDS[name]
    argv = ["grid", "--agent", g["agent"], "--seeds", *map(str, g["seeds"]),
            "--eval-episodes", str(g["eval_episodes"]), "--parts", str(g["parts"]),
            "--out", str(out), "--quiet"]
    for flag, key in (("--games", "games"), ("--presets", "presets")):
        if g[key]:
            argv += [flag, *g[key]]
    if g["steps"] is not None:
        argv += ["--steps", str(g["steps"])]
    if g["overrides"]:
        argv += ["--set", *g["overrides"]]
    return argv


class Load:
    """The 1-minute load average, sampled every ``every`` seconds while it runs."""

    def __init__(self, every: float = 5.0):
        self.every, self.samples, self._stop = every, [], threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)

    def _sample(self):
        while not self._stop.is_set():
            self.samples.append(os.getloadavg()[0])
            self._stop.wait(self.every)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()

    def summary(self) -> dict:
        s = self.samples or [os.getloadavg()[0]]
        return dict(min=min(s), mean=sum(s) / len(s), max=max(s), samples=len(s))


def busiest() -> list[str]:
    """The processes using the most CPU right now (``ps``), as evidence of other work."""
    lines = subprocess.run(["ps", "-eo", "pcpu,etime,args", "--sort=-pcpu"], capture_output=True,
                           text=True).stdout.splitlines()
    return [line[:160] for line in lines[1:6]]


def run_grid_command(name: str, out: Path) -> dict:
    """The grid as its command runs it (Ray started and stopped included)."""
    argv = [sys.executable, "-m", "stori_jax.cli", *command(name, out)]
    before = dict(load=os.getloadavg(), busiest=busiest())
    with Load() as load:
        start = time.perf_counter()
        done = subprocess.run(argv, capture_output=True, text=True)
        seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({done.returncode}):\n{done.stderr[-3000:]}")
    return dict(command="stori-jax " + " ".join(command(name, out)), seconds=seconds,
                load_during=load.summary(), before=before, stdout_tail=done.stdout[-2000:])


def run_serial(name: str, out: Path) -> dict:
    """The same trials one after another in this process: :func:`play_trial`, the trial's
    code without Ray, each as ``stori-jax train`` + ``eval`` alone would run it (every core)."""
    from baselines.grid.spec import grid_spec, trial_config
    from baselines.grid.trial import play_trial

    g = GRIDS[name]
    spec = grid_spec(g["agent"], games=g["games"], presets=g["presets"], seeds=g["seeds"],
                     steps=g["steps"], eval_episodes=g["eval_episodes"],
                     overrides=g["overrides"], parts=g["parts"])
    before = dict(load=os.getloadavg(), busiest=busiest())
    with Load() as load:
        start = time.perf_counter()
        for game, preset, seed in spec.runs:
            play_trial(trial_config(spec, out.resolve(), game, preset, seed),
                       report=lambda metrics, run: None)
            print(f"serial {name}: {game} {preset} seed {seed} done "
                  f"({time.perf_counter() - start:.0f} s)", flush=True)
        seconds = time.perf_counter() - start
    return dict(trials=len(spec.runs), seconds=seconds, load_during=load.summary(),
                before=before)


def compare(grid_out: Path, serial_out: Path) -> dict:
    """Each run of the grid beside the same run made serially: the evaluations' episodes, and
    for trained runs the logs (timings apart), episodes and final parameters."""
    import numpy as np

    from baselines.ppo import TIMING_FIELDS

    same, differ = 0, []
    for path in sorted(grid_out.rglob("eval-*.json")):
        if "tune" in path.relative_to(grid_out).parts:
            continue
        run = path.parent.relative_to(grid_out)
        other = serial_out / run / path.name
        a, b = json.loads(path.read_text()), json.loads(other.read_text())
        keys = ("returns", "lengths", "mean_return", "std_return", "eval_seed", "truncated",
                "agent_steps")
        ok = all(a[k] == b[k] for k in keys)
        if (grid_out / run / "log.csv").exists():
            import csv
            import pickle

            import jax

            def log(folder):
                with open(folder / "log.csv", newline="") as f:
                    return [{k: v for k, v in r.items() if k not in TIMING_FIELDS}
                            for r in csv.DictReader(f)]

            ok &= log(grid_out / run) == log(serial_out / run)
            ok &= ((grid_out / run / "episodes.csv").read_text()
                   == (serial_out / run / "episodes.csv").read_text())
            ca, cb = (pickle.loads((f / run / "checkpoint.pkl").read_bytes())
                      for f in (grid_out, serial_out))
            ok &= all(np.array_equal(np.asarray(x), np.asarray(y)) for x, y in zip(
                jax.tree.leaves((ca["params"], ca["opt_state"], ca["key"])),
                jax.tree.leaves((cb["params"], cb["opt_state"], cb["key"]))))
        same += ok
        if not ok:
            differ.append(str(run))
    return dict(runs=same + len(differ), identical=same, differ=differ)


def keep(grid_out: Path, into: Path) -> None:
    """The grid's table, curves and runs (no checkpoints, no Tune state) into ``into``."""
    into.mkdir(parents=True, exist_ok=True)
    for name in ["table.md", "table.json", "grid.json", *(p.name for p in
                                                          grid_out.glob("curves-*.png"))]:
        shutil.copy2(grid_out / name, into / name)
    for pattern in KEPT:
        for path in grid_out.rglob(pattern):
            relative = path.relative_to(grid_out)
            if relative.parts[0] == "tune":
                continue
            (into / relative).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, into / relative)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", nargs="+", choices=list(GRIDS), default=list(GRIDS))
    parser.add_argument("--work", type=Path, default=Path("results") / "grid-evidence",
                        help="where the grid and serial runs are made (checkpoints and Tune's "
                             "state stay there)")
    parser.add_argument("--date", default=datetime.date.today().isoformat())
    args = parser.parse_args()
    from stori_jax.provenance import software

    into = RESULTS / f"grid-{args.date}"
    timing_path = into / "timing.json"
    timing = json.loads(timing_path.read_text()) if timing_path.exists() else {}
    for name in args.only:
        work = args.work / name
        if work.exists():
            shutil.rmtree(work)
        print(f"{name}: grid ...", flush=True)
        grid = run_grid_command(name, work / "grid")
        print(f"{name}: grid {grid['seconds']:.0f} s; serial ...", flush=True)
        serial = run_serial(name, work / "serial")
        same = compare(work / "grid", work / "serial")
        timing[name] = dict(grid=grid, serial=serial, speedup=serial["seconds"] / grid["seconds"],
                            grid_equals_serial=same, cores=len(os.sched_getaffinity(0)),
                            software=software())
        print(f"{name}: grid {grid['seconds']:.0f} s, serial {serial['seconds']:.0f} s, "
              f"speed-up {timing[name]['speedup']:.2f}x; identical runs {same['identical']} of "
              f"{same['runs']}", flush=True)
        keep(work / "grid", into / name)
        into.mkdir(parents=True, exist_ok=True)
        timing_path.write_text(json.dumps(timing, indent=1))


if __name__ == "__main__":
    main()
