"""The benchmark scripts compute what they claim: which runs a plan measures, the steps/s and
ms formulas (on a fake clock: nothing here is timed), the ratios, and what a run writes (JSON,
a markdown table whose columns say what they hold, PNG plots).  The naive baseline follows
stori-jax's concept-drift schedule and masks."""

import argparse
import datetime
import importlib
import json
from collections import Counter
from pathlib import Path
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest

import stori_jax

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def script(monkeypatch, name: str):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    return importlib.import_module(name)


class FakeClock:
    """perf_counter() that only moves when told to (each fake env step advances it)."""

    def __init__(self):
        self.now = 100.0

    def perf_counter(self):
        return self.now

    def sleep(self, seconds):
        pass


def throughput_args(**overrides):
    args = dict(quick=False, seconds=3.0, batch=32, sizes=[8, 32, 64], games=None,
                presets=None, workers=2, skip_naive=False)
    return argparse.Namespace(**{**args, **overrides})


def table(text: str) -> list[dict]:
    """The rows of the first markdown table in ``text``, as dicts keyed by the header."""
    lines = [line for line in text.splitlines() if line.startswith("|")]
    header = [cell.strip() for cell in lines[0].strip("|").split("|")]
    return [dict(zip(header, (cell.strip() for cell in line.strip("|").split("|"))))
            for line in lines[2:]]


def assert_made_with_this_software(recorded):
    """A result file's ``software`` is provenance.software()'s: this Python, machine, code
    commit (dirty or not: another process may be editing the checkout) and package versions."""
    from stori_jax import provenance

    now = provenance.software()
    assert set(recorded) == {"python", "machine", "commit", "packages"}
    assert {k: recorded[k] for k in ("python", "machine", "packages")} == {
        k: now[k] for k in ("python", "machine", "packages")}
    assert (recorded["commit"] or "").removesuffix("+dirty") == \
        (now["commit"] or "").removesuffix("+dirty")


# -- throughput.py: the formulas ----------------------------------------------------------------

def test_a_timed_rate_counts_agent_steps_of_the_whole_batch_after_the_warm_up(monkeypatch):
    """Warm-up steps (here 1 s each, as a compile would be) are neither timed nor counted; the
    rate is agent steps summed over the batch per second, the median of the windows."""
    throughput = script(monkeypatch, "throughput")
    clock = FakeClock()
    monkeypatch.setattr(throughput, "time", clock)
    calls, durations = [], iter([1.0] * 7 + [0.011] * 10 + [0.021] * 5 + [0.041] * 3)

    def step(actions):
        calls.append(actions.copy())
        clock.now += next(durations)

    rate = throughput._timed_loop(step, num_envs=5, num_actions=4, seconds=0.3, warmup=7)
    # three 0.1 s windows, of 10, 5 and 3 steps taking 0.11, 0.105 and 0.123 s: the median
    # window's steps per second, times the 5 envs
    assert rate == pytest.approx(5 * 5 / 0.105, rel=1e-6)
    assert len(calls) == 7 + 10 + 5 + 3
    assert all(a.shape == (5,) and a.dtype == np.int32 and 0 <= a.min() and a.max() < 4
               for a in calls)


def test_the_emulator_limit_splits_the_batch_over_the_workers_and_sums_each_window(monkeypatch):
    import queue
    import threading

    throughput = script(monkeypatch, "throughput")
    monkeypatch.setattr(throughput, "time", FakeClock())
    fake_context = SimpleNamespace(Event=threading.Event, Queue=queue.Queue,
                                   Process=threading.Thread)
    monkeypatch.setattr(throughput.mp, "get_context", lambda method: fake_context)
    sizes = []

    def worker(rom_id, n, seconds, start, out):
        assert start.wait(5) and seconds == 6.0
        sizes.append(n)
        out.put([10 * n, 60 * n, 20 * n])  # agent steps per window

    monkeypatch.setattr(throughput, "_limit_worker", worker)
    rate = throughput.emulator_limit("Breakout", batch=7, workers=3, seconds=6.0)
    assert sorted(sizes) == [2, 2, 3]
    # windows of 2 s: 70, 420 and 140 steps summed over the workers; the median is 140 (the
    # slow first window and the fast second do not pull it, as they would a mean of 210)
    assert rate == pytest.approx(140 / 2.0)


def test_the_emulator_limit_step_does_a_workers_work_per_agent_step(monkeypatch):
    """4 frames of one action, the last two screens, one RAM read, a reset at game over."""
    throughput = script(monkeypatch, "throughput")

    class FakeALE:
        def __init__(self, over):
            self.log, self.over = [], over

        def act(self, a):
            self.log.append(("act", a))

        def getScreenRGB(self, out):
            self.log.append(("screen", len(self.log)))
            out[...] = len(self.log)

        def getRAM(self, out):
            self.log.append(("ram",))

        def game_over(self):
            return self.over

        def reset_game(self):
            self.log.append(("reset",))

    emus = [(FakeALE(False), [3]), (FakeALE(True), [5])]
    screens = np.zeros((2, 2, 210, 160, 3), np.uint8)
    throughput._limit_step(emus, screens, np.zeros((2, 128), np.uint8),
                           np.random.default_rng(0))
    assert emus[0][0].log == [("act", 3), ("act", 3), ("act", 3), ("screen", 3), ("act", 3),
                              ("screen", 5), ("ram",)]
    assert emus[1][0].log[-1] == ("reset",) and emus[1][0].log.count(("act", 5)) == 4
    assert screens[0, 0].max() == 4 and screens[0, 1].max() == 6  # frames 3 and 4, in order


def test_a_2_2_run_warms_up_until_its_concept_switch(monkeypatch):
    throughput = script(monkeypatch, "throughput")
    assert throughput.warmup_steps(stori_jax.preset("Breakout", "2.2")) == 300
    assert throughput.warmup_steps(stori_jax.preset("Gopher", "2.2")) == 600
    assert throughput.warmup_steps(stori_jax.preset("Breakout", "3.1")) == throughput.WARMUP
    assert throughput.warmup_steps(stori_jax.preset("Boxing", "1"), default=5) == 5


def test_the_concept_2_share_covers_the_timed_steps_only(monkeypatch):
    """A 2.2 run times from agent step T on: with every env switching at T, the share is 1."""
    throughput = script(monkeypatch, "throughput")
    clock = FakeClock()
    monkeypatch.setattr(throughput, "time", clock)
    made = {}

    class FakeEnv:
        num_actions = 4

        def __init__(self, game, preset, **kwargs):
            made.update(kwargs, game=game, preset=preset)
            self.config, self.t = stori_jax.preset(game, preset), 0

        def reset(self):
            self.t = 0

        def step(self, actions):
            clock.now += 0.01
            concept = np.full(len(actions), int(self.t >= self.config.drift.period), np.int32)
            self.t += 1
            return None, None, None, None, {"concept": concept}

        def close(self):
            pass

    monkeypatch.setattr(stori_jax, "make", FakeEnv)
    rate, share = throughput.stori("Breakout", "2.2", 3, 0.3, "atari84", "envpool")
    assert share == 1.0 and rate == pytest.approx(3 / 0.01, rel=0.05)
    assert made["num_envs"] == 3 and made["obs"] == "atari84" and made["backend"] == "envpool"
    assert made["granularity"] == "step" and made["autoreset"] is False


