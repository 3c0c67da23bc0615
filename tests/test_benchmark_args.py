"""The benchmark scripts refuse bad arguments with a usage error naming the option, before
measuring anything (a bad preset used to surface as a traceback after the emulators started)."""

import importlib
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def script(monkeypatch, name: str):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    return importlib.import_module(name)


@pytest.mark.parametrize("name, argv, message", [
    ("throughput", ["--batch", "0"], "--batch: must be >= 1, got 0"),
    ("throughput", ["--sizes", "8", "-1"], "--sizes: must be >= 1, got [8, -1]"),
    ("throughput", ["--workers", "0"], "--workers: must be >= 1"),
    ("throughput", ["--presets", "9.9"], "--presets: unknown ['9.9']; allowed: ['1', "),
    ("throughput", ["--games", "Gopher", "--presets", "3.2A"],
     "--presets: unknown ['3.2A']; allowed for Gopher: ['1', '2.1', '2.2', '3.1', '3.2']"),
    ("throughput", ["--games", "Breakout", "Pong"], "--games: game must be one of the STORI"),
    ("jax_stages", ["--sizes", "0"], "--sizes: must be >= 1, got [0]"),
    ("ppo_rollout", ["--repeats", "0"], "--repeats: must be >= 1, got 0"),
    ("ppo_rollout", ["--preset", "2"],
     "--preset: unknown preset '2' for Breakout: allowed ['1', '2.1'"),
    ("xla_rollout", ["--steps", "0"], "--steps: must be >= 1, got 0"),
    ("xla_rollout", ["--game", "Pong"], "--game: game must be one of the STORI games"),
    ("xla_rollout", ["--game", "Nope"], "--game: unknown game 'Nope': game must be one of the "
                                        "STORI games ['Breakout', 'Boxing', 'Gopher', "
                                        "'BankHeist'] (the baselines play the paper's presets)"),
    ("xla_rollout", ["--game", "boxing", "--preset", "3.3"],
     "--preset: unknown preset '3.3' for Boxing: allowed"),
    # sizes that cannot fit: throughput.py hung building emulators, the others failed late
    ("throughput", ["--batch", "50000000"], "--batch 50000000 with frame_skip=4 needs"),
    ("throughput", ["--sizes", "8", "50000000"], "--sizes 50000000 with frame_skip=4 needs"),
    ("jax_stages", ["--sizes", "50000000"], "choose a smaller --sizes"),
    ("xla_rollout", ["--sizes", "8", "50000000"], "choose a smaller --sizes"),
    ("throughput", ["--seconds", "inf"], "--seconds must be a finite number > 0, got inf"),
    ("throughput", ["--seconds", "0"], "--seconds must be a finite number > 0, got 0.0"),
    ("throughput", ["--games", "Gopher", "--sizes", "8"],  # was measured as nothing, silently
     "--sizes sets the B of the Breakout 3.1 sweep, which this run does not measure"),
    ("throughput", ["--presets", "2.2", "--sizes", "8"], "--sizes sets the B of the Breakout"),
])
def test_bad_arguments_are_usage_errors_naming_the_option(monkeypatch, capsys, tmp_path,
                                                          name, argv, message):
    module = script(monkeypatch, name)

    def measured(*args, **kwargs):  # an argument let through would start real emulators
        raise AssertionError(f"{name} {argv} was measured instead of refused")

    monkeypatch.setattr(module, "run" if name == "throughput" else "measure", measured)
    with pytest.raises(SystemExit) as exit_info:
        module.main(argv + ["--out", str(tmp_path)])
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err
    assert not any(tmp_path.iterdir())  # refused before measuring or writing anything


@pytest.mark.parametrize("name", ["throughput", "jax_stages", "xla_rollout", "ppo_rollout"])
def test_an_unusable_out_is_refused_before_measuring(monkeypatch, capsys, tmp_path, name):
    """--out naming a file (or a folder that cannot be made) ran the whole measurement, then
    failed with a traceback from mkdir."""
    a_file = tmp_path / "results"
    a_file.write_text("not a folder")
    with pytest.raises(SystemExit) as exit_info:
        script(monkeypatch, name).main(["--out", str(a_file)])
    assert exit_info.value.code == 2
    assert f"--out {a_file} exists and is not a directory" in capsys.readouterr().err


def test_preset_names_are_spelt_as_the_paper_does(monkeypatch):
    """'3.2a' was refused by throughput.py and written as '3.2a' into the file names of the
    rollout benchmarks; every script now takes any case and spells it 3.2A."""
    import argparse

    throughput = script(monkeypatch, "throughput")
    parser = argparse.ArgumentParser()
    args = argparse.Namespace(seconds=1.0, batch=8, workers=1, sizes=None, games=None,
                              presets=["3.2a", "2.1"], quick=False, out=Path("results"))
    throughput._check_arguments(parser, args)
    assert args.presets == ["3.2A", "2.1"]
    checks = script(monkeypatch, "_checks")
    assert checks.stori_game_and_preset(parser, "boxing", "3.2c") == ("Boxing", "3.2C")


def test_throughput_without_envpool_is_refused_before_measuring(monkeypatch, capsys, tmp_path):
    """A throughput run with envpool rows, without the package, recorded an error in each of
    them after minutes of other measurements; a run without envpool rows needs no envpool."""
    throughput = script(monkeypatch, "throughput")
    real_find_spec = throughput.importlib.util.find_spec
    monkeypatch.setattr(throughput.importlib.util, "find_spec",
                        lambda name, *a, **k: None if name == "envpool"
                        else real_find_spec(name, *a, **k))
    with pytest.raises(SystemExit) as exit_info:
        throughput.main(["--quick", "--out", str(tmp_path)])
    assert exit_info.value.code == 2
    assert "envpool is not installed" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())
    measured = []  # Gopher 2.1 (events) has no envpool rows: it runs
    monkeypatch.setattr(throughput, "run", lambda args, jobs: measured.append(jobs) or [])
    monkeypatch.setattr(throughput, "plots", lambda *a: [])
    throughput.main(["--games", "Gopher", "--presets", "2.1", "--skip-naive", "--out",
                     str(tmp_path)])
    assert measured and not throughput.needs_envpool(measured[0])
