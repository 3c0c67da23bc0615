"""Throughput of stori-jax next to the emulator limit and its peers, in ONE run on one machine.

    python benchmarks/throughput.py            # everything (about 18 minutes on 2 cores)
    python benchmarks/throughput.py --quick    # Breakout only, fewer sizes (about 7 minutes)
    python benchmarks/throughput.py --games Boxing --presets 3.1 2.2   # a subset
    python benchmarks/throughput.py --presets 3.1 --sizes 8 32   # the Breakout 3.1 sweep's B

Measured (agent steps per second, frame skip 4, summed over the batch):
- emulator limit: W plain processes each looping bare ``ale_py.ALEInterface`` emulators doing
  exactly the per-step work of a worker (4 frames, two screens, one RAM read), no signalling;
- raw envpool (same B, W threads, raw RGB) and ale-py's ``AtariVectorEnv``;
- the naive way: gymnasium AsyncVectorEnv, one process per env, numpy STORI wrappers;
- stori-jax on both backends for every paper preset, obs ``raw`` and ``atari84``, and a sweep
  over B for 3.1.  envpool rows run ``granularity="step"`` (what that backend supports); the
  presets it cannot run have no envpool row.

2.2 presets switch concept at agent step T of each episode (300 or 600 in the paper's presets),
so their runs warm up for T steps and are timed from there, in concept 2 for every env whose
episode has not ended before T (with a random policy, Breakout's rarely last that long); the
table's "concept 2" column gives the share of timed steps spent in concept 2.  The naive
baseline follows the same schedule and warm-up.

Writes benchmarks/results/<date>-<host>.json, a markdown table (.md) and PNG plots.
"""

from __future__ import annotations

import argparse
import datetime
import importlib.util
import json
import math
import multiprocessing as mp
import os
import socket
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _checks import (fits_in_memory, options_in_name, output_directory,  # noqa: E402
                     require_at_least_one, stori_games)

FRAME_SKIP = 4
WINDOWS = 3  # each rate is the median over this many equal windows (the machine is noisy)


def cores() -> int:
    return len(os.sched_getaffinity(0))


# -- the emulator limit ---------------------------------------------------------------------

def _limit_emulators(rom_id, n, first_seed=0):
    from ale_py import ALEInterface, LoggerMode, roms

    ALEInterface.setLoggerMode(LoggerMode.Error)
    emus = []
    for i in range(n):
        ale = ALEInterface()
        ale.setInt("random_seed", first_seed + i)
        ale.setFloat("repeat_action_probability", 0.0)
        ale.loadROM(roms.get_rom_path(rom_id))
        emus.append((ale, ale.getMinimalActionSet()))
    return emus


def _limit_worker(rom_id, n, seconds, start, out):
    emus = _limit_emulators(rom_id, n)
    screens = np.zeros((n, 2, 210, 160, 3), np.uint8)
    ram = np.zeros((n, 128), np.uint8)
    rng = np.random.default_rng(0)
    start.wait()
    counts = []
    for _ in range(WINDOWS):
        steps, t_end = 0, time.perf_counter() + seconds / WINDOWS
        while time.perf_counter() < t_end:
            _limit_step(emus, screens, ram, rng)
            steps += n
        counts.append(steps)
    out.put(counts)


def _limit_step(emus, screens, ram, rng):
    for e, (ale, actions) in enumerate(emus):
        a = actions[rng.integers(len(actions))]
        for f in range(FRAME_SKIP):
            ale.act(a)
            if f >= FRAME_SKIP - 2:
                ale.getScreenRGB(screens[e, f - FRAME_SKIP + 2])
        ale.getRAM(ram[e])
        if ale.game_over():
            ale.reset_game()


def emulator_limit(game, batch, workers, seconds):
    from stori_jax.games import get_game

    ctx = mp.get_context("spawn")
    start, out = ctx.Event(), ctx.Queue()
    sizes = [len(r) for r in np.array_split(np.arange(batch), workers)]
    procs = [ctx.Process(target=_limit_worker,
                         args=(get_game(game).rom_id, n, seconds, start, out)) for n in sizes]
    for p in procs:
        p.start()
    time.sleep(1.5)  # let every worker load its ROMs
    start.set()
    per_window = np.sum([out.get() for _ in procs], axis=0)
    for p in procs:
        p.join()
    return float(np.median(per_window)) / (seconds / WINDOWS)


