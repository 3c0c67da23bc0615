"""Regenerate every picture of the docs with the project's own drawing code (`stori-jax show`).

    .venv/bin/python docs/make_pictures.py            # presets and every mode (about 8 minutes)
    .venv/bin/python docs/make_pictures.py --presets  # the 24 preset pictures only
    .venv/bin/python docs/make_pictures.py --objects  # the hidden-objects sheet, the coverage

Writes docs/img/<Game>-<preset>.png and docs/img/modes/<Game>-<kind>-<mode>.png, and
docs/modes.md, the page that lists every mode of every game with its picture.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tqdm import tqdm

import stori_jax
from stori_jax import Config, ObservationMask, RandomEvent
from stori_jax.functional.masks import CROP_REGIONS, TORCH_MODE
from stori_jax.visual import contact_sheet

DOCS = Path(__file__).resolve().parent
EVENT_PROB = 0.5  # high enough that an event shows within a short run


def mode_configs():
    """(game, kind, mode, description, config) for every mode of every game."""
    for game in stori_jax.STORI_GAMES:
        spec = stori_jax.get_game(game)
        for mode in list(CROP_REGIONS) + [TORCH_MODE]:
            yield game, "crop", mode, ("torch" if mode == TORCH_MODE else
                                       "left right top bottom".split()[mode - 1] + " half"), \
                Config(observation=ObservationMask("crop", mode, 1.0))
        for mode, entry in spec.blackout_modes.items():
            yield game, "blackout", mode, entry.name, \
                Config(observation=ObservationMask("blackout", mode, 1.0))
        for mode, entry in spec.ram_obs_modes.items():
            yield game, "ram", mode, entry.name, Config(observation=ObservationMask("ram", mode, 1.0))
        for mode, entry in spec.event_modes.items():
            yield game, "event", mode, entry.name, Config(event=RandomEvent(mode, EVENT_PROB))


COVERAGE = "## Coverage\n"


def write_objects_docs() -> None:
    """docs/img/objects-hidden.png and the coverage table at the end of docs/objects.md."""
    from stori_jax.objects import listing, object_table
    from stori_jax.visual import objects_gallery

    objects_gallery(DOCS / "img" / "objects-hidden.png")
    games = listing()
    lines = [COVERAGE, f"{len(games)} games (`stori-jax list --objects`); slots in brackets.", "",
             "| game | classes | notes |", "|---|---|---|"]
    for game, classes in games.items():
        notes = " ".join(object_table(game).notes.split()) or "-"
        lines.append(f"| {game} | " + ", ".join(f"{c} ({n})" for c, n in classes.items())
                     + f" | {notes} |")
    page = DOCS / "objects.md"
    page.write_text(page.read_text().split(COVERAGE)[0] + "\n".join(lines) + "\n")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--presets", action="store_true", help="only the preset pictures")
    parser.add_argument("--objects", action="store_true",
                        help="only the hidden-objects sheet and docs/objects.md's coverage")
    args = parser.parse_args(argv)
    if args.objects:
        return write_objects_docs()
    img = DOCS / "img"
    for game, name in tqdm(stori_jax.list_presets(), desc="presets"):
        contact_sheet(game, name, stori_jax.preset(game, name), img / f"{game}-{name}.png",
                      steps=700)
    if args.presets:
        return
    lines = ["# Every mode of every game", "",
             "Made by `docs/make_pictures.py` with `stori_jax.visual.contact_sheet` (what "
             "`stori-jax show` draws): top row the default game, bottom row the mode, same seed "
             f"and actions. Masks at p = 1; events at p = {EVENT_PROB} (most events change the "
             "RAM, not the picture: the caption counts the firings). A RAM mode leaves the game "
             "untouched and shows the next frame under NOOP of the modified RAM, so its picture "
             "also differs from the true frame where nothing is hidden.", ""]
    current = None
    for game, kind, mode, description, config in tqdm(list(mode_configs()), desc="modes"):
        if game != current:
            lines += ["", f"## {game}", "", "| kind | mode | what it does | picture |",
                      "|---|---|---|---|"]
            current = game
        path = img / "modes" / f"{game}-{kind}-{mode}.png"
        contact_sheet(game, f"{kind} {mode}", config, path, steps=150, moments=2)
        lines.append(f"| {kind} | {mode} | {description} | ![]({path.relative_to(DOCS)}) |")
    (DOCS / "modes.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
