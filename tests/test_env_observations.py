"""Observations through ``stori_jax.make`` on real emulators: every RAM-obs mode (type 3.2 'ram'),
blackout and crop masks, and the type-0 labelled RAM observation.

Masks are compared with a 3.1 twin (same seed, same actions, ``obs='raw'``): a mask changes the
observation only, never the game.
"""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np
import pytest

import stori_jax
from stori_jax import Config, ObservationMask, get_game
from stori_jax.builder import emulator_seeds
from stori_jax.plan import compile_plan

from _env_support import (binomial_ok, breakout_tracker, last_ram, lockstep_with_twin, make,
                          new_ale, random_actions, run_env, run_lockstep)

STEPS = 30
BOXING_RING = (110, 156, 66)
GOPHER_BEFORE_DUG = (187, 159, 71)
BANKHEIST_BLUE, BANKHEIST_SCORE = (0, 0, 148), (162, 98, 33)
BLACK = (0, 0, 0)


def actions_of(game, steps=STEPS):
    return random_actions(get_game(game).num_actions, steps, 2, seed=11)


@functools.lru_cache(maxsize=None)
def twin_run(game, steps=STEPS):
    env = make(game, obs="raw")
    try:
        return run_env(env, actions_of(game, steps))
    finally:
        env.close()


def masked_run(game, mask, steps=STEPS, granularity="frame"):
    env = make(game, Config(observation=mask, granularity=granularity), obs="raw")
    try:
        return run_env(env, actions_of(game, steps))
    finally:
        env.close()


def all_obs(run):
    """(T + 1, B, ...) the reset observation, then every step's."""
    return np.concatenate([run.reset_obs[None], run.stacked("obs")])


def all_masked(run):
    return np.concatenate([run.reset_info["obs_masked"][None], run.stacked("obs_masked")])


def assert_same_game(run, twin):
    np.testing.assert_array_equal(run.ram, twin.ram)
    for name in ("reward", "terminated", "truncated", "lives"):
        np.testing.assert_array_equal(run.stacked(name), twin.stacked(name), err_msg=name)


# ---------------------------------------------------------------------------------------------
# the default pipeline against a bare emulator
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("game", ["Breakout", "Boxing"])
def test_observations_are_the_max_of_a_steps_last_two_frames_on_a_bare_emulator(game):
    """3.1 at frame_skip 4 beside a bare ale-py emulator fed env 0's actions: 'raw' is
    max(screen of frame 3, screen of frame 4) of each step, the reward the sum over the four
    frames, and atari84's newest frame atari84_frame of that pooled screen."""
    from stori_jax.functional import atari84_frame

    seed, steps = 5, 40
    raw_env = make(game, obs="raw", seed=seed)
    env84 = make(game, obs="atari84", seed=seed)
    ale = new_ale(get_game(game).rom_id, emulator_seeds(seed, 1)[0])
    actions = ale.getMinimalActionSet()
    try:
        raw, _ = raw_env.reset()
        obs84, _ = env84.reset()
        ale.reset_game()
        np.testing.assert_array_equal(np.asarray(raw)[0], ale.getScreenRGB(), err_msg="reset")
        pooled_differs = 0
        for t, a in enumerate(random_actions(len(actions), steps, 1, seed=3)[:, 0]):
            step = np.array([a, a], np.int32)
            raw, reward, *_ = raw_env.step(step)
            obs84, *_ = env84.step(step)
            screens, total = [], 0
            for _ in range(4):
                total += ale.act(actions[a])
                screens.append(ale.getScreenRGB().copy())
            assert not ale.game_over()
            expected = np.maximum(screens[2], screens[3])
            pooled_differs += not np.array_equal(expected, screens[3])
            np.testing.assert_array_equal(np.asarray(raw)[0], expected, err_msg=f"step {t}")
            assert float(reward[0]) == total, f"step {t}"
            np.testing.assert_array_equal(np.asarray(obs84)[0, ..., -1],
                                          np.asarray(atari84_frame(expected[None]))[0],
                                          err_msg=f"step {t}: atari84")
        assert pooled_differs > 0, "the pooling should matter on some step"
    finally:
        raw_env.close()
        env84.close()


# ---------------------------------------------------------------------------------------------
# RAM-obs modes: the screen is rendered from modified RAM, the game is untouched
# ---------------------------------------------------------------------------------------------

RAM_MODES = [("Breakout", m) for m in (1, 2)] + [("Boxing", m) for m in (1, 2, 3)] + \
            [("Gopher", m) for m in (1, 2, 3, 4, 5)] + [("BankHeist", m) for m in range(1, 7)]

# condition of a mode that applies only when it is met, read from the true RAM after the step
CONDITIONAL = {
    ("Gopher", 5): lambda ram: ram[:, 92] != 128,                    # a seed is in the air
    ("BankHeist", 5): lambda ram: (ram[:, 24:27] == 253).any(-1),    # a bank is shown
    ("BankHeist", 6): lambda ram: (ram[:, 24:27] == 254).any(-1),    # a police car is shown
}


