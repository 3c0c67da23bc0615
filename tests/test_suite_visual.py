"""The user-facing commands: suite (table, JSON, gallery), show (contact sheet), record (GIF)."""

import json
import os
from types import SimpleNamespace

import numpy as np
import pytest
from PIL import Image

import stori_jax
from stori_jax.cli import main


def test_suite_writes_table_json_and_gallery(tmp_path, capsys):
    out = tmp_path / "suite"
    assert main(["suite", "--games", "Breakout", "--presets", "1", "3.2A", "--episodes", "1",
                 "--num-envs", "2", "--max-steps", "60", "--out", str(out), "--quiet"]) == 0
    results = json.loads((out / "results.json").read_text())
    rows = results["rows"]
    assert [(r["game"], r["preset"]) for r in rows] == [("Breakout", "1"), ("Breakout", "3.2A")]
    assert results["software"]["packages"]["stori-jax"]
    noisy, masked = rows
    assert 0.2 < noisy["corrupted_fraction"] < 0.4  # p = 0.3 per frame
    assert noisy["masked_fraction"] == 0 and masked["masked_fraction"] == 1.0  # blackout p = 1
    assert masked["corrupted_actions"] == 0
    table = (out / "table.md").read_text()
    assert "| Breakout | 3.2A | blackout mode 10, p = 1.0 |" in table
    noisy_row = next(line for line in table.splitlines() if line.startswith("| Breakout | 1 |"))
    assert f"| {noisy['corrupted_actions']} ({noisy['corrupted_fraction']:.0%}) |" in noisy_row
    for name in ("1", "3.2A"):
        with Image.open(out / "gallery" / f"Breakout-{name}.png") as img:
            assert img.width > 300 and img.height > 400


@pytest.mark.parametrize("autoreset", [True, False])
def test_the_corrupted_fraction_counts_the_draws_of_played_frames_only(autoreset):
    """p = 1 per frame, episodes cut at frame 6 (steps of 4 frames): every frame played is
    corrupted, so the fraction is 1 (the frames after an episode's end, and the steps that
    reset an env instead (autoreset=False), are not draws)."""
    from stori_jax.suite import play

    config = stori_jax.Config(action_noise=stori_jax.ActionNoise(1.0), granularity="frame")
    with stori_jax.make("Breakout", config=config, num_envs=2, seed=0, num_workers=0, obs="ram",
                        max_episode_frames=6, autoreset=autoreset) as env:
        obs, _ = env.reset()
        row = play(env, obs, 0, max_steps=6)
    assert row["corrupted_fraction"] == 1.0
    # episodes of 2 steps (4 + 2 frames), then (autoreset=False) a reset step
    per_env = 3 * 6 if autoreset else 2 * 6
    assert row["corrupted_actions"] == row["action_draws"] == 2 * per_env


def test_a_suite_run_replaces_an_earlier_runs_files_and_nothing_else(tmp_path, capsys,
                                                                     monkeypatch):
    out = tmp_path / "suite"
    (out / "gallery").mkdir(parents=True)
    stale = [out / "gallery" / "Boxing-2.1.png", out / "gallery" / "Breakout-3.2A.png",
             out / "table.md", out / "results.json"]
    mine = [out / "notes.txt", out / "gallery" / "my-plot.png"]
    for path in stale + mine:
        path.write_text("earlier")
    # a run that stops early (Ctrl-C, an error) leaves the earlier run's files as they were
    import stori_jax.suite

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    with monkeypatch.context() as patch:
        patch.setattr(stori_jax.suite, "run_preset", interrupted)
        assert main(["suite", "--games", "Breakout", "--out", str(out), "--quiet"]) == 130
    assert all(path.read_text() == "earlier" for path in stale + mine)
    assert main(["suite", "--games", "Breakout", "--presets", "1", "--episodes", "1",
                 "--num-envs", "2", "--max-steps", "20", "--out", str(out), "--quiet",
                 "--no-gallery"]) == 0
    assert "removed 2 contact sheets of an earlier suite run" in capsys.readouterr().err
    assert not any(path.exists() for path in stale[:2])  # no sheet beside a table without it
    assert all(path.read_text() == "earlier" for path in mine)
    rows = json.loads((out / "results.json").read_text())["rows"]
    assert [(r["game"], r["preset"]) for r in rows] == [("Breakout", "1")]


def test_an_interrupted_first_suite_run_leaves_no_empty_folder(tmp_path, monkeypatch):
    """Ctrl-C in a run into a new --out (and a new parent) left both folders behind, empty;
    a folder that was there before stays."""
    import stori_jax.suite

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(stori_jax.suite, "run_preset", interrupted)
    out = tmp_path / "results" / "suite"
    assert main(["suite", "--games", "Breakout", "--out", str(out), "--quiet"]) == 130
    assert list(tmp_path.iterdir()) == []
    out.mkdir(parents=True)
    assert main(["suite", "--games", "Breakout", "--out", str(out), "--quiet"]) == 130
    assert list(out.iterdir()) == []