@pytest.mark.parametrize("game, preset, warmup", [("Gopher", "2.2", 600), ("Gopher", "3.2", 5)])
def test_the_naive_baseline_warms_up_on_the_same_schedule(monkeypatch, game, preset, warmup):
    """Its 2.2 runs are timed from agent step T on too, in the same concept as stori-jax's."""
    throughput = script(monkeypatch, "throughput")
    naive = script(monkeypatch, "naive_baseline")
    clock = FakeClock()
    monkeypatch.setattr(throughput, "time", clock)
    made, steps = {}, []

    class FakeVectorEnv:
        def reset(self, seed):
            made["reset_seed"] = seed

        def step(self, actions):
            steps.append(actions)
            clock.now += 0.01

        def close(self):
            pass

    def make(game_name, config, num_envs, seed):
        made.update(game=game_name, config=config, num_envs=num_envs)
        return FakeVectorEnv()

    monkeypatch.setattr(naive, "make_naive_vector_env", make)
    rate = throughput.naive(game, preset, 4, 0.3)
    assert made["config"] == stori_jax.preset(game, preset) and made["num_envs"] == 4
    assert rate == pytest.approx(4 / 0.01, rel=0.05)
    assert 27 <= len(steps) - warmup <= 33  # three timed windows of 0.1 s after the warm-up


def test_ratios_compare_like_with_like(monkeypatch):
    throughput = script(monkeypatch, "throughput")

    def row(kind, preset, rate, backend="subproc", obs="raw", B=32, game="Boxing"):
        return dict(kind=kind, game=game, preset=preset, B=B, backend=backend, obs=obs,
                    steps_per_s=rate)

    results = throughput.add_ratios([
        row("emulator limit", "-", 1000.0, backend="-"),
        row("emulator limit", "-", 5000.0, backend="-", B=8),
        row("emulator limit", "-", 7000.0, backend="-", game="Gopher"),
        row("naive gymnasium", "3.2A", 200.0, backend="gymnasium-async"),
        row("naive gymnasium", "3.1", 300.0, backend="gymnasium-async"),
        row("stori-jax", "3.1", 800.0),
        row("stori-jax", "3.1", 400.0, obs="atari84"),
        row("stori-jax", "3.1", 900.0, backend="envpool"),
        row("stori-jax", "3.2A", 600.0),
        row("stori-jax", "3.2A", 300.0, obs="atari84"),
        row("stori-jax", "3.2A", 450.0, backend="envpool"),
        row("stori-jax", "3.2A", None, backend="envpool", obs="atari84"),
    ])
    by = {(r["preset"], r["backend"], r["obs"], r["B"], r["game"]): r for r in results}
    limit = by["-", "-", "raw", 32, "Boxing"]
    assert limit["vs_limit"] == 1.0 and "vs_naive" not in limit
    assert by["3.2A", "gymnasium-async", "raw", 32, "Boxing"]["vs_limit"] == pytest.approx(0.2)
    raw = by["3.2A", "subproc", "raw", 32, "Boxing"]
    assert raw["vs_limit"] == pytest.approx(0.6)  # of the limit of its own game and B
    assert raw["vs_own_3.1"] == pytest.approx(600 / 800)  # same backend and obs
    assert raw["vs_naive"] == pytest.approx(600 / 200)  # same preset
    assert "atari84_vs_raw" not in raw
    small = by["3.2A", "subproc", "atari84", 32, "Boxing"]
    assert small["vs_own_3.1"] == pytest.approx(300 / 400)
    assert small["atari84_vs_raw"] == pytest.approx(300 / 600)  # same backend
    assert small["vs_naive"] == pytest.approx(300 / 200)  # the baseline's obs are raw
    pool = by["3.2A", "envpool", "raw", 32, "Boxing"]
    assert pool["vs_own_3.1"] == pytest.approx(450 / 900)
    assert by["3.1", "envpool", "raw", 32, "Boxing"]["vs_naive"] == pytest.approx(3.0)
    assert "vs_limit" not in by["3.2A", "envpool", "atari84", 32, "Boxing"]  # failed run
    assert by["-", "-", "raw", 8, "Boxing"]["vs_limit"] == 1.0


def test_the_best_peer_is_the_faster_peer_at_each_b_and_observation(monkeypatch):
    throughput = script(monkeypatch, "throughput")

    def row(kind, rate, obs="atari84", backend="subproc", B=32, preset="-"):
        return dict(kind=kind, game="Breakout", preset=preset, B=B, backend=backend, obs=obs,
                    steps_per_s=rate)

    results = throughput.add_best_peers([
        row("envpool 84x84 gray x4", 4000.0, backend="envpool"),
        row("ale-py AtariVectorEnv 84x84 gray x4", 5000.0, backend="ale-py"),
        row("envpool raw", 3000.0, obs="raw", backend="envpool"),
        row("stori-jax", 2500.0, preset="3.1"),
        row("stori-jax", 2000.0, backend="envpool", preset="3.1"),
        row("stori-jax", 1500.0, obs="raw", preset="3.1", B=64),  # no peer at B = 64
    ])
    best = {(r["obs"], r["B"]): r for r in results if r["kind"] == "best peer"}
    assert set(best) == {("atari84", 32), ("raw", 32)}
    assert (best["atari84", 32]["steps_per_s"], best["atari84", 32]["backend"]) == (
        5000.0, "ale-py AtariVectorEnv 84x84 gray x4")
    subproc, pool, lone = [r for r in results if r["kind"] == "stori-jax"]
    assert subproc["vs_best_peer"] == pytest.approx(0.5) and "vs_native_envpool" not in subproc
    assert pool["vs_native_envpool"] == pytest.approx(0.5)  # envpool's own, not the best peer
    assert "vs_best_peer" not in lone
    lines = throughput.targets(results, batch=32)
    assert "- B = 32: Breakout 3.1 atari84 / best peer (84x84 gray x4) = 0.50 (target >= 1.0: " \
           "missed)" in lines


# -- throughput.py: what a run measures ---------------------------------------------------------

def planned(throughput, **overrides):
    jobs = throughput.plan_measurements(throughput_args(**overrides))
    keys = [(j["kind"], j["game"], j["preset"], j["B"], j["backend"], j["obs"]) for j in jobs]
    assert all(n == 1 for n in Counter(keys).values()), "a run measured twice"
    return set(keys)


def test_a_full_run_measures_every_preset_and_the_breakout_sweep(monkeypatch):
    throughput = script(monkeypatch, "throughput")
    keys = planned(throughput)
    from stori_jax.backends.envpool import unsupported_reasons  # noqa: F401 - envpool_supports uses it

    for b in (8, 32, 64):
        assert ("emulator limit", "Breakout", "-", b, "-", "raw") in keys
        assert ("lock-step ceiling", "Breakout", "-", b, "-", "raw") in keys
        for obs in ("raw", "atari84"):  # each peer beside each of stori-jax's observations
            for peer, backend in (("envpool", "envpool"), ("ale-py", "ale-py")):
                assert (throughput.PEER_KINDS[peer][obs], "Breakout", "-", b, backend,
                        obs) in keys
            assert ("stori-jax", "Breakout", "3.1", b, "subproc", obs) in keys
    for game in ("Boxing", "Gopher", "BankHeist"):
        assert ("emulator limit", game, "-", 32, "-", "raw") in keys
        # native envpool beside the game's envpool-backend runs, at the presets' B
        assert {k[0] for k in keys if k[0] != "emulator limit" and k[2] == "-" and
                k[1] == game} == set(throughput.PEER_KINDS["envpool"].values())
    for game, preset in stori_jax.list_presets():
        assert ("naive gymnasium", game, preset, 32, "gymnasium-async", "raw") in keys
        for obs in ("raw", "atari84"):
            assert ("stori-jax", game, preset, 32, "subproc", obs) in keys
            assert (("stori-jax", game, preset, 32, "envpool", obs) in keys) == \
                throughput.envpool_supports(game, preset)
    assert throughput.envpool_supports("Gopher", "2.2")
    assert not throughput.envpool_supports("Boxing", "2.2")  # RAM-obs
    assert not throughput.envpool_supports("Breakout", "2.1")  # events write the RAM
    assert len(keys) == 3 * 8 + 3 * 3 + 24 * 3 - 2 + sum(
        2 * throughput.envpool_supports(g, p) for g, p in stori_jax.list_presets())


