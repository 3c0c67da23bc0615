"""James Bond 007: the car, its shot, the helicopter or ice (RAM[49]), the hornet, the enemy
shot, and the eruption, diver or fire hole of the stage."""

from stori_jax.objects.table import obj, table, where


@obj("Player")
def player(r):
    return r[:, 27] - 1, 50 + r[:, 25], 8, 4, True


@obj("Player_Shot")
def player_shot(r):
    return r[:, 38] - 11, 55 + r[:, 31], 1, 4, r[:, 31] != 128


@obj("Helicopter")
def helicopter(r):
    return r[:, 61] - 1, 57, 8, 6, r[:, 49] == 6


@obj("Ice")
def ice(r):
    return r[:, 61] - 1, 57, 8, 12, (r[:, 49] != 255) & (r[:, 49] != 6)


@obj("Hornet")
def hornet(r):
    return r[:, 59] - 2, 75, 8, 14, r[:, 50] != 255


@obj("Enemy_Shot")
def enemy_shot(r):
    return r[:, 39] - 11, 55 + r[:, 30], 1, 4, r[:, 30] != 128


def _eruption(r):
    return (r[:, 51] == 54) & (r[:, 108] == 251)


def _diver(r):
    return ~_eruption(r) & (r[:, 51] == 48)


@obj("Eruption")
def eruption(r):
    small = r[:, 109] == 86
    return (r[:, 60] + where(small, 4, 0), 125, where(small, 20, 32), where(small, 7, 15),
            _eruption(r))


@obj("Diver")
def diver(r):
    return r[:, 60] - 1, 131, 7, 20, _diver(r)


@obj("Fire_Hole")
def fire_hole(r):
    return r[:, 43], 122, 16, 48, ~_eruption(r) & ~_diver(r) & (r[:, 108] == 250)


GAME = table("jamesbond", player, player_shot, helicopter, ice, hornet, enemy_shot, eruption,
             diver, fire_hole,
             notes="OCAtari keeps the helicopter when the ice replaces it, and an eruption or "
                   "diver once gone; here each is present exactly while its RAM says so.")