def test_a_suite_run_stopped_after_some_sheets_leaves_the_earlier_run_whole(tmp_path,
                                                                          monkeypatch):
    """A run into the folder of an earlier one, stopped after its first preset (a Ctrl-C):
    the earlier table and sheets stay as they were (the new first sheet used to replace the
    old one beside the old table), and no staging folder is left behind."""
    import stori_jax.suite

    out = tmp_path / "suite"
    (out / "gallery").mkdir(parents=True)
    earlier = [out / "table.md", out / "results.json", out / "gallery" / "Breakout-1.png"]
    for path in earlier:
        path.write_text("earlier")
    played = []
    real = stori_jax.suite.run_preset

    def stops_at_the_second(*args, **kwargs):
        if played:
            raise KeyboardInterrupt
        played.append(args)
        return real(*args, **kwargs)

    monkeypatch.setattr(stori_jax.suite, "run_preset", stops_at_the_second)
    assert main(["suite", "--games", "Breakout", "--presets", "1", "2.1", "--episodes", "1",
                 "--num-envs", "2", "--max-steps", "20", "--out", str(out), "--quiet"]) == 130
    assert played and all(path.read_text() == "earlier" for path in earlier)
    assert sorted(p.name for p in out.rglob("*")) == ["Breakout-1.png", "gallery",
                                                      "results.json", "table.md"]


def test_a_suite_run_removes_the_staging_folders_of_runs_killed_before_cleaning_up(tmp_path,
                                                                                   monkeypatch):
    """A suite killed by SIGTERM (a timeout, a scheduler, a closed terminal) runs no cleanup:
    its hidden staging folder of half-made sheets stayed in --out for good. The next run
    removes those of dead runs, not a running one's."""
    import multiprocessing
    import stori_jax.suite
    from stori_jax.suite import STAGING_PREFIX, _host

    out = tmp_path / "suite"
    dead = multiprocessing.get_context("spawn").Process(target=int)
    dead.start(), dead.join()
    host = _host()
    abandoned = out / f"{STAGING_PREFIX}{dead.pid}@{host}-abc123"
    live = out / f"{STAGING_PREFIX}{os.getpid()}@{host}-def456"  # this process runs
    elsewhere = out / f"{STAGING_PREFIX}{dead.pid}@{'0' * 16}-a_b1"  # its pids: not ours
    foreign = out / f"{STAGING_PREFIX}notapid"
    folders = (abandoned, live, elsewhere, foreign)
    for folder in folders:
        (folder / "gallery").mkdir(parents=True)
        (folder / "gallery" / "Breakout-1.png").write_text("half made")
    monkeypatch.setattr(stori_jax.suite, "run_preset", lambda game, name, **kw: dict(
        game=game, preset=name, definition="d", mean_return=None, episodes=0, events_fired=0,
        corrupted_actions=0, corrupted_fraction=0.0, masked_fraction=0.0, env_steps_per_s=None))
    stori_jax.suite.run_suite([("Breakout", "3.1")], episodes=1, num_envs=1, max_steps=1,
                              seed=0, out=out, gallery=False, progress=False)
    assert not abandoned.exists() and all(folder.is_dir() for folder in folders[1:])
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [folder.name for folder in folders[1:]] + ["results.json", "table.md"])


def test_an_interrupted_picture_leaves_the_earlier_file(tmp_path):
    """Ctrl-C while a long GIF is encoded left a 0-byte file in place of the earlier one."""
    from stori_jax.visual import _save_whole

    path = tmp_path / "episode.gif"
    path.write_bytes(b"earlier")

    def interrupted(tmp):
        with open(tmp, "wb") as f:
            f.write(b"half")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        _save_whole(path, interrupted)
    assert path.read_bytes() == b"earlier" and [p.name for p in tmp_path.iterdir()] == [
        "episode.gif"]
    _save_whole(path, lambda tmp: Image.new("RGB", (2, 2)).save(tmp))
    assert Image.open(path).format == "GIF"


@pytest.mark.parametrize("umask", [0o022, 0o077])
def test_pictures_are_written_as_any_file_is(tmp_path, umask):
    """With the umask's permissions (mkstemp's temporary file made every picture 0600)."""
    import os

    from stori_jax.visual import _save_whole

    old = os.umask(umask)
    try:
        path = _save_whole(tmp_path / "sheet.png", lambda tmp: Image.new("RGB", (2, 2)).save(tmp))
    finally:
        os.umask(old)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask
    assert [p.name for p in tmp_path.iterdir()] == ["sheet.png"]