def _lockstep_worker(rom_id, n, conn):
    emus = _limit_emulators(rom_id, n, first_seed=1000)
    screens, ram = np.zeros((n, 2, 210, 160, 3), np.uint8), np.zeros((n, 128), np.uint8)
    rng = np.random.default_rng(1)
    conn.send_bytes(b"K")
    while conn.recv_bytes() == b"S":
        _limit_step(emus, screens, ram, rng)
        conn.send_bytes(b"K")


def lockstep_ceiling(game, batch, cores, seconds):
    """The ceiling of a lock-step process design, stori-jax's split: this process emulates its
    share of bare emulators (the per-step work of ``emulator_limit``) while the workers emulate
    theirs, one pipe byte each way per step, nothing else; agent steps per second."""
    from stori_jax.builder import default_split
    from stori_jax.games import get_game

    rom_id = get_game(game).rom_id
    workers, here = default_split(batch, cores)
    ctx = mp.get_context("spawn")
    conns, procs = [], []
    for n in (hi - lo for lo, hi in _split(batch - here, workers)):
        parent, child = ctx.Pipe()
        procs.append(ctx.Process(target=_lockstep_worker, args=(rom_id, n, child)))
        procs[-1].start()
        conns.append(parent)
    emus = _limit_emulators(rom_id, here)
    screens, ram = np.zeros((here, 2, 210, 160, 3), np.uint8), np.zeros((here, 128), np.uint8)
    rng = np.random.default_rng(0)
    for conn in conns:
        conn.recv_bytes()

    def step(_actions):
        for conn in conns:
            conn.send_bytes(b"S")
        _limit_step(emus, screens, ram, rng)
        for conn in conns:
            conn.recv_bytes()

    try:
        return _timed_loop(step, batch, 1, seconds)
    finally:
        for conn in conns:
            conn.send_bytes(b"C")
        for p in procs:
            p.join()


def _split(n, parts):
    bounds = np.linspace(0, n, parts + 1).round().astype(int)
    return list(zip(bounds[:-1], bounds[1:]))


# -- peers ------------------------------------------------------------------------------------

WARMUP = 20  # agent steps before timing


def warmup_steps(config, default: int = WARMUP) -> int:
    """Agent steps before timing: a 2.2 preset's T, so that the timed steps start in concept 2."""
    return config.drift.period if config.drift else default


def _timed_loop(step, num_envs, num_actions, seconds, warmup=WARMUP):
    rng = np.random.default_rng(0)
    actions = rng.integers(0, num_actions, (256, num_envs)).astype(np.int32)
    for t in range(warmup):
        step(actions[t % 256])
    rates, steps = [], 0
    for _ in range(WINDOWS):
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds / WINDOWS:
            step(actions[steps % 256])
            steps += 1
            n += 1
        rates.append(n * num_envs / (time.perf_counter() - t0))
    return float(np.median(rates))


# a peer's observation, as stori-jax's obs kind it stands beside: (height, width, gray, stack)
PEER_IMAGES = {"raw": (210, 160, False, 1), "atari84": (84, 84, True, 4)}


def envpool_peer(game, batch, workers, seconds, obs="raw"):
    import envpool

    from stori_jax.games import get_game

    spec = get_game(game)
    height, width, gray, stack = PEER_IMAGES[obs]
    task = "".join(p.capitalize() for p in spec.rom_id.split("_")) + "-v5"
    env = envpool.make(task, env_type="gymnasium", num_envs=batch, batch_size=batch,
                       num_threads=workers, img_height=height, img_width=width, gray_scale=gray,
                       stack_num=stack, frame_skip=FRAME_SKIP, noop_max=1, episodic_life=False,
                       reward_clip=False, repeat_action_probability=0.0)
    env.reset()
    rate = _timed_loop(lambda a: env.step(a), batch, spec.num_actions, seconds)
    env.close()
    return rate


