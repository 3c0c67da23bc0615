"""Where the time of one agent step goes: the calling process's wall time by phase, and the CPU
time of it (XLA's threads included) and of its emulator workers, in ms per step of B envs.

    python benchmarks/profile_step.py                       # Breakout 3.1, B = 32, both obs
    python benchmarks/profile_step.py --presets 3.1 1 --obs atari84 --batch 64 --repeats 3

Each configuration is run with the default worker split once per ``--frame-work`` value (the
observation made by the emulating processes, or by JAX in this process: make's
``frame_work``), ``--repeats`` times, interleaved.  Phases of the calling process:

- send: actions checked, the step's draws (JAX, or numpy where nothing is random), inputs
  written, commands sent;
- emulate here: the envs this process emulates itself;
- wait: blocked on the workers' replies;
- finish: the JAX end (masks, pooling, preprocessing where the caller does them, the stack,
  info) handed to XLA and finished (the rest of recv);
- agent: the loop's own work between steps (random actions here).

Writes benchmarks/results/profile-<date>-<host>[-options].{json,md}.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import socket
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _checks import options_in_name, output_directory  # noqa: E402

PHASES = ("send", "emulate here", "wait", "finish", "agent")


def _cpu_ms(pid: int) -> float:
    """CPU time (user + system) of process ``pid`` so far, in ms."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) * 1000.0 / os.sysconf("SC_CLK_TCK")


def profile(game: str, preset: str, obs: str, batch: int, steps: int,
            frame_work: str = "workers") -> dict:
    """ms per step of each phase, and CPU ms per step of this process and of the workers."""
    import jax

    import stori_jax

    env = stori_jax.make(game, preset, num_envs=batch, seed=0, obs=obs, frame_work=frame_work)
    spent = dict.fromkeys(PHASES, 0.0)

    def timed(phase, fn):
        def wrapper(*args, **kw):
            start = time.perf_counter()
            try:
                return fn(*args, **kw)
            finally:
                spent[phase] += time.perf_counter() - start
        return wrapper

    backend = env.backend
    inline = [e for e in getattr(backend, "_inline", [])]
    for emulator in inline:
        emulator.step = timed("emulate here", emulator.step)
    backend._wait_all = timed("wait", backend._wait_all)
    recv_total = [0.0]
    rng = np.random.default_rng(0)
    try:
        env.reset()
        for _ in range(20):  # compile and warm up
            env.step(rng.integers(0, env.num_actions, batch))
        for phase in spent:
            spent[phase] = 0.0
        pids = [p.pid for p in getattr(backend, "processes", [])]
        cpu_here, cpu_workers = _cpu_ms(os.getpid()), sum(_cpu_ms(p) for p in pids)
        start = time.perf_counter()
        for _ in range(steps):
            t0 = time.perf_counter()
            actions = rng.integers(0, env.num_actions, batch)
            t1 = time.perf_counter()
            env.send(actions)
            t2 = time.perf_counter()
            out = env.recv()
            t3 = time.perf_counter()
            spent["agent"] += t1 - t0
            spent["send"] += t2 - t1
            recv_total[0] += t3 - t2
        jax.block_until_ready(out)
        wall = time.perf_counter() - start
        cpu_here = _cpu_ms(os.getpid()) - cpu_here
        cpu_workers = sum(_cpu_ms(p) for p in pids) - cpu_workers
    finally:
        env.close()
    in_recv = spent["emulate here"] + spent["wait"]
    spent["finish"] = recv_total[0] - in_recv
    per_step = {phase: 1000 * spent[phase] / steps for phase in PHASES}
    return dict(game=game, preset=preset, obs=obs, B=batch, frame_work=frame_work,
                frames_layout=env.plan.frames_layout, inline_envs=len(inline), workers=len(pids),
                steps_per_s=steps * batch / wall, wall_ms_per_step=1000 * wall / steps,
                phases_ms=per_step, cpu_ms_here=cpu_here / steps,
                cpu_ms_workers=cpu_workers / steps)


def markdown(rows, meta) -> str:
    lines = [f"# A step's time, {meta['date']} on {meta['host']} ({meta['cores']} cores)", "",
             "ms per agent step of B envs: the calling process's wall time by phase, then CPU "
             "time of the calling process (XLA's threads included) and of its workers.", "",
             "| game | preset | obs | B | frame work (frames sent) | split (workers + here) | "
             "steps/s | wall ms | " + " | ".join(PHASES) + " | CPU here | CPU workers |",
             "|" + "---|" * (10 + len(PHASES))]
    for r in rows:
        lines.append(
            f"| {r['game']} | {r['preset']} | {r['obs']} | {r['B']} | "
            f"{r.get('frame_work', 'caller')} ({r.get('frames_layout', 'pooled')}) | "
            f"{r['workers']} + {r['inline_envs']} | {r['steps_per_s']:.0f} | "
            f"{r['wall_ms_per_step']:.2f} | "
            + " | ".join(f"{r['phases_ms'][p]:.2f}" for p in PHASES)
            + f" | {r['cpu_ms_here']:.2f} | {r['cpu_ms_workers']:.2f} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--game", default="Breakout")
    parser.add_argument("--presets", nargs="+", default=["3.1"])
    parser.add_argument("--obs", nargs="+", default=["raw", "atari84"])
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--steps", type=int, default=300, help="timed steps per run (default 300)")
    parser.add_argument("--frame-work", nargs="+", default=["workers", "caller"],
                        choices=["workers", "caller"],
                        help="where the frame work runs (make's frame_work), one run each "
                             "(default both)")
    parser.add_argument("--repeats", type=int, default=1,
                        help="run every configuration this many times, interleaved (default 1)")
    parser.add_argument("--out", type=Path, default=HERE / "results")
    args = parser.parse_args(argv)
    output_directory(parser, args.out)
    from stori_jax.provenance import software

    rows = []
    for _ in range(args.repeats):
        for preset in args.presets:
            for obs in args.obs:
                for frame_work in args.frame_work:
                    rows.append(profile(args.game, preset, obs, args.batch, args.steps,
                                        frame_work))
    meta = dict(date=datetime.date.today().isoformat(), host=socket.gethostname(),
                cores=len(os.sched_getaffinity(0)), load=os.getloadavg(), software=software(),
                argv=sys.argv[1:] if argv is None else list(argv))
    args.out.mkdir(parents=True, exist_ok=True)
    stem = args.out / (f"profile-{meta['date']}-{meta['host']}" + options_in_name(
        parser, args, dict(game="", presets="", obs="", batch="B", steps="steps", frame_work="",
                           repeats="x")))
    Path(f"{stem}.json").write_text(json.dumps(dict(meta=meta, rows=rows), indent=1))
    table = markdown(rows, meta)
    Path(f"{stem}.md").write_text(table)
    print(table)
    print(f"wrote {stem}.json, {stem}.md")


if __name__ == "__main__":
    main()