def test_pictures_end_on_the_episodes_last_screen():
    """The step that ends an episode showed the next episode's first screen (autoreset):
    Breakout's last frame read score 000 and 5 lives again."""
    from stori_jax.visual import twin_run

    frames = twin_run("Breakout", stori_jax.preset("Breakout", "3.1"), 400, seed=0,
                      with_twin=False)
    assert len(frames) < 401, "the episode should end within 400 steps"
    assert (frames[-1]["preset"] != frames[0]["preset"]).any()


def test_show_puts_the_mask_on_the_preset_side_only(tmp_path):
    path = tmp_path / "sheet.png"
    assert main(["show", "Breakout", "3.2A", "--steps", "20", "--out", str(path)]) == 0
    sheet = np.asarray(Image.open(path).convert("RGB"))
    # layout: title 36 px, then rows of (16 px caption + 210 px screen + 6 px pad), columns of
    # 160 px + 6 px pad; blackout mode 10 hides ball bands y 105..130 and 157..182, x 8..151
    x0, top = 6, 36 + 16
    twin = sheet[top:top + 210, x0:x0 + 160]
    preset = sheet[top + 210 + 6 + 16:top + 2 * 210 + 6 + 16, x0:x0 + 160]
    for rows in (slice(105, 131), slice(157, 183)):  # the top and bottom bands: black
        assert (preset[rows, 8:152] == 0).all()
    np.testing.assert_array_equal(preset[:100], twin[:100])  # above the bands: untouched
    # the middle band and the frame around the bands: untouched
    np.testing.assert_array_equal(preset[131:157], twin[131:157])
    np.testing.assert_array_equal(preset[105:183, :8], twin[105:183, :8])
    np.testing.assert_array_equal(preset[105:183, 152:], twin[105:183, 152:])


def test_record_writes_an_animated_gif(tmp_path):
    path = tmp_path / "episode.gif"
    assert main(["record", "Boxing", "1", "--max-steps", "12", "--out", str(path)]) == 0
    with Image.open(path) as gif:
        assert gif.n_frames == 13  # the first observation and 12 steps


def test_show_and_record_without_a_preset_play_3_1_of_any_ale_py_game(tmp_path, capsys):
    """As `run` (and the help says): no preset is 3.1, so a game without presets works too."""
    assert main(["show", "Pong", "--steps", "4", "--out", str(tmp_path / "pong.png")]) == 0
    assert main(["record", "Breakout", "--max-steps", "3", "--out",
                 str(tmp_path / "b.GIF")]) == 0
    with Image.open(tmp_path / "b.GIF") as gif:
        assert gif.format == "GIF" and gif.n_frames == 4
    with Image.open(tmp_path / "pong.png") as sheet:
        assert sheet.format == "PNG"


@pytest.mark.parametrize("argv, message", [
    (["suite", "--games", "Pong"], "unknown game 'Pong' for presets"),
    (["suite", "--episodes", "0"], "--episodes must be >= 1"),
    (["show", "Pong", "3.1"], "another ale-py game takes no preset"),
    # the format follows the command, checked before anything runs (a .jpg record crashed in
    # Pillow after the whole episode; a .gif sheet was silently a GIF)
    (["record", "Breakout", "3.1", "--out", "r.jpg"],
     "--out r.jpg: record writes a GIF; give a path ending in .gif"),
    (["show", "Breakout", "3.1", "--out", "noext"],
     "--out noext: show writes a PNG; give a path ending in .png"),
    (["show", "Breakout", "3.1", "--out", "x.gif"], "show writes a PNG"),
])
def test_bad_arguments(argv, message, capsys):
    assert main(argv) == 2
    assert message in capsys.readouterr().err


class _TwoPaceEnv:
    """Env 0 ends an episode (return 1) every step, env 1 (return 10) every 5th step."""

    num_envs, num_actions = 2, 4

    def __init__(self):
        self.t = 0

    def step(self, actions):
        self.t += 1
        done = np.array([True, self.t % 5 == 0])
        info = dict(episode_return=np.where(done, [1.0, 10.0], 0.0), event_fired=np.zeros(2),
                    action_corrupted=np.zeros((2, 1), bool), frames_played=np.full(2, 4),
                    obs_masked=np.zeros(2, bool),
                    concept=np.zeros(2, np.int32))
        return np.zeros((2, 1)), np.zeros(2), done, np.zeros(2, bool), info


