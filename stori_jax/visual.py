"""Pictures of what a preset does: contact sheets (``show``) and episode recordings (``record``).

Both run a preset beside its 3.1 twin (same seed, same intended actions: what differs is what the
preset does) with raw observations, and draw with Pillow.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from stori_jax.config import Config

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
    import tempfile

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # the same extension, from which Pillow takes the format
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.partial.",
                               suffix=path.suffix)
    os.close(fd)
    try:
        save(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return path


def twin_run(game: str, config: Config, steps: int, seed: int = 0, *, with_twin: bool = True,
             progress: str | None = None):
    """Run ``config`` and its 3.1 twin side by side on the same intended actions (the same
    game unless the preset corrupts actions); ``with_twin=False`` runs the preset alone.
    ``progress``: a progress bar's label (None: no bar).

    Returns a list of per-step dicts: 'twin' (None without one) and 'preset' screens
    (210, 160, 3), the intended and executed actions, and the step's perturbation flags."""
    from tqdm import tqdm

    import stori_jax

    rng = np.random.default_rng(seed)
    # no autoreset: the step that ends the episode shows its last screen, not the next one's first
    kw = dict(num_envs=1, seed=seed, obs="raw", num_workers=1, autoreset=False)
    env = stori_jax.make(game, config=config, **kw)
    twin = stori_jax.make(game, **kw) if with_twin else None

    def screen(obs):  # env 0's screen of a batch of one, if there is one
        return None if obs is None else np.asarray(obs[0])

    frames = []
    try:
        obs, info = env.reset()
        twin_obs = twin.reset()[0] if twin is not None else None
        frames.append(dict(step=0, preset=screen(obs), twin=screen(twin_obs),
                           corrupted=False, event=0, concept=0,
                           masked=bool(np.asarray(info["obs_masked"])[0]), action=None,
                           executed=None))
        for t in tqdm(range(1, steps + 1), desc=progress, unit="step", disable=progress is None):
            action = np.array([rng.integers(env.num_actions)], np.int32)
            obs, reward, terminated, truncated, info = env.step(action)
            executed = np.asarray(info["executed_action"]).reshape(1, -1)
            # the twin gets the intended action: without type-1 noise it plays the same game
            twin_obs = twin.step(action)[0] if twin is not None else None
            frames.append(dict(
                step=t, preset=screen(obs), twin=screen(twin_obs),
                corrupted=bool(np.asarray(info["action_corrupted"]).any()),
                event=int(np.asarray(info["event_fired"])[0]),
                concept=int(np.asarray(info["concept"])[0]),
                masked=bool(np.asarray(info["obs_masked"])[0]), action=int(action[0]),
                executed=executed[0].tolist()))
            if bool(terminated[0] | truncated[0]):
                break
    finally:
        env.close()
        if twin is not None:
            twin.close()
    return frames


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


def contact_sheet(game: str, name: str, config: Config, path: Path, *, steps: int = 200,
                  moments: int = 4, seed: int = 0, progress: bool = False) -> Path:
    """A PNG: columns are moments of one run, the top row the 3.1 twin, the bottom the preset."""
    Image, ImageDraw = _pil()
    frames = twin_run(game, config, steps, seed, progress=f"{game} {name}" if progress else None)
    columns = [frames[i] for i in _moments(frames, moments)]
    w, h, pad, top, title = 160, 210, 6, 16, 36
    sheet = Image.new("RGB", (len(columns) * (w + pad) + pad, title + 2 * (h + top + pad)),
                      (24, 24, 24))
    draw = ImageDraw.Draw(sheet)
    draw.text((pad, 4), f"{game} {name}   (top: 3.1 twin, bottom: {name})", fill=(230, 230, 230))
    draw.text((pad, 18), config.describe(), fill=(180, 180, 180))
    for c, f in enumerate(columns):
        x = pad + c * (w + pad)
        for r, key in enumerate(("twin", "preset")):
            y = title + r * (h + top + pad)
            draw.text((x, y + 2), _caption(f) if r else f"step {f['step']}",
                      fill=(230, 230, 120))
            sheet.paste(Image.fromarray(f[key]), (x, y + top))
    return _save_whole(path, sheet.save)


def record_episode(game: str, name: str, config: Config, path: Path, *, max_steps: int = 1000,
                   seed: int = 0, progress: bool = False) -> Path:
    """An animated GIF of one episode of the preset, with a line per step of what happened."""
    Image, ImageDraw = _pil()
    frames = twin_run(game, config, max_steps, seed, with_twin=False,
                      progress=f"{game} {name}" if progress else None)
    w, h, bar = 160 * SCALE, 210 * SCALE, 40
    images = []
    for f in frames:
        img = Image.new("RGB", (w, h + bar), (0, 0, 0))
        img.paste(Image.fromarray(f["preset"]).resize((w, h), Image.NEAREST), (0, bar))
        draw = ImageDraw.Draw(img)
        draw.text((4, 2), f"{game} {name}  {_caption(f)}", fill=(255, 255, 120))
        if f["action"] is not None:
            draw.text((4, 20), f"intended {f['action']}  executed {f['executed']}",
                      fill=(200, 200, 200))
        images.append(img)
    return _save_whole(path, lambda tmp: images[0].save(
        tmp, save_all=True, append_images=images[1:], duration=50, loop=0,
        optimize=False))
