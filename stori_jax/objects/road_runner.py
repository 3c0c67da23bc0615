"""Road Runner: the road runner (RAM[80], RAM[3]; its row's offset from the level RAM[22]),
the coyote (RAM[81], RAM[5]) and the mine on the road (RAM[89], its lane RAM[55])."""

from stori_jax.objects.table import obj, table, where


@obj("Player")
def player(r):
    level = r[:, 22]
    y = r[:, 3] + where(level == 1, 102, where(level == 3, 85, 95))
    return r[:, 80], y, 8, where(r[:, 41] == 6, 24, 32), r[:, 80] < 150


@obj("Enemy")
def enemy(r):
    y = r[:, 5] + where(r[:, 22] == 1, -30, 98)
    return r[:, 81], y, 7, 29, r[:, 81] <= 143


@obj("AcmeMine", 4)
def acme_mine(r):
    x, lane, kind = r[:, 89:90], r[:, 55:56], r[:, 39:40]
    here = (8 < x) & (x <= 150) & (kind != 40) & (kind != 24) & (kind != 31) & (lane <= 1)
    return x - 4, where(lane == 0, 147, 131), 4, 3, here


GAME = table("road_runner", player, enemy, acme_mine,
             notes="The seeds (OCAtari never reports them: it names a class it has not), the "
                   "mines among them (RAM[36..39] == 47), trucks, road cracks, the turret and "
                   "its balls are left out (none on the recorded trajectory).  OCAtari misses the "
                   "coyote until it first leaves the road (RAM[81] > 143): it starts as no "
                   "object; here it is there from the first frame, as on the screen.")