@pytest.mark.parametrize("game,mode", RAM_MODES)
def test_ram_obs_mode_changes_the_observation_only(game, mode):
    run = masked_run(game, ObservationMask("ram", mode, 1.0))
    twin = twin_run(game)
    assert_same_game(run, twin)
    obs, twin_obs, masked = all_obs(run), all_obs(twin), all_masked(run)
    assert obs.shape == twin_obs.shape == (STEPS + 1, 2, 210, 160, 3) and obs.dtype == np.uint8
    # where nothing was rendered the observation IS the twin's
    np.testing.assert_array_equal(obs[~masked], twin_obs[~masked])
    differs = (obs != twin_obs).any(axis=(2, 3, 4))
    if (game, mode) in CONDITIONAL:
        condition = CONDITIONAL[game, mode](run.ram.reshape(-1, 128)).reshape(masked.shape)
        # met after the step (when the second screen is rendered) => applied; in 30 steps
        # Gopher's seed and BankHeist's police never show: the exact test below meets them
        assert not (condition & ~masked).any()
    else:
        assert masked.all(), "p = 1: every observation is rendered from the modified RAM"
    if masked.any():
        assert differs[masked].mean() > 0.5, "the rendered screens should differ from the twin's"


@pytest.mark.parametrize("autoreset", [True, False])
def test_ram_obs_mode_leaves_the_game_alone_across_episode_ends(autoreset):
    """docs/spec.md section 4.2: the rendered frame is not part of the game, across episode ends
    too: RAM, rewards, ends and lives equal the twin's through three truncations at 40 frames
    (the render must not count toward the frame cap, nor survive into the next episode)."""
    actions = actions_of("Breakout", 33)
    run, twin = lockstep_with_twin("Breakout", Config(observation=ObservationMask("ram", 2, 1.0)),
                                   len(actions), lambda k, runs: actions[k], obs="raw",
                                   max_episode_frames=40, autoreset=autoreset)
    assert_same_game(run, twin)
    assert run.stacked("truncated")[:, 0].sum() == 3


# the bytes each mode writes, from docs/spec.md sections 5-8 (not from the library's tables);
# None: the mode's condition is not met, nothing is rendered and the observation is the screen
def _slots_equal(value):
    def writes(ram):
        slots = [a for a in (24, 25, 26) if ram[a] == value]
        return {a: 255 for a in slots} if slots else None
    return writes


SPEC_RAM_WRITES = {
    ("Breakout", 2): lambda ram: {99: 0, 101: 0},
    ("Boxing", 2): lambda ram: {2: 214},
    ("Gopher", 1): lambda ram: {52: int(ram[52]) & ~0b100},                # hide left carrot
    ("Gopher", 2): lambda ram: {52: int(ram[52]) & ~0b010},                # middle
    ("Gopher", 3): lambda ram: {52: int(ram[52]) & ~0b001},                # right
    ("Gopher", 4): lambda ram: {52: 0},                                    # all carrots
    ("Gopher", 5): lambda ram: {92: 128} if ram[92] != 128 else None,    # hide seed
    ("BankHeist", 1): lambda ram: {8: 155, 28: 12},                        # hide robber car
    ("BankHeist", 2): lambda ram: {86: 0},                                 # fuel gauge full
    ("BankHeist", 3): lambda ram: {66: 0, 68: 0},                          # hide city blocks
    ("BankHeist", 4): lambda ram: {69: {0: 30, 1: 190, 2: 46, 3: 126}[int(ram[0]) % 4]},
    ("BankHeist", 5): _slots_equal(253),                                   # hide banks
    ("BankHeist", 6): _slots_equal(254),                                   # hide police
}
# the modes that write only when their condition is met (the rest always write)
CONDITIONAL_WRITES = {("Gopher", 5), ("BankHeist", 5), ("BankHeist", 6)}
# (env seed, action seed, frames): runs long enough that the condition is met on many frames and
# unmet on many (a seed first falls at frame 5168, a police car first shows at 1781); BankHeist's
# banks are shown on every frame of the default 80, so only hide-banks' met side is exercised
RAM_WRITES_RUN = {("Gopher", 5): (2, 2, 5400), ("BankHeist", 6): (5, 3, 2000)}


@pytest.mark.parametrize("game,mode", [
    pytest.param(*case, marks=pytest.mark.slow) if case in RAM_WRITES_RUN else case
    for case in SPEC_RAM_WRITES])
def test_ram_obs_mode_shows_the_next_noop_frame_of_the_written_ram(game, mode):
    """docs/spec.md section 4.2 on a bare ale-py emulator beside the env: save the state, write the
    mode's bytes, run one NOOP frame, take that screen, restore. Every observation must be that
    screen, pixel for pixel, or the true screen where a conditional mode's condition is not met
    (one env, frame_skip 1, p = 1, random steps)."""
    seed, action_seed, steps = RAM_WRITES_RUN.get((game, mode), (5, 3, 80))
    env = make(game, Config(observation=ObservationMask("ram", mode, 1.0)), obs="raw",
               num_envs=1, seed=seed, frame_skip=1)
    ale = new_ale(get_game(game).rom_id, emulator_seeds(seed, 1)[0])
    actions = ale.getMinimalActionSet()
    writes = SPEC_RAM_WRITES[game, mode]
    met = []

    def expected():
        """(the screen the mode shows, whether it rendered one)"""
        state, written = ale.cloneState(), writes(ale.getRAM())
        met.append(written is not None)
        if written is None:
            return ale.getScreenRGB(), False
        for address, value in written.items():
            ale.setRAM(address, value)
        ale.act(actions[0])
        screen = ale.getScreenRGB().copy()
        ale.restoreState(state)
        return screen, True

    def check(obs, info, when):
        screen, rendered = expected()
        np.testing.assert_array_equal(np.asarray(obs)[0], screen, err_msg=when)
        assert bool(np.asarray(info["obs_masked"])[0]) == rendered, when

    try:
        obs, info = env.reset()
        ale.reset_game()
        check(obs, info, "reset")
        for t, a in enumerate(random_actions(len(actions), steps, 1, seed=action_seed)[:, 0]):
            obs, _, _, _, info = env.step(np.array([a], np.int32))
            ale.act(actions[a])
            assert not ale.game_over()
            check(obs, info, f"step {t}")
    finally:
        env.close()
    if (game, mode) in CONDITIONAL_WRITES:
        assert sum(met) >= 50, "the condition should be met often"
    if (game, mode) in RAM_WRITES_RUN:
        assert len(met) - sum(met) >= 50, "the condition should be unmet often too"