def test_a_subset_measures_only_what_it_names(monkeypatch):
    throughput = script(monkeypatch, "throughput")
    keys = planned(throughput, games=["Boxing"], presets=["3.1", "2.2"], sizes=[8],
                   skip_naive=True)
    assert {k[:3] for k in keys} == {("emulator limit", "Boxing", "-"),
                                     ("envpool raw", "Boxing", "-"),
                                     ("envpool 84x84 gray x4", "Boxing", "-"),
                                     ("stori-jax", "Boxing", "3.1"), ("stori-jax", "Boxing", "2.2")}
    assert {k[3] for k in keys} == {32}  # --sizes is Breakout 3.1's sweep only
    quick = planned(throughput, quick=True, sizes=[8, 32], presets=["2.2"])
    assert {k[1] for k in quick} == {"Breakout"}
    assert ("emulator limit", "Breakout", "-", 32, "-", "raw") in quick  # no sweep without 3.1
    assert not any(k[0] in throughput.PEERS for k in quick if k[2] == "-" and k[1] != "Breakout")
    sweep = planned(throughput, quick=True, sizes=[8, 16], presets=["3.1"])
    assert {k[3] for k in sweep if k[0] == "emulator limit"} == {8, 16, 32}
    assert ("stori-jax", "Breakout", "3.1", 32, "subproc", "raw") in sweep  # B not in the sweep
    # a game with none of the presets named has no row to compare with its emulator limit
    only_32 = planned(throughput, presets=["3.2"], sizes=[8], skip_naive=True)
    assert {k[1] for k in only_32 if k[0] == "emulator limit"} == {"Gopher", "BankHeist"}


def test_a_game_or_preset_named_twice_is_measured_once(monkeypatch, tmp_path):
    throughput = script(monkeypatch, "throughput")
    args = throughput_args(games=["Gopher", "gopher"], presets=["2.1", "2.1"], sizes=None,
                           out=tmp_path)
    throughput._check_arguments(argparse.ArgumentParser(), args)
    assert (args.games, args.presets) == (["Gopher"], ["2.1"])


# -- throughput.py: what a run writes -----------------------------------------------------------

def fake_results():
    rows = []
    for b, limit in ((8, 4000.0), (32, 5000.0)):
        rows.append(dict(kind="emulator limit", game="Breakout", preset="-", B=b, backend="-",
                         obs="raw", steps_per_s=limit))
        rows.append(dict(kind="stori-jax", game="Breakout", preset="3.1", B=b,
                         backend="subproc", obs="raw", steps_per_s=limit / 2,
                         concept2_share=None))
    rows.append(dict(kind="naive gymnasium", game="Breakout", preset="2.2", B=32,
                     backend="gymnasium-async", obs="raw", steps_per_s=1000.0))
    rows.append(dict(kind="stori-jax", game="Breakout", preset="2.2", B=32, backend="subproc",
                     obs="raw", steps_per_s=2000.0, concept2_share=0.25))
    rows.append(dict(kind="stori-jax", game="Breakout", preset="2.2", B=32, backend="subproc",
                     obs="atari84", steps_per_s=1500.0, concept2_share=0.75))
    return [dict(r, W=2) for r in rows]


def test_a_failed_run_shows_as_failed_and_its_error_below_the_table(monkeypatch):
    """The error was a cell past the table's last column, which markdown does not show: the
    failed run read as a row of '-'."""
    throughput = script(monkeypatch, "throughput")
    rows = fake_results()
    rows[-1] = dict(rows[-1], steps_per_s=None, error="ValueError: no emulator")
    text = throughput.markdown(throughput.add_ratios(rows), dict(date="d", host="h", cores=2,
                                                                 workers=2, batch=32))
    assert table(text)[-1]["steps/s"] == "failed"
    assert "\n\nFailed runs:\n- stori-jax Breakout 2.2 subproc atari84 32: ValueError: no " \
           "emulator\n\n" in text


def test_the_table_columns_hold_what_their_headers_say(monkeypatch):
    throughput = script(monkeypatch, "throughput")
    results = throughput.add_ratios(fake_results())
    meta = dict(date="2026-11-24", host="h", cores=2, workers=2, batch=32)
    rows = table(throughput.markdown(results, meta))
    assert len(rows) == len(results)
    row = rows[-1]
    assert row == {"kind": "stori-jax", "game": "Breakout", "preset": "2.2",
                   "backend": "subproc", "obs": "atari84", "B": "32", "steps/s": "1500",
                   "vs limit": "0.30", "vs ceiling": "-", "vs own 3.1": "-", "vs naive": "1.50",
                   "atari84/raw": "0.75", "concept 2": "0.75", "vs best peer": "-",
                   "vs native envpool": "-"}
    assert rows[-2]["vs own 3.1"] == "0.80" and rows[-2]["concept 2"] == "0.25"


def test_a_run_writes_json_a_table_and_the_plots_it_names(monkeypatch, tmp_path, capsys):
    throughput = script(monkeypatch, "throughput")
    monkeypatch.setattr(throughput, "run", lambda args, jobs: fake_results())
    throughput.main(["--games", "breakout", "--presets", "3.1", "2.2", "--sizes", "8", "32",
                     "--out", str(tmp_path)])
    written = sorted(p.name for p in tmp_path.iterdir())
    stems = {name.split("-Breakout-3.1-2.2-B8-32")[0] for name in written}
    assert len(stems) == 1 and all("-Breakout-3.1-2.2-B8-32" in name for name in written)
    stem = tmp_path / (stems.pop() + "-Breakout-3.1-2.2-B8-32")
    assert written == sorted(f"{stem.name}{end}" for end in (
        ".json", ".md", "-vs-batch.png", "-presets.png"))
    for end in ("-vs-batch.png", "-presets.png"):
        assert Path(f"{stem}{end}").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    data = json.loads(Path(f"{stem}.json").read_text())
    assert data["meta"]["seconds"] == 3.0 and data["meta"]["workers"] >= 1
    assert_made_with_this_software(data["meta"]["software"])
    assert data["results"] == throughput.add_ratios(fake_results())
    text = Path(f"{stem}.md").read_text()
    assert text in capsys.readouterr().out
    assert table(text)[-1]["vs naive"] == "1.50"


