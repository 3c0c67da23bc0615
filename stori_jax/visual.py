"""Pictures of what a preset does: contact sheets (``show``) and episode recordings (``record``).

Both run a preset beside its 3.1 twin (same seed, same intended actions: what differs is what the
preset does) with raw observations, and draw with Pillow.
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import NamedTuple

import numpy as np

from stori_jax.config import Config

SHEET_STEPS = 200  # agent steps a contact sheet plays at most by default
SCALE = 2  # a recording's screens are drawn at 2x (320x420); contact sheets at 1x


def _pil():
    try:
        from PIL import Image, ImageDraw
    except ImportError as e:  # Pillow comes with matplotlib
        raise ValueError("pictures need Pillow: pip install pillow") from e
    return Image, ImageDraw


def _save_whole(path: Path, save) -> Path:
    """``save(tmp)`` beside ``path``, then renamed to it: an interrupted write (Ctrl-C while a
    long GIF is encoded) leaves no half-written file and an earlier one as it was."""
    import os
    import secrets

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # a name no other writer picks, with the same extension (from which Pillow takes the
    # format); created by ``save`` as any file is (permissions after the umask: mkstemp's
    # would be 0600)
    tmp = path.with_name(f".{path.stem}.partial.{os.getpid()}.{secrets.token_hex(6)}"
                         f"{path.suffix}")
    try:
        save(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return path


class Showcase(NamedTuple):
    """Which episode a picture follows: env ``env_index`` of the seed (random actions drawn
    for a batch of ``action_batch`` envs each step), from the episode whose first observation
    agent step ``start`` returned (0: the reset's); ``note``: a line saying so on the picture."""

    env_index: int = 0
    start: int = 0
    action_batch: int = 1
    note: str = ""


def random_actions(rng: np.random.Generator, num_actions: int, batch: int) -> np.ndarray:
    """A picture's random actions of one step, drawn for ``batch`` envs (the search for a 2.2
    picture's episode and the run that draws it must draw the same)."""
    return rng.integers(num_actions, size=batch).astype(np.int32)


def twin_run(game: str, config: Config, steps: int, seed: int = 0, *, with_twin: bool = True,
             progress: str | None = None, showcase: Showcase = Showcase()):
    """Run ``config`` and its 3.1 twin side by side on the same intended actions (the same
    game unless the preset corrupts actions); ``with_twin=False`` runs the preset alone.
    ``progress``: a progress bar's label (None: no bar).

    Both play random actions, and the pictures follow ``showcase``'s episode for ``steps`` steps
    or until it ends (a batch of ``env_index + 1`` envs: env i plays as in any larger batch).

    Returns a list of per-step dicts: 'twin' (None without one) and 'preset' screens
    (210, 160, 3), the intended and executed actions, and the step's perturbation flags, 'step'
    counting the episode's agent steps.  Where the twin's episode ends first (a preset that
    changes the game: type 1, 2.1), its last screen stays from then on and 'twin_ended' says
    at which step (None while it plays): the next step would start a new episode."""
    from tqdm import tqdm

    import stori_jax

    rng = np.random.default_rng(seed)
    k, start = showcase.env_index, showcase.start
    num_envs = k + 1
    # no autoreset: the step that ends the episode shows its last screen, not the next one's
    # first (that comes with the next step, which resets the env instead of stepping it)
    kw = dict(num_envs=num_envs, seed=seed, obs="raw", num_workers=1, autoreset=False)
    env = stori_jax.make(game, config=config, **kw)
    twin = stori_jax.make(game, **kw) if with_twin else None

    def screen(obs):  # env k's screen, if there is one
        return None if obs is None else np.asarray(obs[k])

    frames, twin_ended = [], None
    try:
        obs, info = env.reset()
        twin_obs = twin.reset()[0] if twin is not None else None
        for t in tqdm(range(start + steps + 1), desc=progress, unit="step",
                      disable=progress is None):
            if t:
                actions = random_actions(rng, env.num_actions, showcase.action_batch)[:num_envs]
                obs, reward, terminated, truncated, info = env.step(actions)
                # the twin gets the intended actions: without type-1 noise it plays the same game
                if twin is not None and twin_ended is None:
                    twin_obs, _, twin_term, twin_trunc = twin.step(actions)[:4]
                    if t > start and bool(twin_term[k] | twin_trunc[k]):
                        twin_ended = t - start  # its screen stays: the next is a new episode
            if t < start:
                continue
            first = t == start  # the episode's first observation: no action made it
            frames.append(dict(
                step=t - start, preset=screen(obs), twin=screen(twin_obs), twin_ended=twin_ended,
                corrupted=not first and bool(np.asarray(info["action_corrupted"])[k].any()),
                event=0 if first else int(np.asarray(info["event_fired"])[k]),
                concept=0 if first else int(np.asarray(info["concept"])[k]),
                masked=bool(np.asarray(info["obs_masked"])[k]),
                action=None if first else int(actions[k]),
                # the frames played only (an episode's last step may end before its last)
                executed=None if first else np.asarray(info["executed_action"])[k].reshape(
                    -1)[:int(np.asarray(info["frames_played"])[k])].tolist()))
            if not first and bool(terminated[k] | truncated[k]):
                break
    finally:
        env.close()
        if twin is not None:
            twin.close()
    return frames


DRIFT_CANDIDATES = 16  # envs a 2.2 picture looks through for an episode that reaches concept 2
DRIFT_SEARCH = 5  # ... for at most this many times the picture's steps
AFTER_SWITCH = 100  # agent steps a 2.2 picture plays past T by default


def episode_step_cap() -> int:
    """Agent steps an episode of a picture's envs (make's frame cap and frame skip) lasts at
    most: concept 2 of a T at or past it never comes."""
    from stori_jax.builder import FRAME_SKIP, MAX_EPISODE_FRAMES

    return -(-MAX_EPISODE_FRAMES // FRAME_SKIP)


def first_concept2_step(drift) -> int:
    """The 0-indexed episode step from which concept 2 can come, as the schedule says: T
    (sudden, cyclic), or T + 1 where P(concept 2) is still 0 at T (gradual)."""
    from stori_jax.functional import concept2_probability

    at_t = float(concept2_probability(drift.period, drift.schedule, drift.period))
    return drift.period if at_t > 0 else drift.period + 1


def default_steps(config: Config) -> int:
    """A contact sheet's steps by default: SHEET_STEPS, or for a 2.2 config at least enough to
    show concept 2 (T + AFTER_SWITCH, at most an episode's steps; SHEET_STEPS where concept 2
    comes after the episode's frame cap)."""
    if config.drift is None or first_concept2_step(config.drift) >= episode_step_cap():
        return SHEET_STEPS
    return min(max(SHEET_STEPS, config.drift.period + AFTER_SWITCH), episode_step_cap())


def drift_showcase(game: str, config: Config, steps: int, seed: int = 0, *,
                   progress: str | None = None) -> Showcase:
    """Which episode a picture of ``config`` follows (for :func:`twin_run`).

    A 2.2 preset switches concept at agent step T of an episode, and a random policy's episode
    may end before it (Breakout's mostly do, at ~180 steps for T = 300): a picture of env 0's
    first episode would show concept 1 only.  So a 2.2 picture looks through the episodes of
    DRIFT_CANDIDATES envs of the seed (playing the random actions ``twin_run`` draws) for the
    first that reaches concept 2 within ``steps`` steps, for DRIFT_SEARCH x ``steps`` agent
    steps at most, and follows it (env 0's first episode if none does; the note says so).
    ``progress``: the search's progress bar label (None: no bar)."""
    if config.drift is None:
        return Showcase()
    period = config.drift.period
    if first_concept2_step(config.drift) >= episode_step_cap():
        return Showcase(note=f"concept 2 begins after agent step {period} of an episode, past "
                             f"the frame cap's {episode_step_cap()} steps: never, not shown")
    if steps <= period:  # concept 2 begins at the episode's agent step T + 1 at the earliest
        return Showcase(note=f"concept 2 begins after agent step {period} of an episode: "
                             "not shown")
    from tqdm import tqdm

    import stori_jax

    rng = np.random.default_rng(seed)
    n, budget = DRIFT_CANDIDATES, DRIFT_SEARCH * steps
    with stori_jax.make(game, config=config, num_envs=n, seed=seed, obs="raw", num_workers=1,
                        autoreset=False) as env, \
            tqdm(total=budget, desc=progress, unit="step", disable=progress is None) as bar:
        env.reset()
        started = np.zeros(n, np.int64)  # the agent step that began each env's episode
        for t in range(1, budget + 1):
            actions = random_actions(rng, env.num_actions, n)
            _, _, _, _, info = env.step(actions)
            bar.update()
            new_episode = np.asarray(info["reset_step"])  # the step after an end resets
            started[new_episode] = t
            reached = ~new_episode & (np.asarray(info["concept"]) > 0) & (t - started <= steps)
            if reached.any():
                k = int(np.argmax(reached))  # the lowest such env
                start = int(started[k])
                note = "" if k == 0 and start == 0 else (
                    f"env {k}'s episode from agent step {start} (seed {seed}), the first of "
                    f"{n} envs' episodes to reach concept 2")
                return Showcase(k, start, n, note)
    return Showcase(action_batch=n, note=f"no episode of {n} envs (seed {seed}) reached "
                                         f"concept 2 within {steps} steps in {budget} agent steps")


def _search_label(game: str, name: str, progress: bool) -> str | None:
    return f"{game} {name}: finding an episode that reaches concept 2" if progress else None


def _moments(frames, count: int):
    """Steps worth showing: evenly spread, plus the first event, concept switch and mask."""
    picks = set(np.linspace(0, len(frames) - 1, count).astype(int).tolist())
    for key in ("event", "concept", "masked"):
        hits = [i for i, f in enumerate(frames) if f[key]]
        if hits:
            picks.add(hits[0])
    return sorted(picks)[: count + 3]


def _caption(f) -> str:
    bits = [f"step {f['step']}"]
    if f["corrupted"]:
        bits.append("action corrupted")
    if f["event"]:
        bits.append(f"event x{f['event']}")
    if f["concept"]:
        bits.append("concept 2")
    if f["masked"]:
        bits.append("masked")
    return ", ".join(bits)


def contact_sheet(game: str, name: str, config: Config, path: Path, *,
                  steps: int | None = None, moments: int = 4, seed: int = 0,
                  progress: bool = False) -> Path:
    """A PNG: columns are moments of one run, the top row the 3.1 twin, the bottom the preset.
    ``steps``: agent steps to play at most (default 200, a 2.2 preset's T + 100 if longer, at
    most an episode's 27000 steps, :func:`default_steps`); a 2.2 preset follows an env whose episode reaches concept 2 (see :func:`drift_showcase`)."""
    Image, ImageDraw = _pil()
    steps = default_steps(config) if steps is None else steps
    showcase = drift_showcase(game, config, steps, seed, progress=_search_label(game, name,
                                                                                progress))
    note = showcase.note
    frames = twin_run(game, config, steps, seed, progress=f"{game} {name}" if progress else None,
                      showcase=showcase)
    columns = [frames[i] for i in _moments(frames, moments)]
    w, h, pad, top, title = 160, 210, 6, 16, 50 if note else 36
    sheet = Image.new("RGB", (len(columns) * (w + pad) + pad, title + 2 * (h + top + pad)),
                      (24, 24, 24))
    draw = ImageDraw.Draw(sheet)
    draw.text((pad, 4), f"{game} {name}   (top: 3.1 twin, bottom: {name})", fill=(230, 230, 230))
    draw.text((pad, 18), config.describe(), fill=(180, 180, 180))
    if note:
        draw.text((pad, 32), note, fill=(180, 180, 180))
    for c, f in enumerate(columns):
        x = pad + c * (w + pad)
        for r, key in enumerate(("twin", "preset")):
            y = title + r * (h + top + pad)
            draw.text((x, y + 2), _caption(f) if r else _twin_caption(f), fill=(230, 230, 120))
            sheet.paste(Image.fromarray(f[key]), (x, y + top))
    return _save_whole(path, sheet.save)


def _twin_caption(frame: dict) -> str:
    """The top row's caption: the step, and where the twin's episode ended before it (its last
    screen shown)."""
    ended = frame.get("twin_ended")
    if ended is None or ended == frame["step"]:
        return f"step {frame['step']}"
    return f"step {frame['step']} (twin's end: {ended})"


def record_episode(game: str, name: str, config: Config, path: Path, *, max_steps: int = 1000,
                   seed: int = 0, progress: bool = False) -> Path:
    """An animated GIF of one episode of the preset, with a line per step of what happened (a
    2.2 preset: of an env whose episode reaches concept 2, see :func:`drift_showcase`)."""
    Image, ImageDraw = _pil()
    showcase = drift_showcase(game, config, max_steps, seed, progress=_search_label(game, name,
                                                                                    progress))
    note = showcase.note
    frames = twin_run(game, config, max_steps, seed, with_twin=False,
                      progress=f"{game} {name}" if progress else None, showcase=showcase)
    # lines of at most 52 characters (about 6 px each) on a 320 px frame; one bar height for all
    captions = [textwrap.wrap(f"{game} {name}  {_caption(f)}", 52) for f in frames]
    note_lines = textwrap.wrap(note, 52)
    caption_rows = max(len(c) for c in captions)
    w, h, bar = 160 * SCALE, 210 * SCALE, 8 + 16 * (caption_rows + 1 + len(note_lines))
    images = []
    for f, caption in zip(frames, captions):
        img = Image.new("RGB", (w, h + bar), (0, 0, 0))
        img.paste(Image.fromarray(f["preset"]).resize((w, h), Image.NEAREST), (0, bar))
        draw = ImageDraw.Draw(img)
        for i, line in enumerate(caption):
            draw.text((4, 2 + 16 * i), line, fill=(255, 255, 120))
        y = 2 + 16 * caption_rows
        if f["action"] is not None:
            draw.text((4, y), f"intended {f['action']}  executed {f['executed']}",
                      fill=(200, 200, 200))
        for i, line in enumerate(note_lines):
            draw.text((4, y + 16 * (i + 1)), line, fill=(200, 200, 200))
        images.append(img)
    return _save_whole(path, lambda tmp: images[0].save(
        tmp, save_all=True, append_images=images[1:], duration=50, loop=0,
        optimize=False))


# eight games with a class hidden (ObservationMask kind "objects"), for objects_gallery
GALLERY_HIDDEN = (("Breakout", ("Ball",)), ("Pong", ("Ball",)), ("Freeway", ("Car",)),
                  ("Boxing", ("Enemy",)), ("Seaquest", ("Player",)), ("Tennis", ("Ball",)),
                  ("Bowling", ("Ball",)), ("Asterix", ("Enemy",)))


def objects_gallery(path: Path, *, steps: int = 120, seed: int = 0,
                    hidden=GALLERY_HIDDEN) -> Path:
    """A PNG: one column per game, the 3.1 screen on top and below it the same screen with
    ``hidden``'s classes blacked out (ObservationMask('objects', 1, 1.0, classes)), after
    ``steps`` random steps."""
    from stori_jax.config import ObservationMask

    Image, ImageDraw = _pil()
    w, h, pad, top, title = 160, 210, 6, 16, 22
    sheet = Image.new("RGB", (len(hidden) * (w + pad) + pad, title + 2 * (h + top + pad)),
                      (24, 24, 24))
    draw = ImageDraw.Draw(sheet)
    draw.text((pad, 4), "top: 3.1; bottom: the named object class hidden (kind 'objects')",
              fill=(230, 230, 230))
    for c, (game, classes) in enumerate(hidden):
        config = Config(observation=ObservationMask("objects", 1, 1.0, classes=classes))
        frame = twin_run(game, config, steps, seed)[-1]
        x = pad + c * (w + pad)
        for r, key in enumerate(("twin", "preset")):
            y = title + r * (h + top + pad)
            draw.text((x, y + 2), game if r == 0 else "hidden: " + "+".join(classes),
                      fill=(230, 230, 120))
            sheet.paste(Image.fromarray(frame[key]), (x, y + top))
    return _save_whole(path, sheet.save)