def test_ram_obs_mode_at_step_granularity_renders_both_pooled_screens():
    """Step granularity, frame_skip 4, Boxing hide player (RAM mode 3, 1 <- 214) at p = 1,
    beside a bare emulator: one decision covers the step, and BOTH screens max-pooled into its
    observation are rendered from the written RAM (each the next NOOP frame after frame 3 and
    after frame 4).  Rendering only the last one let the true screen 3 show the white player
    through the max-pool."""
    seed, steps = 5, 15
    config = Config(observation=ObservationMask("ram", 3, 1.0), granularity="step")
    env = make("Boxing", config, obs="raw", num_envs=1, seed=seed)
    ale = new_ale(get_game("Boxing").rom_id, emulator_seeds(seed, 1)[0])
    actions = ale.getMinimalActionSet()

    def rendered():
        state = ale.cloneState()
        ale.setRAM(1, 214)
        ale.act(actions[0])
        screen = ale.getScreenRGB().copy()
        ale.restoreState(state)
        return screen

    true_player_shows = 0
    try:
        assert not env.plan.per_frame
        obs, info = env.reset()
        ale.reset_game()
        np.testing.assert_array_equal(np.asarray(obs)[0], rendered(), err_msg="reset")
        for t, a in enumerate(random_actions(len(actions), steps, 1, seed=3)[:, 0]):
            obs, _, _, _, info = env.step(np.array([a], np.int32))
            screens, truth = [], []
            for _ in range(4):
                ale.act(actions[a])
                truth.append(ale.getScreenRGB().copy())
                screens.append(rendered())
            assert not ale.game_over() and bool(np.asarray(info["obs_masked"])[0])
            np.testing.assert_array_equal(np.asarray(obs)[0], np.maximum(screens[2], screens[3]),
                                          err_msg=f"step {t}")
            last_only = np.maximum(truth[2], screens[3])
            true_player_shows += not np.array_equal(last_only, np.asarray(obs)[0])
    finally:
        env.close()
    assert true_player_shows > steps // 2


def test_ram_obs_mode_renders_the_first_observation_after_an_autoreset():
    """At p = 1 the first observation of every episode is rendered too: the observation
    returned with a truncation (max_episode_frames 40 = 10 steps) equals the first reset's."""
    config = Config(observation=ObservationMask("ram", 2, 1.0))
    env = make("Boxing", config, obs="raw", max_episode_frames=40)
    try:
        run = run_env(env, actions_of("Boxing", 12))
    finally:
        env.close()
    assert all_masked(run).all()
    truncated = run.stacked("truncated")
    np.testing.assert_array_equal(truncated[:, 0], np.arange(12) == 9)
    np.testing.assert_array_equal(run.obs[9], run.reset_obs)
    assert (run.obs[8] != run.reset_obs).any()


@pytest.mark.parametrize("end", ["truncated", "game over"])
def test_ram_obs_mode_leaves_an_episodes_final_frame_true_and_says_so(end):
    """autoreset=False: ALE emulates no frame past an episode's end, so a RAM mode cannot
    render the frame that ends an episode; that observation is the true screen, and
    obs_masked is False there (it said True).  Breakout, ball hidden (mode 2) at p = 1, FIRE
    (the ball is served; the paddle never moves): truncated at frame 42, in the middle of the
    11th step (its observation is that one frame), or a game over (five balls lost).  Every
    observation before the last one is rendered (obs_masked; most differ from the twin's)."""
    config = Config(observation=ObservationMask("ram", 2, 1.0))
    kw = dict(obs="raw", num_envs=1, num_workers=0, autoreset=False)
    if end == "truncated":
        kw["max_episode_frames"] = 42
    fire = np.ones(1, np.int32)
    env, twin = make("Breakout", config, **kw), make("Breakout", **kw)
    try:
        env.reset(), twin.reset()
        differed = []
        for k in range(2000):
            obs, _, terminated, truncated, info = env.step(fire)
            twin_obs, *_ = twin.step(fire)
            if terminated[0] or truncated[0]:
                break
            assert info["obs_masked"][0], k
            differed.append((np.asarray(obs) != np.asarray(twin_obs)).any())
    finally:
        env.close()
        twin.close()
    if end == "truncated":
        assert truncated[0] and k == 10
    else:
        assert terminated[0] and not truncated[0]
    assert np.mean(differed) > 0.5
    assert not info["obs_masked"][0]
    np.testing.assert_array_equal(np.asarray(obs), np.asarray(twin_obs))


def test_boxing_hide_enemy_removes_the_black_boxer():
    """RAM mode 2 (Boxing 3.2C): the enemy (black, RAM 2) is drawn in the ring colour: no black
    pixel is left inside the ring, while the twin shows the black boxer there."""
    run, twin = masked_run("Boxing", ObservationMask("ram", 2, 1.0)), twin_run("Boxing")
    ring = (slice(None), slice(None), slice(37, 176), slice(33, 127))
    black = lambda o: (o[ring] == 0).all(-1).sum(axis=(2, 3))  # noqa: E731
    assert (black(all_obs(twin)) > 20).all()
    assert (black(all_obs(run)) == 0).all()