@pytest.mark.parametrize("argv, suffix", [
    ([], ""),
    (["--sizes", "8", "32", "64"], ""),  # the defaults, spelt out
    (["--quick"], "-quick"),
    (["--quick", "--sizes", "8", "32"], "-quick"),
    (["--games", "boxing", "--presets", "3.1", "2.2"], "-Boxing-3.1-2.2"),
    (["--batch", "64", "--sizes", "64"], "-B64-batch64"),
    (["--skip-naive"], "-no-naive"),
    (["--seconds", "0.5", "--workers", "7"], "-workers7-seconds0.5"),
])
def test_a_run_with_other_options_is_named_apart_from_a_full_run(monkeypatch, tmp_path, argv,
                                                                  suffix):
    """Only a run with the default options writes <date>-<host>.*: a quick run, a subset or
    other settings never overwrite it (nor each other), and the JSON records the argv given."""
    throughput = script(monkeypatch, "throughput")
    monkeypatch.setattr(throughput, "run", lambda args, jobs: fake_results())
    monkeypatch.setattr(throughput, "plots", lambda results, stem, batch: [])
    monkeypatch.setattr(throughput, "cores", lambda: 2)  # the --workers default
    throughput.main(argv + ["--out", str(tmp_path)])
    (json_file,) = tmp_path.glob("*.json")
    meta = json.loads(json_file.read_text())["meta"]
    assert json_file.name == f"{meta['date']}-{meta['host']}{suffix}.json"
    assert meta["argv"] == argv + ["--out", str(tmp_path)]


def test_the_batch_plot_is_drawn_only_for_a_sweep(monkeypatch, tmp_path):
    throughput = script(monkeypatch, "throughput")
    one_b = [r for r in throughput.add_ratios(fake_results()) if r["B"] == 32]
    paths = throughput.plots(one_b, tmp_path / "run", batch=32)
    assert [p.name for p in paths] == ["run-presets.png"]


def test_a_run_measures_and_records_with_the_workers_and_seconds_asked(monkeypatch, tmp_path):
    """--workers 7 --seconds 0.5 on a 2-core machine: every measurement gets them, and the
    JSON's meta, each row's W and the table's header say so (not the cores, not 3 s)."""
    throughput = script(monkeypatch, "throughput")
    monkeypatch.setattr(throughput, "cores", lambda: 2)
    monkeypatch.setattr(throughput, "plots", lambda results, stem, batch: [])
    asked = []

    def peer(rate):
        return lambda game, batch, workers, seconds, obs="raw": (
            asked.append((workers, seconds)) or rate)

    monkeypatch.setattr(throughput, "emulator_limit", peer(1000.0))
    monkeypatch.setattr(throughput, "lockstep_ceiling", peer(600.0))
    monkeypatch.setattr(throughput, "envpool_peer", peer(900.0))
    monkeypatch.setattr(throughput, "ale_vector", peer(800.0))
    monkeypatch.setattr(throughput, "stori", lambda game, preset, batch, seconds, obs, backend: (
        asked.append((7, seconds)), (500.0, None))[1])
    throughput.main(["--games", "Breakout", "--presets", "3.1", "--sizes", "8", "--skip-naive",
                     "--workers", "7", "--seconds", "0.5", "--out", str(tmp_path)])
    assert len(asked) >= 6 and set(asked) == {(7, 0.5)}
    (json_file,) = tmp_path.glob("*.json")
    data = json.loads(json_file.read_text())
    assert data["meta"]["workers"] == 7 and data["meta"]["seconds"] == 0.5
    assert data["meta"]["cores"] == 2
    measured = [r for r in data["results"] if r["kind"] != "best peer"]
    assert len(measured) == len(asked) and all(r["W"] == 7 for r in measured)
    assert all(r["steps_per_s"] is not None for r in data["results"])
    (md,) = tmp_path.glob("*.md")
    assert "W = 7 worker processes" in md.read_text()


def test_a_run_records_each_measurement_and_goes_on_past_a_failed_one(monkeypatch):
    throughput = script(monkeypatch, "throughput")

    def broken():
        raise RuntimeError("the emulator died")

    def job(kind, fn, preset="2.2"):
        return dict(kind=kind, game="Breakout", preset=preset, B=8, backend="subproc",
                    obs="raw", fn=fn)

    rows = throughput.run(throughput_args(workers=3), [
        job("stori-jax", lambda: (500.0, 0.25)),
        job("emulator limit", lambda: 1000.0, preset="-"),
        job("stori-jax", broken),
        job("stori-jax", lambda: (250.0, None), preset="3.1"),  # runs after the failure
    ])
    assert [r["steps_per_s"] for r in rows] == [500.0, 1000.0, None, 250.0]
    assert rows[0]["concept2_share"] == 0.25 and rows[3]["concept2_share"] is None
    assert "concept2_share" not in rows[1]
    assert rows[2]["error"] == "RuntimeError: the emulator died"
    assert not any("error" in r for r in rows[:2] + rows[3:])
    assert all(r["W"] == 3 and "fn" not in r for r in rows)


def test_the_presets_plot_draws_each_run_as_its_fraction_of_the_limit(monkeypatch, tmp_path):
    import matplotlib.axes

    throughput = script(monkeypatch, "throughput")
    drawn, real_bar = {}, matplotlib.axes.Axes.bar

    def bar(self, x, height, *args, label=None, **kwargs):
        drawn[label] = [float(h) for h in height]
        return real_bar(self, x, height, *args, label=label, **kwargs)

    monkeypatch.setattr(matplotlib.axes.Axes, "bar", bar)
    results = throughput.add_ratios(fake_results())
    throughput.plots(results, tmp_path / "run", batch=32)
    # bars per kind over the labels "Breakout 2.2", "Breakout 3.1" (0: no such run)
    assert drawn == {"naive gymnasium gymnasium-async raw": [pytest.approx(0.2), 0.0],
                     "stori-jax subproc atari84": [pytest.approx(0.3), 0.0],
                     "stori-jax subproc raw": [pytest.approx(0.4), pytest.approx(0.5)]}


# -- jax_stages.py, ppo_rollout.py, xla_rollout.py ----------------------------------------------

def test_a_stage_time_is_ms_per_call_after_a_warm_up_call(monkeypatch):
    stages = script(monkeypatch, "jax_stages")
    clock = FakeClock()
    monkeypatch.setattr(stages, "time", clock)
    # compile, then one duration per batch; one slow batch (a GC pause): its mean would be 4
    durations = iter([5.0, 0.002, 0.001, 0.009])
    state = {}

    def fn(x):
        calls = state["calls"] = state.get("calls", 0) + 1
        if calls == 1 or (calls - 2) % 10 == 0:
            state["d"] = next(durations)
        clock.now += state["d"]
        return x

    assert stages.timed(fn, np.zeros(3), repeats=10) == pytest.approx(2.0)  # the median ms
    assert state["calls"] == 1 + 3 * 10


def test_the_stage_table_has_a_column_per_size(monkeypatch, tmp_path, capsys):
    stages = script(monkeypatch, "jax_stages")
    fake = {8: {"max-pool": 0.5, "frame stack": 0.25}, 32: {"max-pool": 2.0, "frame stack": 1.0}}
    monkeypatch.setattr(stages, "measure", lambda sizes: {b: fake[b] for b in sizes})
    stages.main(["--sizes", "8", "32", "--out", str(tmp_path)])
    (md,) = tmp_path.glob("jax-stages-*.md")
    assert table(md.read_text()) == [{"stage": "max-pool", "B = 8": "0.500", "B = 32": "2.000"},
                                     {"stage": "frame stack", "B = 8": "0.250",
                                      "B = 32": "1.000"}]
    (js,) = tmp_path.glob("jax-stages-*.json")
    assert json.loads(js.read_text())["results"] == {"8": fake[8], "32": fake[32]}