def test_the_suite_plays_a_quota_of_episodes_per_env_not_the_first_to_end():
    """8 episodes over 2 envs are 4 each: the mean does not favour the env whose episodes are
    short (stopping at the first 8 episodes gave 8 of env 0's, a mean of 1)."""
    from stori_jax.suite import play

    stats = play(_TwoPaceEnv(), np.zeros((2, 1)), 0, max_steps=1000, episodes=8,
                 policy=lambda obs, key: np.zeros(2, np.int32))
    assert stats["episodes"] == 8 and stats["mean_return"] == 5.5
    assert stats["agent_steps"] == 20  # env 1's fourth episode ends at step 20
    # 7 episodes: quotas (4, 3), returns 1, 1, 1, 1 and 10, 10, 10: the mean (a median, say,
    # would be 1; with 8 episodes the mean and the median are both 5.5)
    stats = play(_TwoPaceEnv(), np.zeros((2, 1)), 0, max_steps=1000, episodes=7,
                 policy=lambda obs, key: np.zeros(2, np.int32))
    assert stats["episodes"] == 7 and stats["agent_steps"] == 15
    assert stats["mean_return"] == pytest.approx(34 / 7)


def test_the_twin_row_keeps_its_last_screen_once_its_episode_ended_first():
    """Breakout 1, seed 1: the 3.1 twin's episode ends at step 187, the preset's at 202. The
    twin (autoreset off) then started a new episode, shown under the preset's "step 200" as if
    it were the same moment of the same episode (score 000, 5 lives)."""
    from stori_jax.visual import _twin_caption, twin_run

    frames = twin_run("Breakout", stori_jax.preset("Breakout", "1"), 200, seed=1)
    ended = frames[-1]["twin_ended"]
    assert ended is not None and 0 < ended < frames[-1]["step"]
    assert all(f["twin_ended"] is None for f in frames[:ended])
    assert all(np.array_equal(f["twin"], frames[ended]["twin"]) for f in frames[ended:])
    assert not np.array_equal(frames[ended - 1]["twin"], frames[ended]["twin"])
    assert _twin_caption(frames[-1]) == f"step {frames[-1]['step']} (twin's end: {ended})"
    assert _twin_caption(frames[ended]) == f"step {ended}"
    # a twin that plays the preset's own game (a mask changes no game) ends with it
    masked = twin_run("Breakout", stori_jax.preset("Breakout", "3.2A"), 60, seed=1)
    assert all(f["twin_ended"] is None for f in masked)


def test_the_rate_leaves_out_the_first_step_which_compiles(monkeypatch):
    """The suite's env steps/s timed the first step, which compiles the env's step and the
    policy: with short runs the column was mostly compile time (two identical runs of
    Breakout 1 gave 258 and 475)."""
    import stori_jax.suite
    from stori_jax.suite import play, table

    clock = SimpleNamespace(now=0.0)

    class CompilingEnv(_TwoPaceEnv):
        def step(self, actions):
            clock.now += 30.0 if self.t == 0 else 0.5  # the first step compiles
            return super().step(actions)

    monkeypatch.setattr(stori_jax.suite.time, "perf_counter", lambda: clock.now)
    policy = lambda obs, key: np.zeros(2, np.int32)  # noqa: E731
    stats = play(CompilingEnv(), np.zeros((2, 1)), 0, max_steps=5, policy=policy)
    assert stats["agent_steps"] == 5 and stats["timed_agent_steps"] == 4
    assert stats["elapsed_s"] == 2.0 and stats["env_steps_per_s"] == 4 * 2 / 2.0
    one = play(CompilingEnv(), np.zeros((2, 1)), 0, max_steps=1, policy=policy)
    assert one["env_steps_per_s"] is None  # nothing timed
    row = dict(game="Boxing", preset="2.1", definition="event", mean_return=None, episodes=0,
               events_fired=0, corrupted_actions=0, corrupted_fraction=0.0,
               masked_fraction=0.0, env_steps_per_s=None)
    assert table([row]).splitlines()[2].endswith("| - |")


def test_the_table_puts_each_value_under_its_own_column():
    from stori_jax.suite import table

    row = dict(game="Boxing", preset="2.1", definition="event", mean_return=1.25, episodes=7,
               events_fired=31, corrupted_actions=5, corrupted_fraction=0.25,
               masked_fraction=0.5, env_steps_per_s=1234.4)
    header, rule, line = table([row]).splitlines()
    names = [c.strip() for c in header.strip("|").split("|")]
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert len(names) == len(cells) == rule.count("---")
    assert dict(zip(names, cells)) == {
        "game": "Boxing", "preset": "2.1", "definition": "event", "mean return": "1.2",
        "episodes": "7", "events fired": "31", "corrupted actions (of draws)": "5 (25%)",
        "masked obs": "50%", "env steps/s (after the first)": "1234"}