def ale_vector(game, batch, workers, seconds, obs="raw"):
    from ale_py.vector_env import AtariVectorEnv

    from stori_jax.games import get_game

    spec = get_game(game)
    height, width, gray, stack = PEER_IMAGES[obs]
    env = AtariVectorEnv(spec.rom_id, batch, num_threads=workers, img_height=height,
                         img_width=width, grayscale=gray, stack_num=stack, frameskip=FRAME_SKIP,
                         maxpool=True, noop_max=0, reward_clipping=False, use_fire_reset=False)
    env.reset(seed=0)
    rate = _timed_loop(lambda a: env.step(a), batch, spec.num_actions, seconds)
    env.close()
    return rate


def naive(game, preset, batch, seconds):
    from naive_baseline import make_naive_vector_env

    import stori_jax

    config = stori_jax.preset(game, preset)
    env = make_naive_vector_env(game, config, batch, seed=0)
    env.reset(seed=0)
    rate = _timed_loop(lambda a: env.step(a), batch, stori_jax.get_game(game).num_actions,
                       seconds, warmup=warmup_steps(config, default=5))
    env.close()
    return rate


def stori(game, preset, batch, seconds, obs, backend):
    """stori-jax with its default worker split (one worker per core but one, plus the
    calling process)."""
    import stori_jax

    kwargs = {}
    if backend == "envpool":
        kwargs = dict(autoreset=False, granularity="step")
    env = stori_jax.make(game, preset, num_envs=batch, seed=0, obs=obs, backend=backend,
                         **kwargs)
    env.reset()
    concepts = []  # per step, (B,) on the device: read after timing, not during it

    def step(actions):
        concepts.append(env.step(actions)[-1]["concept"])

    warmup = warmup_steps(env.config)
    rate = _timed_loop(step, batch, env.num_actions, seconds, warmup=warmup)
    env.close()
    concept2 = float(np.mean(np.stack(concepts[warmup:]))) if env.config.drift else None
    return rate, concept2


def envpool_supports(game, preset):
    import stori_jax
    from stori_jax.backends.envpool import unsupported_reasons
    from stori_jax.plan import compile_plan

    cfg = stori_jax.preset(game, preset).replace(granularity="step")
    plan = compile_plan(cfg, stori_jax.get_game(game), num_envs=1, frame_skip=FRAME_SKIP,
                        obs="raw", noop_max=0, autoreset=False)
    return not unsupported_reasons(plan)


# -- the run ----------------------------------------------------------------------------------

PEER_KINDS = {"envpool": {"raw": "envpool raw", "atari84": "envpool 84x84 gray x4"},
              "ale-py": {"raw": "ale-py AtariVectorEnv", "atari84": "ale-py AtariVectorEnv 84x84 gray x4"}}
PEERS = {kind for by_obs in PEER_KINDS.values() for kind in by_obs.values()}


def games_of(args) -> list[str]:
    """The games the run measures: --games, else Breakout for --quick, else all four."""
    import stori_jax

    return args.games or (["Breakout"] if args.quick else list(stori_jax.STORI_GAMES))


def sweeps(args) -> bool:
    """Whether the run measures the Breakout 3.1 sweep over --sizes."""
    return "Breakout" in games_of(args) and (args.presets is None or "3.1" in args.presets)