def test_a_median_rate_is_steps_per_second_of_each_repeat(monkeypatch):
    ppo_rollout = script(monkeypatch, "ppo_rollout")
    clock = FakeClock()
    monkeypatch.setattr(ppo_rollout, "time", clock)
    durations = iter([2.0, 1.0, 4.0])

    def fn():
        clock.now += next(durations)

    assert ppo_rollout.median_rate(fn, steps=100, repeats=3) == pytest.approx(50.0)


def test_the_ppo_table_divides_by_the_env_only_rate(monkeypatch):
    ppo_rollout = script(monkeypatch, "ppo_rollout")
    from baselines import ppo

    r = dict(env_only=1000.0, rollout_overlapped=800.0, rollout_sequential=400.0,
             update_per_s=4000.0, training_sps_model=640.0)
    text = ppo_rollout.markdown(ppo.PPOConfig(game="Boxing", preset="3.1"), r)
    rows = {row["stage"]: row for row in table(text)}
    assert rows["PPO rollout, agent overlapping emulation"] == {
        "stage": "PPO rollout, agent overlapping emulation", "agent steps/s": "800",
        "/ env only": "0.80"}
    assert rows["PPO rollout, choose then step (no overlap)"]["agent steps/s"] == "400"
    assert rows["PPO update alone (agent steps consumed/s)"]["/ env only"] == "4.00"
    assert "Overlap speed-up of the rollout: 2.00x" in text


def test_the_xla_rollout_table_holds_each_loop_in_its_column(monkeypatch):
    xla_rollout = script(monkeypatch, "xla_rollout")
    text = xla_rollout.markdown("Breakout", "3.1", 128, [
        dict(num_envs=8, python_loop=700.0, compiled_scan=350.0, ratio=0.5)])
    assert table(text) == [{"B": "8", "stori_jax.rollout (Python loop)": "700",
                            "lax.scan over env.xla()": "350", "ratio": "0.50"}]


# -- naive_baseline.py --------------------------------------------------------------------------

@pytest.mark.parametrize("game", ["Breakout", "Boxing", "Gopher", "BankHeist"])
def test_the_naive_baseline_switches_concept_at_the_same_steps_as_stori_jax(monkeypatch, game):
    naive = script(monkeypatch, "naive_baseline")
    from stori_jax.functional.drift import concept2_probability

    config = stori_jax.preset(game, "2.2")
    drift = config.drift
    wrapper = SimpleNamespace(drift=drift, rng=np.random.default_rng(0),
                              drifted={"ObservationMask": True, "ActionNoise": False})
    for k in [0, 1, drift.period - 1, drift.period, drift.period + 1, 2 * drift.period - 1,
              2 * drift.period, 3 * drift.period, 5 * drift.period - 1]:
        wrapper.episode_step = k
        active = naive.StoriNumpyWrapper._active_parts(wrapper)
        concept2 = bool(concept2_probability(k, drift.schedule, drift.period))
        assert active == ({"ObservationMask", "ActionNoise"} if concept2 else {"ActionNoise"}), k


def test_the_naive_baseline_masks_as_stori_jax_does(monkeypatch):
    """Gopher 3.2 (per-frame blackout, p = 1): the hidden region takes its fill, nothing else
    changes; a RAM-obs mask or an inactive part leaves the frame alone."""
    naive = script(monkeypatch, "naive_baseline")
    from stori_jax.functional.masks import region_mask

    mask = stori_jax.preset("Gopher", "3.2").observation
    hidden, fill = region_mask(stori_jax.get_game("Gopher").blackout_modes[mask.mode].regions)
    wrapper = SimpleNamespace(mask=mask, active={"ObservationMask"}, hidden=hidden, fill=fill,
                              rng=np.random.default_rng(0))
    frame = np.random.default_rng(1).integers(0, 256, (210, 160, 3), np.uint8)
    out = naive.StoriNumpyWrapper._mask(wrapper, frame)
    np.testing.assert_array_equal(out[hidden], fill[hidden])
    np.testing.assert_array_equal(out[~hidden], frame[~hidden])
    assert hidden.any() and not np.array_equal(out, frame)
    wrapper.active = set()
    assert naive.StoriNumpyWrapper._mask(wrapper, frame) is frame


def test_the_naive_baseline_nets_a_cancelled_boxing_hit_to_zero_as_stori_jax_does(monkeypatch):
    """Boxing event mode 2 cancels a hit and the game answers it with a negative reward on the
    next frame, which stori-jax takes off (cancel_next_reward): the naive baseline left it in
    (rewards of -2 and -1 at p = 1, where stori-jax's are all 0)."""
    naive = script(monkeypatch, "naive_baseline")
    game = stori_jax.get_game("Boxing")

    def rewards(prob):
        env = gym.make("ALE/Boxing-v5", frameskip=1, repeat_action_probability=0.0,
                       obs_type="rgb")
        wrapper = naive.StoriNumpyWrapper(
            env, game=game, config=stori_jax.Config(event=stori_jax.RandomEvent(2, prob)),
            frame_skip=4, seed=3)
        wrapper.reset(seed=3)
        actions, out = np.random.default_rng(0), []
        for _ in range(600):
            _, reward, terminated, truncated, _ = wrapper.step(int(actions.integers(18)))
            out.append(reward)
            assert not (terminated or truncated)
        env.close()
        return np.array(out)

    assert (rewards(0.0) != 0).sum() >= 10  # hits land in these steps
    assert (rewards(1.0) == 0).all()  # every one cancelled, netting 0


class FakeAtari(gym.Env):
    """Stands in for a frameskip=1 gymnasium ALE env: frame t (from 1) has row t lit, every
    frame scores 1, and the actions played are logged."""

    def __init__(self):
        self.observation_space = gym.spaces.Box(0, 255, (210, 160, 3), np.uint8)
        self.action_space = gym.spaces.Discrete(4)
        self.ale = SimpleNamespace(getRAM=lambda: np.zeros(128, np.uint8),
                                   getEpisodeFrameNumber=lambda: self.t)
        self.t, self.played = 0, []

    def frame(self):
        frame = np.zeros((210, 160, 3), np.uint8)
        frame[self.t % 210] = 50
        return frame

    def reset(self, **kwargs):
        self.t = 0
        return self.frame(), {}

    def step(self, action):
        self.t += 1
        self.played.append(int(action))
        return self.frame(), 1.0, False, False, {}


def naive_wrapper(monkeypatch, game, preset):
    naive = script(monkeypatch, "naive_baseline")
    env = FakeAtari()
    wrapper = naive.StoriNumpyWrapper(env, game=stori_jax.get_game(game),
                                      config=stori_jax.preset(game, preset), frame_skip=4, seed=0)
    wrapper.reset()
    return wrapper, env


def test_the_naive_baseline_refuses_what_it_cannot_play_and_plays_every_paper_preset(
        monkeypatch):
    naive = script(monkeypatch, "naive_baseline")
    from stori_jax.presets import list_presets

    for game, name in list_presets():
        naive.check_supported(stori_jax.preset(game, name))
    noise = stori_jax.ActionNoise(0.1)
    for config, refused in (
            (stori_jax.Config(action_noise=noise, granularity="step"), "granularity 'step'"),
            (stori_jax.Config(ram_observation=True), "ram_observation"),
            (stori_jax.Config(action_noise=stori_jax.ActionNoise(0.1, sticky=True)), "sticky")):
        with pytest.raises(ValueError, match=f"the naive baseline cannot play this config: "
                                             f".*{refused}"):
            naive.make_naive_vector_env("Breakout", config, 2, seed=0)