def test_each_gallery_sheet_is_made_of_its_own_preset_with_the_runs_seed(tmp_path,
                                                                         monkeypatch):
    """Every contact sheet shows its own preset's config, played with the suite's seed, and
    lands under its own name (no emulator runs: the sheets and rows are stand-ins)."""
    import stori_jax.suite
    import stori_jax.visual

    made = []

    def sheet(game, name, config, path, *, seed):
        made.append((game, name, config, seed))
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(f"{game} {name}")
        return path

    def row(game, name, **kwargs):
        return dict(game=game, preset=name, definition=stori_jax.describe_preset(game, name),
                    mean_return=None, episodes=0, events_fired=0, corrupted_actions=0,
                    corrupted_fraction=0.0, masked_fraction=0.0, env_steps_per_s=1.0)

    monkeypatch.setattr(stori_jax.visual, "contact_sheet", sheet)
    monkeypatch.setattr(stori_jax.suite, "run_preset", row)
    presets = [("Breakout", "3.2A"), ("Boxing", "1"), ("Gopher", "2.2")]
    out = stori_jax.suite.run_suite(presets, episodes=1, num_envs=1, max_steps=1, seed=5,
                                    out=tmp_path / "suite", gallery=True, progress=False)
    assert made == [(g, n, stori_jax.preset(g, n), 5) for g, n in presets]
    for game, name in presets:
        assert (out / "gallery" / f"{game}-{name}.png").read_text() == f"{game} {name}"
    assert "[Boxing 1](gallery/Boxing-1.png)" in (out / "table.md").read_text()


def test_run_preset_plays_the_env_of_the_suites_seed(monkeypatch):
    """The suite's --seed is the env's seed and the agent's key stream (agent_key(seed))."""
    import stori_jax.suite

    seen = []

    def play(env, obs, seed, **kwargs):
        seen.append((env.seed, seed, env.plan.obs, env.num_envs))
        return {}

    monkeypatch.setattr(stori_jax.suite, "play", play)
    row = stori_jax.suite.run_preset("Breakout", "1", episodes=1, num_envs=2, max_steps=1,
                                     seed=5)
    assert seen == [(5, 5, "atari84", 2)]
    assert (row["game"], row["preset"]) == ("Breakout", "1")


class _SwitchingEnv:
    """Scripted infos: events, and concepts that switch, end with an episode, and restart."""

    num_envs, num_actions = 2, 4
    script = [  # (concept, done, events) per step
        ([0, 1], [False, False], [2, 0]),
        ([1, 1], [True, False], [0, 0]),   # env 0 switches, then its episode ends
        ([0, 1], [False, False], [0, 3]),  # env 0's new episode starts in concept 1 (0)
        ([0, 0], [False, True], [1, 1]),   # env 1 switches back
    ]

    def __init__(self):
        self.t = 0

    def step(self, actions):
        concept, done, events = (np.array(x) for x in self.script[self.t])
        self.t += 1
        info = dict(episode_return=np.where(done, 1.0, 0.0), event_fired=events,
                    action_corrupted=np.zeros((2, 1), bool), frames_played=np.full(2, 4),
                    obs_masked=np.zeros(2, bool),
                    concept=concept.astype(np.int32))
        return np.zeros((2, 1)), np.zeros(2), done, np.zeros(2, bool), info


def test_play_counts_every_event_and_no_switch_at_a_new_episode():
    """Events are summed over envs and steps; a concept switch is counted where an episode's
    concept changes, not where a new episode starts again in concept 1."""
    from stori_jax.suite import play

    stats = play(_SwitchingEnv(), np.zeros((2, 1)), 0, max_steps=4,
                 policy=lambda obs, key: np.zeros(2, np.int32))
    assert stats["events_fired"] == 7
    assert stats["concept_switches"] == 3  # env 1 at step 1 and 4, env 0 at step 2
    assert stats["agent_steps"] == 4 and stats["episodes"] == 2


def test_the_suite_takes_games_and_presets_in_any_case():
    from stori_jax.cli import selected_presets

    assert selected_presets(["breakout", "BOXING"], ["3.2a", "1"]) == [
        ("Breakout", "1"), ("Breakout", "3.2A"), ("Boxing", "1"), ("Boxing", "3.2A")]


def _replay(game, config, actions, **kw):
    """(screens, infos) of a fresh env of ``config`` (3.1 if None) stepped with ``actions``."""
    with stori_jax.make(game, config=config, num_envs=1, seed=0, obs="raw", num_workers=1,
                        autoreset=False, **kw) as env:
        obs, info = env.reset()
        screens, infos = [np.asarray(obs[0])], [info]
        for a in actions:
            obs, *_, info = env.step(np.array([a], np.int32))
            screens.append(np.asarray(obs[0]))
            infos.append(info)
    return screens, infos