def plan_measurements(args):
    import stori_jax

    games = games_of(args)
    presets = [(g, p) for g, p in stori_jax.list_presets()
               if g in games and (args.presets is None or p in args.presets)]
    w = args.workers
    jobs = []
    sweep = sweeps(args)
    for g in sorted({g for g, _ in presets}, key=games.index):  # the games measured here
        if sweep and g == "Breakout" and args.batch in args.sizes:
            continue  # measured in the sweep below
        jobs.append(dict(kind="emulator limit", game=g, preset="-", B=args.batch, backend="-",
                         obs="raw", fn=lambda g=g: emulator_limit(g, args.batch, w, args.seconds)))
        for obs in ("raw", "atari84"):  # native envpool beside this game's envpool-backend runs
            if any(gg == g and envpool_supports(gg, p) for gg, p in presets):
                jobs.append(dict(kind=PEER_KINDS["envpool"][obs], game=g, preset="-",
                                 B=args.batch, backend="envpool", obs=obs,
                                 fn=lambda g=g, obs=obs: envpool_peer(g, args.batch, w,
                                                                      args.seconds, obs)))
    for b in args.sizes if sweep else ():
        jobs.append(dict(kind="emulator limit", game="Breakout", preset="-", B=b, backend="-",
                         obs="raw", fn=lambda b=b: emulator_limit("Breakout", b, w, args.seconds)))
        jobs.append(dict(kind="lock-step ceiling", game="Breakout", preset="-", B=b,
                         backend="-", obs="raw",
                         fn=lambda b=b: lockstep_ceiling("Breakout", b, w, args.seconds)))
        for obs in ("raw", "atari84"):  # each peer with stori-jax's observation's twin
            jobs.append(dict(kind=PEER_KINDS["envpool"][obs], game="Breakout", preset="-",
                             B=b, backend="envpool", obs=obs,
                             fn=lambda b=b, obs=obs: envpool_peer("Breakout", b, w, args.seconds,
                                                                  obs)))
            jobs.append(dict(kind=PEER_KINDS["ale-py"][obs], game="Breakout", preset="-", B=b,
                             backend="ale-py", obs=obs,
                             fn=lambda b=b, obs=obs: ale_vector("Breakout", b, w, args.seconds,
                                                                obs)))
        for obs in ("raw", "atari84"):
            jobs.append(dict(kind="stori-jax", game="Breakout", preset="3.1", B=b,
                             backend="subproc", obs=obs,
                             fn=lambda b=b, obs=obs: stori("Breakout", "3.1", b, args.seconds, obs,
                                                           "subproc")))
    for g, p in presets:
        if not args.skip_naive:
            jobs.append(dict(kind="naive gymnasium", game=g, preset=p, B=args.batch,
                             backend="gymnasium-async", obs="raw",
                             fn=lambda g=g, p=p: naive(g, p, args.batch, args.seconds)))
        for obs in ("raw", "atari84"):
            for backend in ("subproc", "envpool"):
                if sweep and backend == "subproc" and p == "3.1" and g == "Breakout" \
                        and args.batch in args.sizes:
                    continue  # measured in the sweep
                if backend == "envpool" and not envpool_supports(g, p):
                    continue
                jobs.append(dict(kind="stori-jax", game=g, preset=p, B=args.batch,
                                 backend=backend, obs=obs,
                                 fn=lambda g=g, p=p, obs=obs, backend=backend: stori(
                                     g, p, args.batch, args.seconds, obs, backend)))
    return jobs


def needs_envpool(jobs) -> bool:
    return any(job["backend"] == "envpool" for job in jobs)


def run(args, jobs):
    from tqdm import tqdm

    results = []
    for job in tqdm(jobs, desc="throughput", unit="run"):
        fn = job.pop("fn")
        try:
            out = fn()
            if job["kind"] == "stori-jax":
                out, job["concept2_share"] = out
            job["steps_per_s"] = float(out)
        except Exception as e:  # noqa: BLE001 - record and go on: one failure must not lose the run
            job["steps_per_s"] = None
            job["error"] = f"{type(e).__name__}: {e}"
        job["W"] = args.workers
        results.append(job)
    return results