def test_a_naive_step_plays_the_frame_skip_and_max_pools_the_last_two_screens(monkeypatch):
    wrapper, env = naive_wrapper(monkeypatch, "Breakout", "3.1")
    frame, reward, terminated, truncated, _ = wrapper.step(2)
    assert env.played == [2, 2, 2, 2] and reward == 4.0 and not (terminated or truncated)
    assert sorted(np.flatnonzero(frame.any(axis=(1, 2)))) == [3, 4]  # frames 3 and 4, pooled


def test_the_naive_action_noise_replaces_with_the_presets_probability_per_frame(monkeypatch):
    """Breakout 1: p = 0.3 per frame, replaced uniformly from the 4 actions, so an intended
    action is changed on 0.3 * 3/4 of the frames."""
    wrapper, env = naive_wrapper(monkeypatch, "Breakout", "1")
    for _ in range(1000):
        wrapper.step(2)
    played = np.array(env.played)
    assert len(played) == 4000 and set(played) == {0, 1, 2, 3}
    assert np.mean(played != 2) == pytest.approx(0.3 * 3 / 4, abs=0.03)


def test_the_naive_blackout_masks_each_screen_before_the_max_pool(monkeypatch):
    """Gopher 3.2 (per-frame blackout, p = 1): the pooled frame shows the fill where hidden."""
    from stori_jax.functional.masks import region_mask

    wrapper, env = naive_wrapper(monkeypatch, "Gopher", "3.2")
    mask = stori_jax.preset("Gopher", "3.2").observation
    hidden, fill = region_mask(stori_jax.get_game("Gopher").blackout_modes[mask.mode].regions)
    frame = wrapper.step(0)[0]
    np.testing.assert_array_equal(frame[hidden], fill[hidden])
    expected = np.zeros_like(frame)
    expected[[3, 4]] = 50
    np.testing.assert_array_equal(frame[~hidden], expected[~hidden])


def test_the_naive_episode_step_counts_agent_steps_into_concept_2(monkeypatch):
    """Gopher 2.2 (cyclic, T = 600, a p = 1 blackout in concept 2): the first T steps of an
    episode are concept 1 (no mask); step T + 1 is agent step T, concept 2's, masked."""
    from stori_jax.functional.masks import region_mask

    wrapper, env = naive_wrapper(monkeypatch, "Gopher", "2.2")
    drift = stori_jax.preset("Gopher", "2.2").drift
    mask = drift.secondary.observation
    hidden, fill = region_mask(stori_jax.get_game("Gopher").blackout_modes[mask.mode].regions)
    for _ in range(drift.period):
        frame = wrapper.step(0)[0]
    assert wrapper.episode_step == drift.period and wrapper.active == set()
    assert not np.array_equal(frame[hidden], fill[hidden])
    frame = wrapper.step(0)[0]
    assert wrapper.episode_step == drift.period + 1
    assert wrapper.active == {"ObservationMask"}
    np.testing.assert_array_equal(frame[hidden], fill[hidden])
    wrapper.reset()
    assert wrapper.episode_step == 0 and wrapper.active == set()


def test_each_naive_env_draws_from_its_own_seeded_stream(monkeypatch):
    """Env i of seed s is seeded s * 100003 + i: the envs of a vector env do not all replay one
    stream, and the same seed gives the same streams again."""
    naive = script(monkeypatch, "naive_baseline")
    monkeypatch.setattr(gym, "make", lambda *args, **kwargs: FakeAtari())
    monkeypatch.setattr(gym.vector, "AsyncVectorEnv", lambda thunks, **kwargs: thunks)

    def streams(seed):
        thunks = naive.make_naive_vector_env("Breakout", stori_jax.preset("Breakout", "1"), 4,
                                             seed=seed)
        return [tuple(thunk().rng.random(4)) for thunk in thunks]

    first = streams(3)
    assert len(set(first)) == 4
    assert streams(3) == first and set(streams(4)).isdisjoint(first)


class FakeStoriEnv:
    """What the rollout benchmarks use of an env, without emulators."""

    num_actions = 4

    def __init__(self, *args, num_envs=2, **kwargs):
        self.num_envs = num_envs

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def reset(self):
        return np.zeros((self.num_envs, 4), np.float32), {}

    def step(self, actions):
        return (np.zeros((self.num_envs, 4), np.float32),)

    def xla(self):
        import jax.numpy as jnp

        def step(handle, actions):
            return handle + 1, (jnp.zeros((self.num_envs, 4), jnp.float32),)
        return 0, step

    def close(self):
        pass


def rates_in_order(*rates):
    """A median_rate that runs the loop once and returns ``rates`` in turn (and the steps)."""
    queue, seen = list(rates), []

    def median_rate(fn, steps, repeats):
        fn()
        seen.append(steps)
        return queue.pop(0)
    return median_rate, seen


def test_the_xla_ratio_is_the_compiled_rate_over_the_python_loops(monkeypatch):
    import jax.numpy as jnp

    xla_rollout = script(monkeypatch, "xla_rollout")
    median_rate, seen = rates_in_order(700.0, 350.0)  # the Python loop is measured first
    monkeypatch.setattr(xla_rollout, "median_rate", median_rate)
    monkeypatch.setattr(stori_jax, "make", FakeStoriEnv)
    monkeypatch.setattr(stori_jax, "rollout", lambda env, policy, params, key, steps, obs:
                        SimpleNamespace(last_obs=obs))
    monkeypatch.setattr(xla_rollout.ppo, "make_network", lambda config, n: SimpleNamespace(
        init=lambda key, obs: {}))
    monkeypatch.setattr(xla_rollout.ppo, "act",
                        lambda network, params, obs, key: (jnp.zeros(obs.shape[0], jnp.int32),))
    row = xla_rollout.measure("Breakout", "3.1", num_envs=2, steps=5, repeats=3)
    assert row == dict(num_envs=2, python_loop=700.0, compiled_scan=350.0, ratio=0.5)
    assert seen == [10, 10]  # agent steps summed over the batch


def stub_ppo_setup(monkeypatch, ppo):
    """ppo's env-only rate, envs, network and optimizer as measure_stages makes them: stubs."""
    monkeypatch.setattr(ppo, "env_only_sps", lambda config, steps: 1000.0)
    monkeypatch.setattr(ppo, "make_envs", lambda config: [FakeStoriEnv(), FakeStoriEnv()])
    monkeypatch.setattr(ppo, "make_network", lambda config, n: SimpleNamespace(
        init=lambda key, obs: {}))
    monkeypatch.setattr(ppo, "make_optimizer", lambda config: SimpleNamespace(
        init=lambda params: {}))


def test_the_training_rate_model_adds_rollout_and_update_time(monkeypatch):
    import jax.numpy as jnp

    ppo_rollout = script(monkeypatch, "ppo_rollout")
    from baselines import ppo

    config = ppo.PPOConfig(num_envs=4, num_steps=8)
    # in order: the overlapped rollout, the update, the sequential rollout
    median_rate, seen = rates_in_order(800.0, 4000.0, 400.0)
    monkeypatch.setattr(ppo_rollout, "median_rate", median_rate)
    monkeypatch.setattr(stori_jax, "make", FakeStoriEnv)
    stub_ppo_setup(monkeypatch, ppo)
    monkeypatch.setattr(ppo, "act", lambda network, params, obs, key: (
        jnp.zeros(obs.shape[0], jnp.int32), None, None))
    monkeypatch.setattr(ppo, "make_update", lambda network, optimizer, config:
                        lambda params, opt_state, rollout, obs, key: obs)
    monkeypatch.setattr(ppo, "collect", lambda envs, act_fn, params, obs, key, n, episodes,
                        step0: (jnp.zeros(1), obs, key))
    r = ppo_rollout.measure_stages(config, 3, SimpleNamespace(set_postfix_str=print,
                                                              update=lambda: None))
    assert seen == [32, 32, 32]
    assert r == dict(env_only=1000.0, rollout_overlapped=800.0, update_per_s=4000.0,
                     rollout_sequential=400.0,
                     training_sps_model=pytest.approx(1 / (1 / 800 + 1 / 4000)))