def test_the_twin_plays_the_intended_actions_and_flags_are_the_presets():
    """twin_run: the 3.1 twin gets the intended actions (not the corrupted ones the preset
    executed), and each step's flags are what the preset's env reported."""
    from stori_jax.visual import twin_run

    config = stori_jax.Config(action_noise=stori_jax.ActionNoise(0.5),
                              observation=stori_jax.ObservationMask("crop", 1, prob=0.5))
    frames = twin_run("Breakout", config, 12, seed=0)
    intended = [f["action"] for f in frames[1:]]
    executed = [f["executed"][-1] for f in frames[1:]]
    assert intended != executed, "the run should corrupt some actions"
    twin, _ = _replay("Breakout", None, intended)
    preset, infos = _replay("Breakout", config, intended)
    for t, f in enumerate(frames):
        np.testing.assert_array_equal(f["twin"], twin[t], err_msg=f"twin, step {t}")
        np.testing.assert_array_equal(f["preset"], preset[t], err_msg=f"preset, step {t}")
        assert f["masked"] == bool(np.asarray(infos[t]["obs_masked"])[0]), t
        assert f["corrupted"] == bool(np.asarray(infos[t]["action_corrupted"]).any()), t
    assert {f["masked"] for f in frames} == {False, True}


def test_the_executed_actions_shown_are_those_of_the_frames_played(monkeypatch):
    """An episode cut at frame 6 (steps of 4 frames) ends 2 frames into its second step: the
    caption's executed actions are those 2 frames' (not NOOPs for frames never played)."""
    import functools

    from stori_jax.visual import twin_run

    monkeypatch.setattr(stori_jax, "make", functools.partial(stori_jax.make,
                                                             max_episode_frames=6))
    config = stori_jax.Config(action_noise=stori_jax.ActionNoise(0.5), granularity="frame")
    frames = twin_run("Breakout", config, 5, seed=0, with_twin=False)
    assert [len(f["executed"]) for f in frames[1:]] == [4, 2]


def test_a_contact_sheets_top_row_is_the_twin_and_its_bottom_row_the_preset(tmp_path):
    """Boxing 3.2A blacks out the scores and the clock: the first column's top screen is the
    3.1 twin's first observation, the bottom one the same screen with those parts filled."""
    path = tmp_path / "sheet.png"
    assert main(["show", "Boxing", "3.2A", "--steps", "3", "--out", str(path)]) == 0
    sheet = np.asarray(Image.open(path).convert("RGB"))
    x0, top = 6, 36 + 16  # see test_show_puts_the_mask_on_the_preset_side_only
    upper = sheet[top:top + 210, x0:x0 + 160]
    lower = sheet[top + 210 + 6 + 16:top + 2 * 210 + 6 + 16, x0:x0 + 160]
    (screen,), _ = _replay("Boxing", None, [])
    np.testing.assert_array_equal(upper, screen)
    hidden = (lower != screen).any(axis=-1)
    assert hidden.any() and len(np.unique(lower[hidden], axis=0)) == 1  # one fill colour


def _episodes(game, config, seed, num_envs, steps):
    """Every episode of ``num_envs`` envs of ``seed`` playing twin_run's random actions for
    ``steps`` agent steps (autoreset off: the step after an end resets): (env, start, length)."""
    rng = np.random.default_rng(seed)
    started, episodes = [0] * num_envs, []
    with stori_jax.make(game, config=config, num_envs=num_envs, seed=seed, obs="raw",
                        num_workers=1, autoreset=False) as env:
        env.reset()
        for t in range(1, steps + 1):
            _, _, terminated, truncated, _ = env.step(
                rng.integers(env.num_actions, size=num_envs).astype(np.int32))
            for i in np.flatnonzero(np.asarray(terminated | truncated)):
                episodes.append((int(i), started[i], t - started[i]))
                started[i] = t + 1
    return episodes


BLACKOUT = stori_jax.Config(observation=stori_jax.ObservationMask("blackout", 10, 1.0))
SUDDEN_BLACKOUT_AT_220 = stori_jax.Config(drift=stori_jax.ConceptDrift("sudden", 220, BLACKOUT))


def test_a_drift_picture_follows_the_first_episode_that_reaches_concept_2(monkeypatch):
    """A random policy's Breakout episode mostly ends before a 2.2 switch (T = 300): the picture
    follows the first episode of the seed's candidate envs that lasts past T (found here from
    the episodes' lengths alone), from its first screen, and shows concept 2 from step T + 1."""
    import stori_jax.visual as visual

    monkeypatch.setattr(visual, "DRIFT_CANDIDATES", 4)
    config, period, steps, seed = SUDDEN_BLACKOUT_AT_220, 220, 230, 1
    showcase = visual.drift_showcase("Breakout", config, steps, seed)
    # the earliest step at which an episode is in its step T + 1; the lowest env on a tie
    reached = sorted((start + period, i, start)
                     for i, start, length in _episodes("Breakout", config, seed, 4, 700)
                     if length > period)
    _, env_index, start = reached[0]
    assert start > 0, "the case should need a later episode than the first"
    assert showcase == visual.Showcase(
        env_index, start, 4, f"env {env_index}'s episode from agent step {start} (seed {seed}), "
                             "the first of 4 envs' episodes to reach concept 2")
    frames = visual.twin_run("Breakout", config, steps, seed, showcase=showcase)
    assert [f["step"] for f in frames] == list(range(steps + 1))
    (first_screen,), _ = _replay("Breakout", None, [])
    np.testing.assert_array_equal(frames[0]["preset"], first_screen)  # a new episode's first
    assert [f["concept"] for f in frames] == [int(f["step"] > period) for f in frames]
    for f in frames:  # concept 1 is the 3.1 twin; concept 2 a mask on the same game
        assert f["masked"] == bool(f["concept"])
        if not f["concept"]:
            np.testing.assert_array_equal(f["preset"], f["twin"], err_msg=f"step {f['step']}")


