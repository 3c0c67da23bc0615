"""Objects in the env: ``obs="objects"``, ``info["objects"]``, and the 3.2 mode that hides
object classes (ObservationMask kind "objects"), on real screens."""

from __future__ import annotations

import numpy as np
import pytest

import stori_jax
from stori_jax import Config, ConceptDrift, ObservationMask
from stori_jax.objects import hidden_pixels, objects_array, objects_layout


def hide(classes, prob=1.0, **kw):
    return Config(observation=ObservationMask("objects", 1, prob, classes=classes), **kw)


def test_the_objects_observation_is_the_objects_of_the_ram_it_ends_on():
    """obs="objects" and info["objects"] are the objects of the step's RAM; where an episode
    ended, info["final_objects"] holds those it ended on, as the env without autoreset shows."""
    kw = dict(num_envs=2, seed=0, obs="objects", max_episode_frames=60)
    with stori_jax.make("Breakout", "3.1", **kw) as env, \
            stori_jax.make("Breakout", "3.1", autoreset=False, **kw) as twin:
        obs, info = env.reset()
        twin.reset()
        rows = len(objects_layout("Breakout"))
        assert obs.shape == env.observation_space.shape == (2, rows, 5)
        assert obs.dtype == np.int32 and env.observation_space.contains(np.asarray(obs))
        assert np.asarray(obs[:, 0, 4]).all()  # the paddle is present
        for _ in range(20):
            obs, _, terminated, truncated, info = env.step([1, 3])
            ended_on, *_, twin_info = twin.step([1, 3])
            assert np.array_equal(obs, objects_array("Breakout", info["ram"]))
            assert np.array_equal(obs, info["objects"])
            if np.asarray(terminated | truncated).any():
                break
            assert np.array_equal(info["final_objects"], obs)
        else:
            raise AssertionError("no episode ended")
        assert np.array_equal(info["final_objects"], ended_on)
        assert np.array_equal(ended_on, twin_info["objects"])


# (game, classes hidden): six games, each class on screen in the first steps
HIDDEN = [("Breakout", ("Player", "Ball")), ("Pong", ("Ball", "Player")), ("Freeway", ("Car",)),
          ("Boxing", ("Enemy",)), ("Seaquest", ("Player", "OxygenBar")),
          ("Tennis", ("Player", "BallShadow"))]


@pytest.mark.parametrize("game,classes", HIDDEN, ids=[g for g, _ in HIDDEN])
def test_hidden_objects_are_exactly_their_boxes_black_on_the_3_1_twins_screen(game, classes):
    """Frame skip 1 (each observation one emulator frame, whose RAM the twin's info has): the
    masked screen is the 3.1 twin's with the classes' boxes black, and nothing else changed."""
    kw = dict(num_envs=2, seed=1, obs="raw", frame_skip=1, max_episode_frames=400)
    with stori_jax.make(game, config=hide(classes), **kw) as env, \
            stori_jax.make(game, "3.1" if game in stori_jax.STORI_GAMES else None, **kw) as twin:
        masked, _ = env.reset()
        screen, info = twin.reset()
        rng = np.random.default_rng(0)
        hidden_total = 0
        for step in range(40):
            hidden = np.asarray(hidden_pixels(game, info["ram"], classes))
            expected = np.where(hidden[..., None], 0, np.asarray(screen))
            assert np.array_equal(np.asarray(masked), expected), f"step {step}"
            hidden_total += int((np.asarray(screen)[hidden] != 0).sum())
            actions = rng.integers(0, env.num_actions, 2)
            masked, *_ = env.step(actions)
            screen, *_, info = twin.step(actions)
        assert hidden_total > 0  # something visible was hidden


def test_hiding_objects_per_frame_is_seed_exact_across_worker_splits_and_follows_drift():
    cfg = Config(drift=ConceptDrift("cyclic", 3, hide(("Ball", "Player"), 0.5)),
                 granularity="frame")
    runs = []
    for split in (dict(num_workers=0), dict(num_workers=1, inline_envs=1)):
        with stori_jax.make("Breakout", config=cfg, num_envs=3, seed=4, **split) as env:
            obs, info = env.reset()
            trace = [np.asarray(obs)]
            for _ in range(9):
                obs, *_, info = env.step([1, 2, 3])
                trace.append(np.asarray(obs))
                # concept 1 (the default game) hides nothing
                assert not np.asarray(info["obs_masked"])[np.asarray(info["concept"]) == 0].any()
            runs.append(np.stack(trace))
    assert np.array_equal(runs[0], runs[1])


ONE = dict(num_envs=1, seed=0)


def test_object_bad_input_names_the_allowed_values():
    with pytest.raises(ValueError, match=r"Breakout has no object class 'Brick': its classes "
                                         r"are \['Player', 'Ball', 'Block'\]"):
        stori_jax.make("Breakout", config=hide(("Brick",)), **ONE)
    with pytest.raises(ValueError, match=r"Robotank has no object table .* the games with "
                                         r"objects are \[.*'Breakout'"):
        stori_jax.make("Robotank", config=hide(("Ball",)), **ONE)
    with pytest.raises(ValueError, match=r"obs='objects': Robotank has no object table"):
        stori_jax.make("Robotank", obs="objects", **ONE)
    with pytest.raises(ValueError, match=r"classes must name the object classes"):
        ObservationMask("objects", 1, 0.5)
    with pytest.raises(ValueError, match=r"classes applies to kind 'objects' only"):
        ObservationMask("crop", 1, 0.5, classes=("Ball",))
    with pytest.raises(ValueError, match=r"obs='objects' cannot show an observation mask"):
        stori_jax.make("Breakout", "3.2A", obs="objects", **ONE)
    with pytest.raises(ValueError, match=r"hidden objects need the RAM"):
        stori_jax.make("Breakout", config=hide(("Ball",)), backend="envpool", autoreset=False,
                       granularity="step", **ONE)