def test_the_ppo_stages_compile_before_timing_and_run_the_sequential_batch_on_both_halves_workers(
        monkeypatch):
    """Each timed loop runs once before its timing (its compile is not timed), and the no-overlap
    rollout steps all num_envs on as many workers as the two halves have together (9 cores: 4 a
    half), none inline."""
    import os

    import jax.numpy as jnp

    ppo_rollout = script(monkeypatch, "ppo_rollout")
    from baselines import ppo

    config = ppo.PPOConfig(num_envs=8, num_steps=4)
    calls, timed, made = Counter(), [], []

    def median_rate(fn, steps, repeats):
        timed.append(dict(calls))  # how often each loop ran before this timing
        fn()
        return 100.0

    class Env(FakeStoriEnv):
        def __init__(self, *args, **kwargs):
            made.append((args, kwargs))
            super().__init__(*args, **kwargs)

    def count(name, result=None):
        def fn(*args, **kwargs):
            calls[name] += 1
            return result(*args) if result else None
        return fn

    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: set(range(9)))
    monkeypatch.setattr(ppo_rollout, "median_rate", median_rate)
    monkeypatch.setattr(stori_jax, "make", Env)
    stub_ppo_setup(monkeypatch, ppo)
    monkeypatch.setattr(ppo, "make_update", lambda network, optimizer, config: count(
        "update", lambda params, opt_state, rollout, obs, key: obs))
    monkeypatch.setattr(ppo, "collect", count("overlapped", lambda envs, act_fn, params, obs,
                                              key, n, episodes, step0: (jnp.zeros(1), obs, key)))
    monkeypatch.setattr(ppo_rollout, "sequential_rollout", count("sequential"))
    ppo_rollout.measure_stages(config, 3, SimpleNamespace(set_postfix_str=print,
                                                          update=lambda: None))
    assert timed == [dict(overlapped=1), dict(overlapped=2, update=1),
                     dict(overlapped=2, update=2, sequential=1)]
    (args, kwargs), = made
    assert ppo.workers_per_half(config.num_envs // 2) == 4
    assert args == (config.game, config.preset) and kwargs == dict(
        num_envs=8, seed=0, obs="atari84", num_workers=8, inline_envs=0)


def test_the_xla_loops_compile_before_timing(monkeypatch):
    """The Python loop and the compiled scan each run once before their timing: the scan's
    first call traces and compiles it (the env's step runs in Python only then)."""
    import jax.numpy as jnp

    xla_rollout = script(monkeypatch, "xla_rollout")
    calls, timed = Counter(), []

    def median_rate(fn, steps, repeats):
        timed.append(dict(calls))
        fn()
        return 100.0

    class Env(FakeStoriEnv):
        def xla(self):
            handle, step = super().xla()

            def traced(handle, actions):
                calls["compiled"] += 1
                return step(handle, actions)
            return handle, traced

    def rollout(env, policy, params, key, steps, obs):
        calls["python"] += 1
        return SimpleNamespace(last_obs=obs)

    monkeypatch.setattr(xla_rollout, "median_rate", median_rate)
    monkeypatch.setattr(stori_jax, "make", Env)
    monkeypatch.setattr(stori_jax, "rollout", rollout)
    monkeypatch.setattr(xla_rollout.ppo, "make_network", lambda config, n: SimpleNamespace(
        init=lambda key, obs: {}))
    monkeypatch.setattr(xla_rollout.ppo, "act",
                        lambda network, params, obs, key: (jnp.zeros(obs.shape[0], jnp.int32),))
    xla_rollout.measure("Breakout", "3.1", num_envs=2, steps=5, repeats=3)
    assert len(timed) == 2 and timed[0] == dict(python=1)
    assert timed[1]["python"] == 2 and timed[1].get("compiled", 0) >= 1


def test_the_peers_run_raw_frames_at_the_same_batch_threads_and_frame_skip(monkeypatch):
    """Raw envpool and ale-py's AtariVectorEnv: B envs, W threads, frame skip 4, max-pooled
    210x160 RGB, one frame a stack (84x84 gray x4 beside atari84), no reward clipping, no
    episodic life, no sticky actions."""
    import ale_py.vector_env
    import envpool

    throughput = script(monkeypatch, "throughput")
    made = {}

    class FakePool:
        def __init__(self, *args, **kwargs):
            made.setdefault("args", []).append((args, kwargs))

        def reset(self, **kwargs):
            pass

        def close(self):
            pass

    monkeypatch.setattr(envpool, "make", FakePool)
    monkeypatch.setattr(ale_py.vector_env, "AtariVectorEnv", FakePool)
    monkeypatch.setattr(throughput, "_timed_loop", lambda step, b, n, seconds: 123.0)
    assert throughput.envpool_peer("Gopher", 6, 3, 1.0) == 123.0
    assert throughput.ale_vector("Gopher", 6, 3, 1.0) == 123.0
    (pool_args, pool), (vector_args, vector) = made["args"]
    assert pool_args == ("Gopher-v5",) and {k: pool[k] for k in (
        "num_envs", "batch_size", "num_threads", "frame_skip", "img_height", "img_width",
        "gray_scale", "stack_num", "reward_clip", "episodic_life",
        "repeat_action_probability")} == dict(
        num_envs=6, batch_size=6, num_threads=3, frame_skip=4, img_height=210, img_width=160,
        gray_scale=False, stack_num=1, reward_clip=False, episodic_life=False,
        repeat_action_probability=0.0)
    assert vector_args == ("gopher", 6) and {k: vector[k] for k in (
        "num_threads", "frameskip", "maxpool", "img_height", "img_width", "grayscale",
        "stack_num", "reward_clipping")} == dict(
        num_threads=3, frameskip=4, maxpool=True, img_height=210, img_width=160,
        grayscale=False, stack_num=1, reward_clipping=False)
    assert vector.get("repeat_action_probability", 0.0) == 0.0
    assert not vector.get("episodic_life", False)
    throughput.envpool_peer("Gopher", 6, 3, 1.0, obs="atari84")
    throughput.ale_vector("Gopher", 6, 3, 1.0, obs="atari84")
    (_, pool84), (_, vector84) = made["args"][2:]
    assert {k: pool84[k] for k in ("img_height", "img_width", "gray_scale", "stack_num")} == \
        dict(img_height=84, img_width=84, gray_scale=True, stack_num=4)
    assert {k: vector84[k] for k in ("img_height", "img_width", "grayscale", "stack_num")} == \
        dict(img_height=84, img_width=84, grayscale=True, stack_num=4)


def test_each_jax_stage_computes_what_its_name_says(monkeypatch):
    """At B = 2: the masks are per frame (the torch one a torch), the fused stage masks before
    pooling and resizing, and the draws are those of a type-1 preset."""
    import jax.numpy as jnp

    import stori_jax.core
    from stori_jax import functional as F

    jax_stages = script(monkeypatch, "jax_stages")
    captured, draws, plans = {}, [], []
    monkeypatch.setattr(jax_stages, "timed", lambda fn, *args: captured.setdefault(
        "last", (fn, args)))
    real_draws, real_before = F.draw_mask_decisions, stori_jax.core.before_step
    monkeypatch.setattr(F, "draw_mask_decisions", lambda keys, **kw: (
        draws.append(kw), real_draws(keys, **kw))[1])
    monkeypatch.setattr(stori_jax.core, "before_step", lambda plan, *args: (
        plans.append(plan), real_before(plan, *args))[1])
    out = {}
    for name, thunk in jax_stages.stages(2).items():
        captured.clear()
        thunk()
        fn, args = captured["last"]
        draws.clear()
        out[name] = (fn(*args), args, list(draws))
    blackout, (keys, pair), blackout_draws = out["blackout mask (per frame)"]
    assert blackout_draws == [dict(prob=1.0, per_frame=True, torch=False)]
    hidden, fill = F.region_mask(stori_jax.get_game("Breakout").blackout_modes[10].regions)
    assert blackout.shape == (2, 2, 210, 160, 3) and hidden.any()
    np.testing.assert_array_equal(np.asarray(blackout)[:, :, hidden],
                                  np.broadcast_to(fill[hidden], (2, 2) + fill[hidden].shape))
    assert out["torch mask (per frame)"][2] == [dict(prob=1.0, per_frame=True, torch=True)]
    fused = out["mask + max-pool + atari84"][0]
    np.testing.assert_array_equal(fused, F.atari84_frame(F.max_pool(blackout)))
    assert out["max-pool"][0].shape == (2, 210, 160, 3)
    assert out["copy two screens into JAX"][0].shape == (2, 2, 210, 160, 3)
    assert out["luma + area resize 84x84"][0].shape == (2, 84, 84)
    assert len(plans) == 1 and plans[0].noise is not None
    assert isinstance(fused, jnp.ndarray)


def test_the_sequential_rollout_chooses_then_steps_every_step(monkeypatch):
    import jax
    import jax.numpy as jnp

    ppo_rollout = script(monkeypatch, "ppo_rollout")
    log = []

    class Env:
        def step(self, actions):
            log.append(("step", int(actions[0])))
            return (jnp.full((2, 1), len(log), jnp.float32),)

    def act(params, obs, key):
        log.append(("act", int(obs[0, 0])))
        return jnp.full(2, len(log), jnp.int32), None, None

    obs = ppo_rollout.sequential_rollout(Env(), act, {}, jnp.zeros((2, 1)),
                                         jax.random.PRNGKey(0), 3)
    assert log == [("act", 0), ("step", 1), ("act", 2), ("step", 3), ("act", 4), ("step", 5)]
    assert float(obs[0, 0]) == 6


@pytest.mark.parametrize("name, argv, suffix", [
    ("xla_rollout", [], ""),
    ("xla_rollout", ["--sizes", "8", "32"], ""),  # the defaults, spelt out
    ("xla_rollout", ["--sizes", "2", "--steps", "8", "--repeats", "1"], "-B2-steps8-repeats1"),
    ("ppo_rollout", [], ""),
    ("ppo_rollout", ["--repeats", "1"], "-repeats1"),
    ("jax_stages", [], ""),
    ("jax_stages", ["--sizes", "256", "1024"], "-B256-1024"),
])
def test_the_other_scripts_name_a_run_with_other_options_apart(monkeypatch, tmp_path, name,
                                                               argv, suffix):
    """A tiny xla_rollout run overwrote the day's full one (a GPU run of jax_stages with --sizes
    256 1024 the day's default one): an option that differs from its default is in the names."""
    module = script(monkeypatch, name)
    if name == "jax_stages":
        monkeypatch.setattr(module, "measure", lambda sizes: {b: {"stage": 1.0} for b in sizes})
    else:
        monkeypatch.setattr(module, "measure", lambda *args: dict(
            num_envs=1, python_loop=1.0, compiled_scan=1.0, ratio=1.0))
        monkeypatch.setattr(module, "markdown", lambda *args: "title\n")
        monkeypatch.setattr(module, "plot", lambda rows, path, title: path.write_bytes(b""))
    if name == "ppo_rollout":
        monkeypatch.setattr(module, "stage_rates", lambda results: [])
    module.main(argv + ["--out", str(tmp_path)])
    stems = {p.name.rsplit(".", 1)[0] for p in tmp_path.iterdir()}
    assert len(stems) == 1
    (stem,) = stems
    assert stem.endswith({"xla_rollout": "-Breakout-3.1", "ppo_rollout": "-Breakout-3.1-nips",
                          "jax_stages": ""}[name] + suffix), stem
    day = datetime.date.today().isoformat()
    assert stem.startswith(f"{name.replace('_', '-')}-{day}")
    data = json.loads((tmp_path / f"{stem}.json").read_text())
    assert_made_with_this_software(data["meta"]["software"] if name == "jax_stages"
                                   else data["software"])


@pytest.mark.parametrize("argv, suffix", [([], ""), (["--batch", "64", "--frame-work", "caller"],
                                                     "-B64-caller")])
def test_a_step_profile_has_a_row_per_frame_work_placement_and_its_options_in_the_name(
        monkeypatch, tmp_path, argv, suffix):
    profile_step = script(monkeypatch, "profile_step")
    asked = []

    def fake(game, preset, obs, batch, steps, frame_work):
        asked.append((obs, batch, frame_work))
        return dict(game=game, preset=preset, obs=obs, B=batch, inline_envs=8, workers=1,
                    frame_work=frame_work, frames_layout="pooled",
                    steps_per_s=1000.0, wall_ms_per_step=32.0,
                    phases_ms=dict.fromkeys(profile_step.PHASES, 1.0), cpu_ms_here=20.0,
                    cpu_ms_workers=10.0)

    monkeypatch.setattr(profile_step, "profile", fake)
    profile_step.main(argv + ["--out", str(tmp_path)])
    batch, placements = (64, ["caller"]) if argv else (32, ["workers", "caller"])
    assert asked == [(obs, batch, w) for obs in ("raw", "atari84") for w in placements]
    (md,) = tmp_path.glob("*.md")
    assert md.name == f"profile-{datetime.date.today().isoformat()}-" \
                      f"{json.loads(md.with_suffix('.json').read_text())['meta']['host']}" \
                      f"{suffix}.md"
    rows = table(md.read_text())
    assert len(rows) == len(asked) and rows[0]["split (workers + here)"] == "1 + 8"
    assert rows[0]["send"] == "1.00" and rows[0]["CPU workers"] == "10.00"


def test_the_objects_benchmark_writes_its_rows(monkeypatch, tmp_path):
    """One smoke run of objects_throughput.py (tiny batch): a row per variant, JSON + table +
    plot written."""
    bench = script(monkeypatch, "objects_throughput")
    bench.main(["--games", "Breakout", "--batch", "2", "--steps", "2", "--repeats", "1",
                "--out", str(tmp_path)])
    written = sorted(p.suffix for p in tmp_path.iterdir())
    assert written == [".json", ".md", ".png"]
    results = json.loads(next(tmp_path.glob("*.json")).read_text())["results"]["Breakout"]
    assert list(results) == ["3.1 raw", "objects", "3.1 atari84", "hide Ball atari84"]
    assert all(rate > 0 for rate in results.values())