def add_ratios(results):
    limits = {(r["game"], r["B"]): r["steps_per_s"] for r in results
              if r["kind"] == "emulator limit"}
    ceilings = {(r["game"], r["B"]): r["steps_per_s"] for r in results
                if r["kind"] == "lock-step ceiling" and r["steps_per_s"]}
    own_31 = {(r["game"], r["B"], r["obs"], r["backend"]): r["steps_per_s"] for r in results
              if r["kind"] == "stori-jax" and r["preset"] == "3.1"}
    naive_rate = {(r["game"], r["preset"], r["B"]): r["steps_per_s"] for r in results
                  if r["kind"] == "naive gymnasium"}
    raw = {(r["game"], r["preset"], r["B"], r["backend"]): r["steps_per_s"] for r in results
           if r["kind"] == "stori-jax" and r["obs"] == "raw"}
    for r in results:
        rate = r["steps_per_s"]
        if rate is None:
            continue
        limit = limits.get((r["game"], r["B"]))
        r["vs_limit"] = rate / limit if limit else None
        if r["kind"] == "stori-jax":
            ceiling = ceilings.get((r["game"], r["B"]))
            if ceiling and r["backend"] == "subproc":
                r["vs_ceiling"] = rate / ceiling
            base = own_31.get((r["game"], r["B"], r["obs"], r["backend"]))
            r["vs_own_3.1"] = rate / base if base else None
            n = naive_rate.get((r["game"], r["preset"], r["B"]))
            r["vs_naive"] = rate / n if n else None
            if r["obs"] == "atari84":
                rr = raw.get((r["game"], r["preset"], r["B"], r["backend"]))
                r["atari84_vs_raw"] = rate / rr if rr else None
    return results


def add_best_peers(results):
    """A "best peer" row per (game, B, obs) the peers were measured at (the faster of envpool
    and ale-py's vector env), and each stori-jax run's ratio to it ("vs best peer") and, on the
    envpool backend, to native envpool with the same observation ("vs native envpool")."""
    best, native = {}, {}
    for r in results:
        if r["kind"] in PEERS and r["steps_per_s"] is not None:
            key = (r["game"], r["B"], r["obs"])
            if r["steps_per_s"] > best.get(key, (0, None))[0]:
                best[key] = (r["steps_per_s"], r["kind"])
            if r["backend"] == "envpool":
                native[key] = r["steps_per_s"]
    rows = []
    for (game, b, obs), (rate, kind) in sorted(best.items()):
        rows.append(dict(kind="best peer", game=game, preset="-", B=b, backend=kind, obs=obs,
                         steps_per_s=rate))
    for r in results:
        if r["kind"] == "stori-jax" and r["steps_per_s"] is not None:
            key = (r["game"], r["B"], r["obs"])
            if key in best:
                r["vs_best_peer"] = r["steps_per_s"] / best[key][0]
            if r["backend"] == "envpool" and key in native:
                r["vs_native_envpool"] = r["steps_per_s"] / native[key]
    return results + rows