def test_a_drift_picture_that_cannot_show_concept_2_says_why(monkeypatch, tmp_path):
    import stori_jax.visual as visual

    config = SUDDEN_BLACKOUT_AT_220
    assert visual.drift_showcase("Breakout", config, 220) == visual.Showcase(
        note="concept 2 begins after agent step 220 of an episode: not shown")
    assert visual.drift_showcase("Breakout", stori_jax.Config(), 50) == visual.Showcase()
    # a T at or past an episode's 27000 steps (108000 frames at frame skip 4): no episode
    # reaches it, so no search (a T of 2**31 - 1 searched for 5 x (T + 100) steps) and the
    # sheet plays its usual 200 steps
    for period in (27000, 2**31 - 1):
        never = stori_jax.Config(drift=stori_jax.ConceptDrift("sudden", period, BLACKOUT))
        assert visual.drift_showcase("Breakout", never, period + 100) == visual.Showcase(
            note=f"concept 2 begins after agent step {period} of an episode, past the frame "
                 "cap's 27000 steps: never, not shown")
        assert visual.default_steps(never) == visual.SHEET_STEPS
    latest = stori_jax.Config(drift=stori_jax.ConceptDrift("sudden", 26999, BLACKOUT))
    assert visual.default_steps(latest) == 27000  # T + 100 cut to the episode's steps
    # gradual drift can switch from step T + 1 on: T = 26999 never does
    gradual = stori_jax.Config(drift=stori_jax.ConceptDrift("gradual", 26999, BLACKOUT))
    assert visual.default_steps(gradual) == visual.SHEET_STEPS
    assert "never, not shown" in visual.drift_showcase("Breakout", gradual, 27000).note
    monkeypatch.setattr(visual, "DRIFT_CANDIDATES", 1)
    monkeypatch.setattr(visual, "DRIFT_SEARCH", 1)
    # seed 0's env 0 plays a 200-odd-step first episode: none reaches step 221 within 230 steps
    assert max(length for _, _, length in _episodes("Breakout", config, 0, 1, 230)) <= 220
    assert visual.drift_showcase("Breakout", config, 230) == visual.Showcase(
        0, 0, 1, "no episode of 1 envs (seed 0) reached concept 2 within 230 steps in 230 "
                 "agent steps")
    # the note is a third line of the sheet's title: the screens move down 14 px
    path = visual.contact_sheet("Breakout", "mine", config, tmp_path / "sheet.png", steps=230)
    sheet = np.asarray(Image.open(path).convert("RGB"))
    assert sheet.shape[0] == 50 + 2 * (16 + 210 + 6)
    (first_screen,), _ = _replay("Breakout", None, [])
    np.testing.assert_array_equal(sheet[50 + 16:50 + 16 + 210, 6:166], first_screen)


def test_a_drift_picture_plays_long_enough_to_reach_concept_2(monkeypatch, tmp_path):
    """By default (a --steps given is played as given)."""
    import stori_jax.visual as visual

    played = []

    def twin_run(game, config, steps, seed, **kw):
        played.append((steps, kw["showcase"]))
        return [dict(step=0, preset=np.zeros((210, 160, 3), np.uint8),
                     twin=np.zeros((210, 160, 3), np.uint8), corrupted=False, event=0,
                     concept=0, masked=False, action=None, executed=None)]

    monkeypatch.setattr(visual, "twin_run", twin_run)
    monkeypatch.setattr(visual, "drift_showcase", lambda game, config, steps, seed, **kw: (
        visual.Showcase(note=f"{steps}")))
    gopher = stori_jax.preset("Gopher", "2.2")  # cyclic, T = 600
    short = stori_jax.Config(drift=stori_jax.ConceptDrift("cyclic", 50, stori_jax.preset(
        "Breakout", "3.2A")))
    for config, steps, expected in ((stori_jax.Config(), None, visual.SHEET_STEPS),
                                    (gopher, None, 600 + visual.AFTER_SWITCH), (gopher, 5, 5),
                                    (short, None, visual.SHEET_STEPS)):
        visual.contact_sheet("Gopher", "x", config, tmp_path / "x.png", steps=steps)
        assert played[-1] == (expected, visual.Showcase(note=f"{expected}"))
    assert visual.SHEET_STEPS == 200 and visual.AFTER_SWITCH == 100


