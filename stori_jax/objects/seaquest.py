"""Seaquest: the submarine, the sharks and enemy submarines (four lanes of three, bottom lane
first), the divers and enemy missiles (one per lane, top lane first), the surface submarine, the
player's missile, the oxygen bar and the collected divers."""

import jax.numpy as jnp

from stori_jax.objects.table import at, obj, table

LANES, PER_LANE = 4, 3


def _submarine_lane(r):  # (B, 4) lane i (bottom first) holds submarines, not sharks
    kind = at(r, range(89, 93)) % 8
    return (3 < kind) & (kind < 7)


def _enemies(r, submarines):
    lane = jnp.repeat(jnp.arange(LANES), PER_LANE)
    slot = jnp.tile(jnp.arange(PER_LANE), LANES)
    here = (r[:, 36 + lane] >> (2 - slot)) & 1 == 1
    x = (r[:, 30 + lane] + 16 * slot) % 256
    y = 141 - 24 * lane
    sub = _submarine_lane(r)[:, lane]
    if submarines:
        return x, y, 8, 11, here & (x <= 165) & sub
    return x, y + r[:, 93:94] - 4, 8, 7, here & (x <= 165) & ~sub


@obj("Player")
def player(r):
    t = r[:, 105]
    return r[:, 70], r[:, 97] + 33, 16, 11, ~((0 < t) & (t < 15))


@obj("Shark", 12)
def shark(r):
    return _enemies(r, False)


@obj("Submarine", 12)
def submarine(r):
    return _enemies(r, True)


def _lane_items(r):  # slot i: lane 3 - i (top first), x RAM[74 - i]
    x = at(r, range(74, 70, -1))
    shown = (0 < x) & (x < 160)
    return x, shown, _submarine_lane(r)[:, ::-1], 3 - jnp.arange(LANES)


@obj("Diver", 4)
def diver(r):
    x, shown, sub, lane = _lane_items(r)
    return x, 141 - 24 * lane, 8, 11, shown & ~sub


@obj("EnemyMissile", 4)
def enemy_missile(r):
    x, shown, sub, lane = _lane_items(r)
    return x + 3, 145 - 24 * lane, 6, 4, shown & sub


@obj("SurfaceSubmarine")
def surface_submarine(r):
    x = r[:, 118]
    return x, 45, 8, 11, (r[:, 60] >= 2) & (x < 160)


@obj("PlayerMissile")
def player_missile(r):
    x = r[:, 103]
    return x, r[:, 97] + 40, 8, 1, (0 < x) & (x < 160)


@obj("OxygenBar")
def oxygen_bar(r):
    return 49, 170, jnp.minimum(r[:, 102], 63), 5, r[:, 102] != 0


@obj("CollectedDiver", 6)
def collected_diver(r):
    i = jnp.arange(6)
    return 58 + 8 * i, 178, 8, 9, i < r[:, 62:63]


GAME = table("seaquest", player, shark, submarine, diver, enemy_missile, surface_submarine,
             player_missile, oxygen_bar, collected_diver,
             notes="OCAtari reports the submarine at (76, 46) on the frame it reappears, and "
                   "keeps a lane's submarines (sharks) and missiles (divers) when the lane "
                   "changes kind; here every object follows the RAM of its frame.")