def targets(results, batch: int) -> list[str]:
    """The issue's throughput targets, each with its measured figure(s) and met / missed."""
    def rows(**match):
        return [r for r in results if all(r.get(k) == v for k, v in match.items())
                and r.get("steps_per_s") is not None]

    def verdict(values, bound):
        return "met" if values and min(values) >= bound else "missed"

    lines = []
    for b in sorted({r["B"] for r in rows(kind="stori-jax", game="Breakout", preset="3.1",
                                         backend="subproc")}):
        peer = [r["vs_best_peer"] for r in rows(kind="stori-jax", game="Breakout", preset="3.1",
                                                backend="subproc", obs="atari84", B=b)
                if "vs_best_peer" in r]
        raw = [r["vs_limit"] for r in rows(kind="stori-jax", game="Breakout", preset="3.1",
                                           backend="subproc", obs="raw", B=b) if r.get("vs_limit")]
        for obs in ("raw", "atari84"):
            ceiling = [r["vs_ceiling"] for r in rows(kind="stori-jax", game="Breakout",
                                                     preset="3.1", backend="subproc", obs=obs,
                                                     B=b) if r.get("vs_ceiling")]
            if ceiling:
                lines.append(f"- B = {b}: Breakout 3.1 {obs} / the lock-step ceiling = "
                             f"{ceiling[0]:.2f} (target >= 0.95: {verdict(ceiling, 0.95)})")
        if peer:
            lines.append(f"- B = {b}: Breakout 3.1 atari84 / best peer (84x84 gray x4) = "
                         f"{peer[0]:.2f} (target >= 1.0: {verdict(peer, 1.0)})")
        if raw:
            lines.append(f"- B = {b}: Breakout 3.1 raw / emulator limit = {raw[0]:.2f} "
                         f"(target >= 0.85: {verdict(raw, 0.85)})")
    presets = rows(kind="stori-jax", backend="subproc", obs="atari84", B=batch)
    own = [r for r in presets if r.get("vs_own_3.1") is not None and r["preset"] != "3.1"]
    if own:
        from stori_jax import preset as config_of

        def renders(r):
            return any(name == "observation" and part.kind == "ram"
                       for name, part, _ in config_of(r["game"], r["preset"]).components())

        plain = [r["vs_own_3.1"] for r in own if not renders(r)]
        ram = [r["vs_own_3.1"] for r in own if renders(r)]
        worst = min(own, key=lambda r: r["vs_own_3.1"])
        lines.append(f"- B = {batch}: every preset's atari84 / its game's 3.1: min "
                     f"{min(plain):.2f} (target >= 0.9: {verdict(plain, 0.9)}), RAM-obs presets "
                     f"min {fmt(min(ram) if ram else None)} (target >= 0.7: "
                     f"{verdict(ram, 0.7) if ram else 'none measured'}); lowest: "
                     f"{worst['game']} {worst['preset']}")
    naive = [r for r in rows(kind="stori-jax", backend="subproc", obs="raw", B=batch)
             if r.get("vs_naive") is not None]
    if naive:
        worst = min(naive, key=lambda r: r["vs_naive"])
        lines.append(f"- B = {batch}: every preset's raw / the naive reference way on the same "
                     f"cores: min {worst['vs_naive']:.2f} ({worst['game']} {worst['preset']}; "
                     f"target >= 1.0: {verdict([r['vs_naive'] for r in naive], 1.0)})")
    envpool = [r for r in rows(kind="stori-jax", backend="envpool") if "vs_native_envpool" in r]
    if envpool:
        worst = min(envpool, key=lambda r: r["vs_native_envpool"])
        lines.append(f"- backend='envpool' / native envpool, same observation: min "
                     f"{worst['vs_native_envpool']:.2f} ({worst['game']} {worst['preset']} "
                     f"{worst['obs']}; target >= 0.9: "
                     f"{verdict([r['vs_native_envpool'] for r in envpool], 0.9)})")
    return lines


def fmt(x, spec=".2f"):
    return "-" if x is None else format(x, spec)


