"""Bank Heist: the getaway car, the banks and police cars (three slots shared by both, told
apart by their kind byte) and the dynamite."""

from stori_jax.objects.table import at, obj, table

SLOT_Y, SLOT_KIND, SLOT_X = range(9, 12), range(24, 27), range(29, 32)
BANK, POLICE = 253, 254


def _slots(r, kind):
    y = at(r, SLOT_Y)
    return at(r, SLOT_X), y + 37, 8, 7, (y != 0) & (at(r, SLOT_KIND) == kind)


@obj("Player")
def player(r):
    return r[:, 28], r[:, 8] + 37, 8, 7, True


@obj("Bank", 3)
def bank(r):
    return _slots(r, BANK)


@obj("Police", 3)
def police(r):
    return _slots(r, POLICE)


@obj("Dynamite")
def dynamite(r):
    return r[:, 32] - 1, r[:, 12] + 37, 8, 2, r[:, 12] != 0


GAME = table("bank_heist", player, bank, police, dynamite)
