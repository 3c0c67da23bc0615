"""Name This Game: the diver, the oxygen boat and its pipe, the shark, the treasure, the
octopus, its tentacles (a bitmap of 10 rows in RAM 0..49) and the diver's shot."""

import jax.numpy as jnp

from stori_jax.objects.table import obj, table, where

# tentacle bitmap: (first RAM byte, first x, bits left to right) per group of 10 rows
TENTACLE_GROUPS = ((0, 16, (7, 6, 5, 4, 3, 2, 1, 0)), (10, 48, (0, 1, 2, 3, 4, 5, 6, 7)),
                   (20, 80, (4, 5, 6, 7)), (30, 96, (7, 6, 5, 4, 3, 2, 1, 0)),
                   (40, 128, (0, 1, 2, 3, 4, 5, 6, 7)))
TENTACLE_ROWS = 10


def _tentacle_cells():  # per slot: RAM address, bit, x, y
    cells = []
    for first, x0, bits in TENTACLE_GROUPS:
        for j in range(TENTACLE_ROWS):
            cells += [(first + j, b, x0 + 4 * k, 126 - 7 * j) for k, b in enumerate(bits)]
    return tuple(jnp.array(c) for c in zip(*cells))


def _shark_row(r):  # the first of RAM[59], RAM[58], ... that is non-zero; 7: none
    rows = r[:, 59 - jnp.arange(7)] != 0
    return where(rows.any(1), jnp.argmax(rows, axis=1), 7)


@obj("Player")
def player(r):  # drawn smaller while no shark is out
    hidden = _shark_row(r) == 7
    x = r[:, 99]
    return (where(hidden, x + 3, x - 1), where(hidden, 147, 139), where(hidden, 11, 16),
            where(hidden, 11, 13), True)


@obj("Oxygen_Boat")
def oxygen_boat(r):
    return r[:, 100] - 1, 9, 16, 14, True


@obj("Oxygen_Pipe")
def oxygen_pipe(r):
    return r[:, 100] + 6, 23, 1, 123, r[:, 117] != 0


@obj("Shark")
def shark(r):  # with no shark out, OCAtari puts it where the diver is drawn big
    row = _shark_row(r)
    none = row == 7
    return (where(none, r[:, 99] - 1, r[:, 60] - 1), where(none, 139, 35 + 14 * row), 16, 12,
            True)


@obj("Treasure")
def treasure(r):  # RAM[71] % 4: 3 full, 2 half, 1 little, 0 gone
    size = r[:, 71] % 4
    return (jnp.array([0, 78, 74, 72])[size], jnp.array([0, 167, 165, 163])[size],
            jnp.array([0, 4, 10, 16])[size], jnp.array([0, 2, 4, 6])[size], size != 0)


@obj("Octopus")
def octopus(r):
    return 20, 29, 120, 33, True


@obj("Tentacle", 360)
def tentacle(r):
    address, bit, x, y = _tentacle_cells()
    return x, y, 4, 6, (r[:, address] >> bit) & 1 == 1


@obj("Shot")
def shot(r):
    y = r[:, 50]
    return r[:, 51] - 2, y + 30 + (y >> 5) + (y >> 3), 1, 2, y != 0


GAME = table("name_this_game", player, oxygen_boat, oxygen_pipe, shark, treasure, octopus,
             tentacle, shot,
             notes="Treasure: OCAtari shows it again, full, the frame after it is gone; here it "
                   "is present exactly while RAM[71] % 4 != 0.")