@pytest.mark.parametrize("mode,score,colour", [(2, (87, 134, 1, 16), BLACK),
                                               (3, (33, 69, 1, 16), (214, 214, 214))])
def test_boxing_hiding_a_boxer_hides_its_score(mode, score, colour):
    """docs/spec.md section 6: RAM mode 2 (enemy) and 3 (player) also hide that side's score
    digits, drawn in the boxer's colour in the score region given there."""
    run, twin = masked_run("Boxing", ObservationMask("ram", mode, 1.0)), twin_run("Boxing")
    x0, x1, y0, y1 = score

    def digit_pixels(obs):
        return (obs[:, :, y0:y1 + 1, x0:x1 + 1] == colour).all(-1).sum(axis=(2, 3))

    assert (digit_pixels(all_obs(twin)) > 10).all()
    assert (digit_pixels(all_obs(run)) == 0).all()


@pytest.mark.parametrize("mode,address", [(1, 3), (2, 2), (3, 1)])
def test_a_ram_mode_shows_boxings_colour_flip(mode, address):
    """docs/spec.md sections 6 and 4.2 on a bare emulator beside the env: the flip's colours are
    written before EVERY frame, the hidden NOOP frame of a RAM mode included (it showed the
    game's own colours: a flip combined with a RAM mode was invisible whenever the mode
    rendered). Colour flip at p = 1 toggles every frame; the RAM mode renders every observation:
    mode 1 (hide the ring, RAM 3) or mode 2 / 3 (hide the enemy / player: RAM 2 / 1, which the
    flip writes too). The flip's standing writes come first, the mode's own last: a hidden boxer
    stays hidden (the flip's colour written over the mode's 214 showed it)."""
    from stori_jax import RandomEvent

    config = Config(event=RandomEvent(1, 1.0), observation=ObservationMask("ram", mode, 1.0))
    env = stori_jax.make("Boxing", config=config, obs="raw", num_envs=1, seed=5, frame_skip=1,
                         num_workers=0)
    ale = new_ale(get_game("Boxing").rom_id, emulator_seeds(5, 1)[0])
    actions = ale.getMinimalActionSet()
    flipped, shown = False, 0

    def colours():  # RAM 1 and 2 as the flip writes them
        a, b = int(start[1]), int(start[2])
        return {1: b, 2: a} if flipped else {1: a, 2: b}

    def expected():
        state = ale.cloneState()
        for written, value in {**colours(), address: 214}.items():
            ale.setRAM(written, value)
        ale.act(actions[0])
        screen = ale.getScreenRGB().copy()
        ale.restoreState(state)
        return screen

    try:
        env.reset()
        ale.reset_game()
        start = ale.getRAM().copy()
        for t, a in enumerate(random_actions(len(actions), 40, 1, seed=3)[:, 0]):
            obs = np.asarray(env.step(np.array([a], np.int32))[0])[0]
            flipped = not flipped
            for written, value in colours().items():
                ale.setRAM(written, value)
            ale.act(actions[a])
            np.testing.assert_array_equal(obs, expected(), err_msg=f"step {t}")
            shown += flipped
    finally:
        env.close()
    assert shown == 20


# ---------------------------------------------------------------------------------------------
# blackout and crop: exactly the spec's regions, in the spec's fill
# ---------------------------------------------------------------------------------------------

def region(x0, x1, y0, y1, fill=BLACK):
    return (x0, x1, y0, y1, fill)


# written from docs/spec.md sections 4-8 (not from the library's tables); painted in order
SPEC_MASKS = {
    ("Breakout", "blackout", 1): [region(8, 151, 57, 92), region(7, 152, 189, 195),
                                  region(2, 158, 3, 16), region(8, 151, 105, 130),
                                  region(8, 151, 131, 156), region(8, 151, 157, 182)],
    ("Boxing", "blackout", 1): [region(32, 127, 36, 176, BOXING_RING),
                                region(87, 134, 1, 16, BOXING_RING),
                                region(33, 69, 1, 16, BOXING_RING),
                                region(57, 97, 14, 27, BOXING_RING)],
    ("Gopher", "blackout", 1): [region(0, 159, 161, 200, GOPHER_BEFORE_DUG),
                                region(0, 159, 87, 145), region(0, 159, 26, 56),
                                region(0, 159, 0, 25)] + [
        region(x0, x1, y0, y1, fill) for x0, x1 in ((0, 59), (100, 159))
        for y0, y1, fill in ((146, 150, (101, 209, 174)), (151, 155, (117, 231, 194)),
                             (156, 160, (132, 252, 212)))],
    ("Gopher", "blackout", 6): [region(0, 159, 164, 200, GOPHER_BEFORE_DUG)],
    ("BankHeist", "blackout", 1): [region(12, 147, 37, 44), region(12, 15, 37, 177),
                                   region(12, 147, 173, 177), region(144, 147, 37, 177),
                                   region(12, 73, 11, 36, BANKHEIST_BLUE),
                                   region(78, 147, 11, 36, BANKHEIST_BLUE),
                                   region(12, 147, 178, 186, BANKHEIST_SCORE)],
    ("Breakout", "crop", 1): [region(0, 79, 0, 209)],
    ("Boxing", "crop", 3): [region(0, 159, 0, 104)],
}


def expected_mask(regions):
    hidden = np.zeros((210, 160), bool)
    fill = np.zeros((210, 160, 3), np.uint8)
    for x0, x1, y0, y1, colour in regions:
        hidden[y0:y1 + 1, x0:x1 + 1] = True
        fill[y0:y1 + 1, x0:x1 + 1] = colour
    return hidden, fill