def markdown(results, meta) -> str:
    lines = [f"# Throughput, {meta['date']} on {meta['host']} ({meta['cores']} cores)", "",
             "Agent steps per second summed over the batch (frame skip 4), each the median of "
             f"{WINDOWS} windows. W = {meta['workers']} worker processes for the emulator limit, "
             "W threads for raw envpool and ale-py; stori-jax uses its default worker split and "
             "envpool its own thread count. \"vs limit\" is to the emulator limit of the same "
             "game and B, \"vs naive\" to the naive baseline of the same preset and B, both "
             "measured in this run; \"vs ceiling\" to the lock-step ceiling (bare emulators in "
             "stori-jax's split, one pipe byte each way a step). envpool rows run "
             "granularity='step'. \"concept 2\": the share of a 2.2 preset's timed steps spent "
             "in concept 2.", "",
             "| kind | game | preset | backend | obs | B | steps/s | vs limit | vs ceiling | "
             "vs own 3.1 | vs naive | atari84/raw | concept 2 | vs best peer | "
             "vs native envpool |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    failed = []
    for r in results:
        run = f"{r['kind']} | {r['game']} | {r['preset']} | {r['backend']} | {r['obs']} | {r['B']}"
        if "error" in r:  # below the table: a cell past the last column is not shown
            failed.append(f"- {run.replace(' | ', ' ')}: {r['error']}")
        lines.append(
            f"| {run} | {'failed' if 'error' in r else fmt(r['steps_per_s'], '.0f')} | "
            f"{fmt(r.get('vs_limit'))} | {fmt(r.get('vs_ceiling'))} | "
            f"{fmt(r.get('vs_own_3.1'))} | {fmt(r.get('vs_naive'))} | "
            f"{fmt(r.get('atari84_vs_raw'))} | {fmt(r.get('concept2_share'))} | "
            f"{fmt(r.get('vs_best_peer'))} | {fmt(r.get('vs_native_envpool'))} |")
    if failed:
        lines += ["", "Failed runs:", *failed]
    goals = targets(results, meta["batch"])
    if goals:
        lines += ["", "Targets (ratios measured in this run):", *goals]
    return "\n".join(lines) + "\n"


def plots(results, stem: Path, batch: int) -> list[Path]:
    """The PNGs the results allow (a sweep over B, the per-preset runs); returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    series = {}
    for r in results:
        if r["game"] != "Breakout" or r["preset"] not in ("-", "3.1") or r["steps_per_s"] is None:
            continue
        if r["kind"] == "naive gymnasium":
            continue
        label = r["kind"] + ("" if r["kind"] != "stori-jax" else f" {r['backend']} {r['obs']}")
        series.setdefault(label, []).append((r["B"], r["steps_per_s"]))
    series = {label: sorted(set(points)) for label, points in series.items()
              if len({b for b, _ in points}) > 1}
    written = [_plot_vs_batch(plt, series, stem)] if series else []  # a sweep over B was run
    presets = _plot_presets(plt, results, stem, batch)
    return written + ([presets] if presets is not None else [])


def _plot_vs_batch(plt, series, stem: Path):
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for label, points in sorted(series.items()):
        ax.plot(*zip(*points), marker="o", label=label)
    ax.set_xscale("log", base=2)
    ax.set_xlabel("batch size B")
    ax.set_ylabel("agent steps / s")
    ax.set_title("Breakout 3.1: throughput vs batch size")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path = stem.with_name(stem.name + "-vs-batch.png")
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _plot_presets(plt, results, stem: Path, batch: int):
    rows = [r for r in results if r["kind"] in ("stori-jax", "naive gymnasium")
            and r["B"] == batch and r.get("vs_limit") is not None]  # the per-preset runs
    if not rows:
        return None
    labels = sorted({f"{r['game']} {r['preset']}" for r in rows},
                    key=lambda s: (s.split()[0], s.split()[1]))
    kinds = sorted({(r["kind"], r["backend"], r["obs"]) for r in rows})
    fig, ax = plt.subplots(figsize=(max(8, len(labels) * 0.6), 5))
    width = 0.8 / max(1, len(kinds))
    for k, kind in enumerate(kinds):
        values = []
        for label in labels:
            match = [r["vs_limit"] for r in rows if f"{r['game']} {r['preset']}" == label
                     and (r["kind"], r["backend"], r["obs"]) == kind]
            values.append(match[0] if match else 0)
        ax.bar(np.arange(len(labels)) + k * width, values, width, label=" ".join(kind))
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xticks(np.arange(len(labels)) + 0.4 - width / 2, labels, rotation=60, ha="right",
                  fontsize=8)
    ax.set_ylabel("fraction of the emulator limit")
    ax.set_title("Per preset, as a fraction of the emulator limit")
    ax.legend(fontsize=7)
    fig.tight_layout()
    path = stem.with_name(stem.name + "-presets.png")
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _check_arguments(parser, args):
    from stori_jax.cli import selected_presets
    from stori_jax.presets import spelt_as_the_paper

    if not (math.isfinite(args.seconds) and args.seconds > 0):
        parser.error(f"--seconds must be a finite number > 0, got {args.seconds}")
    require_at_least_one(parser, batch=args.batch, workers=args.workers, sizes=args.sizes)
    fits_in_memory(parser, "--batch", [args.batch])
    if args.sizes is not None:
        fits_in_memory(parser, "--sizes", args.sizes)
    if args.games is not None:  # each game once
        args.games = list(dict.fromkeys(stori_games(parser, "--games", args.games)))
    try:  # the suite's check: every preset named must belong to one of the games
        selected_presets(args.games or (["Breakout"] if args.quick else None), args.presets)
    except ValueError as error:
        parser.error(str(error))
    if args.presets is not None:
        args.presets = list(dict.fromkeys(spelt_as_the_paper(p) for p in args.presets))
    if args.sizes is not None and not sweeps(args):
        parser.error("--sizes sets the B of the Breakout 3.1 sweep, which this run does not "
                     "measure (it needs Breakout among --games and 3.1 among --presets)")
    output_directory(parser, args.out)


SWEEP_SIZES = {False: [8, 32, 64], True: [8, 32]}  # B of the 3.1 sweep, by --quick


def _shown(sizes) -> str:
    return " ".join(map(str, sizes))


def name_suffix(parser, args) -> str:
    """What sets this run apart from a default full run, for its file names (a run with other
    options never overwrites a full run of the same day, nor one with other options): --quick,
    the games and presets named, and every other option that differs from its default."""
    parts = ["quick"] if args.quick else []
    parts += ["-".join(names) for names in (args.games, args.presets) if names]
    if args.sizes != SWEEP_SIZES[args.quick]:
        parts.append("B" + "-".join(map(str, args.sizes)))
    return "".join(f"-{part}" for part in parts) + options_in_name(
        parser, args, {"batch": "batch", "workers": "workers", "seconds": "seconds"}) + (
        "-no-naive" if args.skip_naive else "")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help=f"Breakout only, B in {_shown(SWEEP_SIZES[True])} (unless --games / "
                        "--sizes say otherwise)")
    parser.add_argument("--seconds", type=float, default=3.0,
                        help="measuring time per run (default 3.0)")
    parser.add_argument("--batch", type=int, default=32,
                        help="B for the per-preset runs (default 32)")
    parser.add_argument("--sizes", type=int, nargs="+", default=None,
                        help=f"B of the Breakout 3.1 sweep (default {_shown(SWEEP_SIZES[False])})")
    parser.add_argument("--games", nargs="+", default=None, help="default: the four STORI games")
    parser.add_argument("--presets", nargs="+", default=None,
                        help="only these presets (e.g. 3.1 2.2); default: all")
    parser.add_argument("--workers", type=int, default=cores(),
                        help="processes of the emulator limit, threads of envpool and ale-py "
                             f"(default {cores()}: the cores)")
    parser.add_argument("--skip-naive", action="store_true",
                        help="leave out the naive gymnasium baseline")
    parser.add_argument("--out", type=Path, default=HERE / "results",
                        help="directory for the results (default benchmarks/results)")
    args = parser.parse_args(argv)
    _check_arguments(parser, args)
    if args.sizes is None:
        args.sizes = SWEEP_SIZES[args.quick]
    jobs = plan_measurements(args)
    if importlib.util.find_spec("matplotlib") is None:
        parser.error("matplotlib is not installed, and this run draws its plots with it: "
                     "pip install -e '.[agents]' (the test set-up's install has it)")
    if needs_envpool(jobs) and importlib.util.find_spec("envpool") is None:
        parser.error("envpool is not installed, and this run compares against it (raw envpool "
                     "and stori-jax's envpool backend): pip install -e '.[envpool]'")
    from stori_jax.provenance import software

    meta = dict(date=datetime.date.today().isoformat(), host=socket.gethostname(),
                cores=cores(), workers=args.workers, batch=args.batch,
                seconds=args.seconds, argv=sys.argv[1:] if argv is None else list(argv),
                software=software())
    results = add_best_peers(add_ratios(run(args, jobs)))
    args.out.mkdir(parents=True, exist_ok=True)
    stem = args.out / f"{meta['date']}-{meta['host']}{name_suffix(parser, args)}"
    Path(f"{stem}.json").write_text(json.dumps(dict(meta=meta, results=results), indent=1))
    table = markdown(results, meta)
    Path(f"{stem}.md").write_text(table)
    pictures = plots(results, stem, args.batch)
    print(table)
    print("wrote " + ", ".join(str(p) for p in [f"{stem}.json", f"{stem}.md", *pictures]))


if __name__ == "__main__":
    main()