def test_a_recordings_captions_and_note_are_wrapped_into_its_bar(monkeypatch, tmp_path):
    """A 2.2 note is 80-100 characters, a caption with a long config name and every flag as
    long, and a recording 320 px wide: both ran off its right edge."""
    import textwrap

    import stori_jax.visual as visual

    note = ("env 12's episode from agent step 1234 (seed 0), the first of 16 envs' episodes to "
            "reach concept 2")
    frame = dict(step=0, preset=np.zeros((210, 160, 3), np.uint8), twin=None, corrupted=False,
                 event=0, concept=0, masked=False, action=None, executed=None)
    busy = dict(frame, step=15, corrupted=True, event=2, concept=1, masked=True, action=3,
                executed=[3, 1, 1, 3])
    monkeypatch.setattr(visual, "drift_showcase", lambda *a, **k: visual.Showcase(note=note))
    monkeypatch.setattr(visual, "twin_run", lambda *a, **k: [frame, busy])
    name = "breakout_drift_to_noise_v2"
    path = visual.record_episode("Breakout", name, stori_jax.Config(), tmp_path / "a.gif")
    caption = textwrap.wrap(f"Breakout {name}  {visual._caption(busy)}", 52)
    assert len(caption) == 2 and len(textwrap.wrap(note, 52)) == 2
    with Image.open(path) as gif:
        assert gif.size == (320, 420 + 8 + 16 * (2 + 1 + 2))  # captions, action, note
        gif.seek(1)
        bar = np.asarray(gif.convert("RGB"))[:8 + 16 * 5]
    assert np.flatnonzero(bar.any(axis=(0, 2))).max() < 320 - 4  # nothing runs off the edge
    rows = np.flatnonzero(bar.any(axis=(1, 2)))
    assert rows.max() > 2 + 16 * 4  # the note's second line is drawn


def test_the_table_says_why_a_row_has_fewer_episodes_than_asked(tmp_path):
    """--episodes 1 --num-envs 2: env 0 plays the one episode; a row whose env 0 had not
    finished by --max-steps showed '-' and 0 episodes with no word why (env 1's finished
    episode does not stand in for it)."""
    from stori_jax.suite import short_rows_note

    rows = [dict(game="Breakout", preset="1", episodes=1),
            dict(game="Breakout", preset="2.2", episodes=0),
            dict(game="Boxing", preset="3.2A", episodes=2)]
    assert short_rows_note(rows[:1], 1, 2, 300) == ""
    assert short_rows_note(rows, 3, 2, 300) == (
        "\nFewer than 3 episodes in Breakout 1, Breakout 2.2, Boxing 3.2A: each run stopped at "
        "--max-steps 300 agent steps first. Each of the 2 envs plays a fixed share of the "
        "episodes (2, 1), so that short episodes are not favoured.\n")
    out = tmp_path / "suite"
    assert main(["suite", "--games", "Breakout", "--presets", "3.2A", "--episodes", "1",
                 "--num-envs", "2", "--max-steps", "5", "--out", str(out), "--quiet",
                 "--no-gallery"]) == 0
    assert "Fewer than 1 episode in Breakout 3.2A: each run stopped at --max-steps 5" in (
        out / "table.md").read_text()


def test_suite_no_gallery_and_num_envs_reach_the_run(tmp_path, capsys):
    """--no-gallery: no contact sheet and no gallery line in table.md; --num-envs: the envs
    stepped (recorded in results.json; blackout at p = 1 masks every env's every step)."""
    out = tmp_path / "suite"
    assert main(["suite", "--games", "Breakout", "--presets", "3.2A", "--episodes", "1",
                 "--num-envs", "2", "--max-steps", "10", "--out", str(out), "--quiet",
                 "--no-gallery"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["results.json", "table.md"]
    assert "Gallery" not in (out / "table.md").read_text()
    assert f"wrote {out}/table.md, {out}/results.json\n" in capsys.readouterr().out
    results = json.loads((out / "results.json").read_text())
    assert results["num_envs"] == 2
    row, = results["rows"]
    assert row["masked_obs"] == 2 * row["agent_steps"] > 0


def test_run_counts_masked_obs_over_every_envs_steps(capsys):
    """`run` printed the masked observations out of --steps, not of the --steps x --num-envs
    observations played (blackout at p = 1 masks them all)."""
    assert main(["run", "Breakout", "3.2A", "--steps", "3", "--num-envs", "2",
                 "--num-workers", "0", "--quiet"]) == 0
    assert "masked obs        : 6 of 6\n" in capsys.readouterr().out