def spec_and_env_masks(game, kind, mode):
    """(hidden, fill) from docs/spec.md, and the (hidden, fill) the env's plan masks with."""
    plan = compile_plan(Config(observation=ObservationMask(kind, mode, 1.0)), get_game(game),
                        num_envs=1, frame_skip=4, obs="raw", noop_max=0)
    return expected_mask(SPEC_MASKS[game, kind, mode]), plan.static_mask(get_game(game))


@pytest.mark.parametrize("game,kind,mode", list(SPEC_MASKS))
def test_the_env_masks_exactly_the_spec_regions(game, kind, mode):
    """The env's own mask, pixel for pixel: where a region's edge shows the fill colour anyway
    (Boxing's ring), the screens of the test below cannot tell a region one pixel short."""
    (hidden, fill), (env_hidden, env_fill) = spec_and_env_masks(game, kind, mode)
    np.testing.assert_array_equal(env_hidden, hidden)
    np.testing.assert_array_equal(env_fill[hidden], fill[hidden])


@pytest.mark.parametrize("game,kind,mode", [("Breakout", "blackout", 1),
                                            ("Boxing", "blackout", 1), ("Boxing", "crop", 3)])
def test_a_masked_observation_is_the_twins_with_the_regions_filled(game, kind, mode):
    """Every observation is the 3.1 twin's outside the regions and the fill inside them (a
    black fill, the ring colour; a blackout, a crop), and the game is the twin's."""
    steps = 8
    run = masked_run(game, ObservationMask(kind, mode, 1.0), steps=steps)
    twin = twin_run(game, steps=steps)
    assert_same_game(run, twin)
    (hidden, fill), _ = spec_and_env_masks(game, kind, mode)
    obs, twin_obs = all_obs(run), all_obs(twin)
    assert all_masked(run).all()
    np.testing.assert_array_equal(obs[:, :, ~hidden], twin_obs[:, :, ~hidden])
    np.testing.assert_array_equal(obs[:, :, hidden],
                                  np.broadcast_to(fill[hidden], obs[:, :, hidden].shape))
    # the region did hide something
    assert (twin_obs[:, :, hidden] != fill[hidden]).any()


def torch_centres(seen, hidden):
    """Integer centres (x, y) of a radius-75 disc containing every ``seen`` pixel and no
    ``hidden`` one."""
    ys, xs = np.mgrid[:210, :160]
    cx, cy = xs.ravel(), ys.ravel()

    def max_dist2(points):  # (210*160,) max squared distance from each centre to ``points``
        out = np.zeros(cx.shape, np.int64)
        for y, x in points:
            np.maximum(out, (cx - x) ** 2 + (cy - y) ** 2, out=out)
        return out

    # the farthest seen pixel from any centre is one of each row's two extreme seen pixels
    rows = [(y, x) for y in np.unique(np.nonzero(seen)[0])
            for x in (np.nonzero(seen[y])[0].min(), np.nonzero(seen[y])[0].max())]
    ok = max_dist2(rows) <= 75 ** 2
    hy, hx = np.nonzero(hidden)
    for i in np.nonzero(ok)[0]:
        if ((hx - cx[i]) ** 2 + (hy - cy[i]) ** 2 <= 75 ** 2).any():
            ok[i] = False
    return np.stack([cx[ok], cy[ok]], -1)


def test_torch_shows_a_disc_of_radius_75_and_blacks_out_the_rest():
    """Crop mode 5 at step granularity (one centre for both screens): the observation is the
    twin's inside a disc of radius 75 and black outside it."""
    steps = 5
    run = masked_run("Breakout", ObservationMask("crop", 5, 1.0), steps=steps, granularity="step")
    twin = twin_run("Breakout", steps=steps)  # 3.1 is the same game at either granularity
    assert_same_game(run, twin)
    obs, twin_obs = all_obs(run), all_obs(twin)
    assert all_masked(run).all()
    for t in range(steps + 1):
        for b in range(2):
            o, w = obs[t, b], twin_obs[t, b]
            kept = (o == w).all(-1)
            black = (o == 0).all(-1)
            assert (black | kept).all(), "a pixel is the twin's or black"
            # outside the disc everything is black: at least the screen minus the largest disc
            assert black.sum() >= 210 * 160 - (np.pi * 75 ** 2 + 2 * np.pi * 75 + 1)
            seen, hidden = kept & (w != 0).any(-1), ~kept
            assert seen.any() and hidden.any()
            assert len(torch_centres(seen, hidden)), f"no disc explains step {t}, env {b}"


def torch_screen(screen, centre):
    """``screen`` with every pixel farther than 75 from ``centre`` (x, y) black (docs/spec.md
    section 4.1)."""
    ys, xs = np.mgrid[:210, :160]
    hidden = (xs - int(centre[0])) ** 2 + (ys - int(centre[1])) ** 2 > 75 ** 2
    return np.where(hidden[..., None], np.uint8(0), screen)


