"""stori_jax.objects against OCAtari 2.2.1's own RAM-mode objects, frame by frame.

The fixtures (tests/fixtures/objects/<rom_id>.npz) are RAM trajectories of ale-py with
OCAtari's objects for each frame, recorded by tests/fixtures/objects/record_ocatari.py (its
docstring: how, and the layout).  Per game, one jitted call over the whole trajectory must give
exactly OCAtari's boxes, slot for slot (present objects first, in OCAtari's list order).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from stori_jax import objects as O

FIXTURES = Path(__file__).parent / "fixtures" / "objects"
GAMES = sorted(O.GAMES)


def load(rom_id):
    with np.load(FIXTURES / f"{rom_id}.npz") as f:
        data = {k: f[k] for k in f.files}
    classes = [str(c) for c in data["classes"]]
    expected = {c: O.Boxes(*(data[f"{c}/{k}"].astype(np.int32) for k in "xywh"),
                           data[f"{c}/present"]) for c in classes}
    return data["ram"], expected


def first_difference(got, want):
    for field in O.Boxes._fields:
        g, w = np.asarray(getattr(got, field)), getattr(want, field)
        bad = np.argwhere(g != w)
        if bad.size:
            t, k = bad[0]
            return (f"{field} differs at frame {t}, slot {k} ({len(bad)} values): "
                    f"got {g[t, k]}, OCAtari {w[t, k]}; frame {t}: got "
                    f"{[tuple(int(getattr(got, f)[t, k]) for f in O.Boxes._fields)]}")
    return None


@pytest.mark.parametrize("rom_id", GAMES)
def test_objects_equal_ocatari(rom_id):
    ram, expected = load(rom_id)
    got = O.objects_of(rom_id, ram)
    assert list(O.classes_of(rom_id)) == list(expected), "the classes are OCAtari's, in its order"
    for name, want in expected.items():
        g = got[name]
        assert g.x.shape == want.x.shape, (name, g.x.shape, want.x.shape)
        problem = first_difference(g, want)
        assert problem is None, f"{rom_id} {name}: {problem}"