def test_torch_at_frame_granularity_gives_each_pooled_screen_its_own_disc():
    """Breakout 3.2C (torch, p = 1, frame granularity) beside a bare emulator: every step's
    observation is max(screen 3 seen through its own disc, screen 4 through its own), the two
    centres the env's own draws for the step (core.before_step on its state), pixel for pixel.
    (Both screens through the first screen's disc passes the one-disc test above.)"""
    from stori_jax.core import before_step

    seed, steps = 5, 12
    env = make("Breakout", stori_jax.preset("Breakout", "3.2C"), obs="raw", seed=seed)
    ale = new_ale(get_game("Breakout").rom_id, emulator_seeds(seed, 1)[0])
    actions = ale.getMinimalActionSet()
    one_disc_differs = 0
    try:
        assert env.plan.per_frame and env.plan.frames_layout == "pair"
        env.reset()
        ale.reset_game()
        for t, a in enumerate(random_actions(len(actions), steps, 1, seed=3)[:, 0]):
            step = np.array([a, a], np.int32)
            _, draws = before_step(env._jit_plan, env._state, jnp.asarray(step))
            centres = np.asarray(draws.mask_centres)[0]
            assert np.asarray(draws.mask_apply).all()
            obs, _, _, _, info = env.step(step)
            screens = []
            for _ in range(4):
                ale.act(actions[a])
                screens.append(ale.getScreenRGB().copy())
            assert not ale.game_over() and bool(np.asarray(info["obs_masked"])[0])
            expected = np.maximum(torch_screen(screens[2], centres[0]),
                                  torch_screen(screens[3], centres[1]))
            np.testing.assert_array_equal(np.asarray(obs)[0], expected, err_msg=f"step {t}")
            one_disc = np.maximum(torch_screen(screens[2], centres[0]),
                                  torch_screen(screens[3], centres[0]))
            one_disc_differs += not np.array_equal(one_disc, expected)
    finally:
        env.close()
    assert one_disc_differs >= steps // 2, "the second disc should show on most steps"


@pytest.mark.parametrize("preset", ["3.2A", "3.2C"])
def test_resized_observations_are_of_the_masked_screen(preset):
    """atari84 and dreamer64 resize the masked screen, not the true one: beside an obs='raw'
    env of the same preset, seed and actions, every observation (the reset's included) is
    atari84_frame / dreamer64 of the raw one, at frame granularity (a blackout, the torch).
    A 3.1 twin checks that the mask did change the resized observation."""
    from stori_jax.functional import atari84_frame, dreamer64

    kw = dict(num_envs=2, seed=3)
    envs = [make("Breakout", stori_jax.preset("Breakout", preset), obs=obs, **kw)
            for obs in ("atari84", "dreamer64", "raw")] + [make("Breakout", obs="raw", **kw)]
    try:
        assert envs[0].plan.per_frame
        runs = run_lockstep(envs, 40, lambda k, runs: breakout_tracker(last_ram(runs[2])))
    finally:
        for env in envs:
            env.close()
    a84, d64, raw, twin = (all_obs(run) for run in runs)
    for resize, newest in ((atari84_frame, a84[..., -1]), (dreamer64, d64)):
        expected = np.stack([np.asarray(resize(r)) for r in raw])
        np.testing.assert_array_equal(newest, expected)
        unmasked = np.stack([np.asarray(resize(r)) for r in twin])
        differs = (expected != unmasked).any(axis=tuple(range(2, expected.ndim)))
        assert differs.any(), "the mask should change some resized observation"
    assert np.array_equal(runs[2].ram, runs[3].ram)


def test_mask_at_step_granularity_applies_per_step_with_probability_p():
    steps = 60
    mask = ObservationMask("blackout", 9, 0.5)  # Boxing 3.2A's regions (scores + clock)
    run = masked_run("Boxing", mask, steps=steps, granularity="step")
    twin = twin_run("Boxing", steps=steps)
    assert_same_game(run, twin)
    hidden, fill = expected_mask([region(87, 134, 1, 16, BOXING_RING),
                                  region(33, 69, 1, 16, BOXING_RING),
                                  region(57, 97, 14, 27, BOXING_RING)])
    obs, twin_obs, masked = all_obs(run), all_obs(twin), all_masked(run)
    np.testing.assert_array_equal(obs[~masked], twin_obs[~masked])
    np.testing.assert_array_equal(obs[masked][:, hidden],
                                  np.broadcast_to(fill[hidden], obs[masked][:, hidden].shape))
    np.testing.assert_array_equal(obs[masked][:, ~hidden], twin_obs[masked][:, ~hidden])
    assert binomial_ok(int(masked.sum()), masked.size, 0.5)


def test_mask_at_frame_granularity_applies_to_each_pooled_screen_with_probability_p():
    """At frame granularity each of the two screens max-pooled into an observation is masked on
    its own with prob p, so an observation shows the mask with prob 1 - (1 - p)^2."""
    steps, p = 200, 0.3
    run = masked_run("Boxing", ObservationMask("crop", 1, p), steps=steps, granularity="frame")
    assert_same_game(run, twin_run("Boxing", steps=steps))
    masked = all_masked(run)
    assert binomial_ok(int(masked.sum()), masked.size, 1 - (1 - p) ** 2)
    assert not binomial_ok(int(masked.sum()), masked.size, p), "one draw per step would be p"


def test_ram_mode_at_frame_granularity_renders_each_pooled_screen_with_probability_p():
    """A RAM-obs mode at frame granularity: each of the two screens max-pooled into a step's
    observation gets its own render decision, so the observation shows the mode with prob
    1 - (1 - p)^2.  Boxing hide enemy (mode 2): the black boxer is gone from the pooled ring
    exactly when obs_masked (one hidden screen suffices: max(black, ring) is the ring).  (One
    decision shared by both screens rendered with prob p.)"""
    steps, p = 200, 0.5
    run = masked_run("Boxing", ObservationMask("ram", 2, p), steps=steps, granularity="frame")
    assert_same_game(run, twin_run("Boxing", steps=steps))
    obs, masked = run.stacked("obs"), run.stacked("obs_masked")  # the steps' (not the resets')
    ring = (slice(None), slice(None), slice(37, 176), slice(33, 127))
    enemy_shown = (obs[ring] == 0).all(-1).sum(axis=(-2, -1)) > 20
    np.testing.assert_array_equal(enemy_shown, ~masked)
    assert binomial_ok(int(masked.sum()), masked.size, 1 - (1 - p) ** 2)
    assert not binomial_ok(int(masked.sum()), masked.size, p), "one decision per step would be p"


def test_at_frame_skip_1_an_observation_gets_one_mask_decision():
    """frame_skip 1: each observation is one emulator frame, masked with probability p (the
    spec's per-frame rate) and wholly when masked. (Two decisions on the one frame in both
    slots masked a black crop only when both fired, p^2, and flagged 1 - (1 - p)^2.)"""
    p, steps = 0.5, 50
    env = make("Breakout", Config(observation=ObservationMask("crop", 1, p)), obs="raw",
               num_envs=4, frame_skip=1)
    try:
        run = run_env(env, random_actions(4, steps, 4, seed=2))
    finally:
        env.close()
    obs, masked = all_obs(run), all_masked(run)
    left_black = (obs[..., :, :80, :] == 0).all(axis=(-3, -2, -1))
    np.testing.assert_array_equal(left_black, masked)
    assert binomial_ok(int(masked.sum()), masked.size, p)
    assert not binomial_ok(int(masked.sum()), masked.size, 1 - (1 - p) ** 2)


@pytest.mark.parametrize("end_frame", [41, 43, 44])
@pytest.mark.parametrize("layout", ["pooled", "pair"])
def test_without_autoreset_an_episode_that_ends_mid_step_shows_its_last_frame(end_frame, layout):
    """autoreset=False and an episode truncated at frame 41, 43 or 44 (frames 1, 3 and 4 of the
    11th step): the final observation is the screen of the episode's last frame (beside a bare
    emulator), max-pooled with the frame before it only where the step played both (44). It
    was the previous step's screens (41) or one of them pooled with the last frame (43). A
    restored snapshot from before that step gives the same observation. 'pair': the screens
    reach JAX unpooled (a per-frame crop, p = 1: the left half black) and env 0 is emulated
    in this process, env 1 in a worker."""
    seed = 5
    mask = ObservationMask("crop", 1, 1.0) if layout == "pair" else None
    num_envs = 2 if layout == "pair" else 1
    kw = dict(obs="raw", num_envs=num_envs, seed=seed, max_episode_frames=end_frame,
              autoreset=False, inline_envs=num_envs - 1 if layout == "pair" else None,
              num_workers=1 if layout == "pair" else 0)
    expected = []
    for emulator_seed in emulator_seeds(seed, num_envs):
        ale = new_ale(get_game("Breakout").rom_id, emulator_seed)
        ale.reset_game()
        screens = []
        for _ in range(end_frame):
            ale.act(ale.getMinimalActionSet()[1])  # FIRE
            screens.append(ale.getScreenRGB().copy())
        last = np.maximum(screens[-2], screens[-1]) if end_frame % 4 == 0 else screens[-1]
        if mask is not None:
            last[:, :80] = 0
        expected.append(last)
    fire = np.ones(num_envs, np.int32)
    config = Config(observation=mask) if mask is not None else None
    env, restored = make("Breakout", config, **kw), make("Breakout", config, **kw)
    try:
        assert env.plan.frames_layout == layout
        env.reset()
        for _ in range(10):
            env.step(fire)
        restored.reset()
        restored.restore(env.snapshot())
        obs, _, _, truncated, info = env.step(fire)
        assert truncated.all()
        np.testing.assert_array_equal(np.asarray(obs), np.stack(expected))
        assert np.asarray(info["obs_masked"]).all() == (mask is not None)
        np.testing.assert_array_equal(np.asarray(restored.step(fire)[0]), np.asarray(obs))
    finally:
        env.close()
        restored.close()


def reset_observations(game, mask, resets, num_envs=8):
    """(resets * num_envs) first observations of an episode and their obs_masked flags."""
    env = make(game, Config(observation=mask), obs="raw", num_envs=num_envs)
    try:
        seen = [env.reset() for _ in range(resets)]
    finally:
        env.close()
    obs = np.concatenate([np.asarray(o) for o, _ in seen])
    return obs, np.concatenate([np.asarray(i["obs_masked"]) for _, i in seen])


def test_the_first_observation_of_an_episode_gets_one_mask_decision():
    """A reset shows one emulator frame (copied into both pooled slots), so it is masked with
    probability p and, when masked, wholly: the left half is black exactly when obs_masked.
    (Two decisions on the one frame gave a flag rate of 1 - (1 - p)^2 and, under a black crop,
    an observation that showed through whenever one of them missed.)"""
    p = 0.5
    obs, masked = reset_observations("Breakout", ObservationMask("crop", 1, p), resets=32)
    left_black = (obs[:, :, :80] == 0).all(axis=(1, 2, 3))
    np.testing.assert_array_equal(left_black, masked)
    assert binomial_ok(int(masked.sum()), masked.size, p)
    assert not binomial_ok(int(masked.sum()), masked.size, 1 - (1 - p) ** 2)


def test_the_first_observation_of_an_episode_shows_one_torch_disc():
    obs, masked = reset_observations("Breakout", ObservationMask("crop", 5, 1.0), resets=8,
                                     num_envs=2)
    twin_obs = twin_run("Breakout").reset_obs
    assert masked.all()
    for o, w in zip(obs, np.concatenate([twin_obs] * 8)):
        kept = (o == w).all(-1)
        seen, hidden = kept & (w != 0).any(-1), ~kept
        assert len(torch_centres(seen, hidden)), "no single disc explains the first observation"


def test_the_first_observation_of_an_episode_gets_one_ram_render_decision():
    p = 0.5
    obs, masked = reset_observations("Boxing", ObservationMask("ram", 2, p), resets=24)
    ring = (slice(None), slice(37, 176), slice(33, 127))
    enemy_shown = (obs[ring] == 0).all(-1).sum(axis=(1, 2)) > 20
    np.testing.assert_array_equal(enemy_shown, ~masked)
    assert binomial_ok(int(masked.sum()), masked.size, p)
    assert not binomial_ok(int(masked.sum()), masked.size, 1 - (1 - p) ** 2)


# ---------------------------------------------------------------------------------------------
# type 0: the RAM observation and its labels
# ---------------------------------------------------------------------------------------------

def test_type0_observation_is_the_ram_with_labels():
    env = make("Breakout", Config(ram_observation=True), obs=None)
    try:
        assert env.observation_space.shape == (2, 128)
        run = run_lockstep([env], 200, lambda k, runs: breakout_tracker(
            runs[0].info[-1]["ram"] if runs[0].info else runs[0].reset_info["ram"]))[0]
    finally:
        env.close()
    obs = all_obs(run)
    assert obs.shape == (201, 2, 128) and obs.dtype == np.uint8
    np.testing.assert_array_equal(obs, run.ram)
    labels = {k: np.stack([run.reset_info["labels"][k]] + [i["labels"][k] for i in run.info])
              for k in run.reset_info["labels"]}
    assert {"ball_x", "ball_y", "player_x", "score"} <= set(labels)
    np.testing.assert_array_equal(labels["ball_x"], run.ram[..., 99])
    np.testing.assert_array_equal(labels["ball_y"], run.ram[..., 101])
    np.testing.assert_array_equal(labels["player_x"], run.ram[..., 72])
    # the corrected score label (BCD in RAM 76, 77) is the running sum of rewards
    returns = np.concatenate([np.zeros((1, 2)), np.cumsum(run.stacked("reward"), 0)])
    assert not run.done.any() and returns[-1].min() > 0
    np.testing.assert_array_equal(labels["score"], returns)


def test_type0_boxing_labels_follow_the_scores():
    env = make("Boxing", Config(ram_observation=True))
    try:
        run = run_env(env, random_actions(18, 150, 2, seed=12))
    finally:
        env.close()
    labels = run.info[-1]["labels"]
    ram = run.info[-1]["ram"].astype(int)
    assert labels["player_x"].tolist() == ram[:, 32].tolist()
    assert labels["enemy_y"].tolist() == ram[:, 35].tolist()
    returns = run.stacked("reward").sum(0)
    np.testing.assert_array_equal(labels["player_score"] - labels["enemy_score"], returns)
    assert (labels["enemy_score"] > 0).any()
    # the clock counts down from 2:00 one second per 60 frames (15 steps): 1:59 after the
    # first step, 1:50 after 150 (the raw minutes byte is 0x1B then)
    clock = np.stack([60 * i["labels"]["clock_minutes"] + i["labels"]["clock_seconds"]
                      for i in run.info]).astype(int)
    assert clock[0].tolist() == [119, 119] and clock[-1].tolist() == [110, 110]
    assert set(np.diff(clock, axis=0).ravel().tolist()) == {0, -1}


# the labels of docs/spec.md sections 7 and 8 and the RAM bytes they read (label: address)
SPEC_LABEL_BYTES = {
    "Gopher": {"farmer_x": 31, "seed_y": 92, "seed_x": 95, "underground_row0_0": 0,
               "underground_row3_5": 23, "duck_25": 25, "duck_94": 94},
    "BankHeist": {"city_count": 0, "robber_y": 8, "robber_x": 28, "bomb": 12, "direction": 15,
                  "orientation": 51, "slot_0": 24, "slot_2": 26, "police_orientation_0": 52,
                  "lives": 85, "fuel": 86, "background_colour": 69, "city_blocks_66": 66},
}


@pytest.mark.parametrize("game", sorted(SPEC_LABEL_BYTES))
def test_type0_labels_read_the_spec_addresses(game):
    """Type 0 through make() on Gopher and BankHeist: the observation is the RAM after every
    step, and each label reads its spec address (Gopher's carrots: bits 2..0 of RAM 52, its
    score: the running sum of rewards; BankHeist's city: RAM 0 % 4)."""
    num_actions = get_game(game).num_actions
    env = make(game, Config(ram_observation=True), obs=None)
    try:
        assert env.observation_space.shape == (2, 128)
        run = run_env(env, random_actions(num_actions, 300, 2, seed=4))
    finally:
        env.close()
    assert not run.done.any()
    np.testing.assert_array_equal(np.concatenate([run.reset_obs[None], run.stacked("obs")]),
                                  run.ram)
    labels = {k: np.stack([run.reset_info["labels"][k]] + [i["labels"][k] for i in run.info])
              for k in run.reset_info["labels"]}
    ram = run.ram.astype(int)
    for name, address in SPEC_LABEL_BYTES[game].items():
        np.testing.assert_array_equal(labels[name], ram[..., address], err_msg=name)
    if game == "Gopher":
        np.testing.assert_array_equal(labels["carrots"], ram[..., 52] & 7)
        returns = np.concatenate([np.zeros((1, 2)), np.cumsum(run.stacked("reward"), 0)])
        assert returns[-1].max() > 0
        np.testing.assert_array_equal(labels["score"], returns)
    else:
        np.testing.assert_array_equal(labels["city"], ram[..., 0] % 4)
    moving = {"Gopher": "farmer_x", "BankHeist": "robber_x"}[game]   # not a still picture
    assert len(np.unique(labels[moving])) > 1
