"""Every bad input raises ValueError, and the message names the field and the allowed values."""

from __future__ import annotations

import math
import re

import jax
import numpy as np
import pytest

from stori_jax import functional as F
from stori_jax import (ActionNoise, Config, ConceptDrift, ObservationMask, RandomEvent,
                       config_from_reference, get_game, preset)
from stori_jax.checks import check_probability

STORI = "['Breakout', 'Boxing', 'Gopher', 'BankHeist']"
SPEC_MODE_COUNTS = {  # blackout, RAM, event modes (docs/spec.md sections 5-8)
    "Breakout": (11, 2, 3), "Boxing": (9, 3, 3), "Gopher": (18, 5, 3), "BankHeist": (10, 6, 4),
}
SECONDARY = re.escape("['1', '2.1', '3.2']")
PROB = re.escape("[0, 1]")


def allowed(n):
    return re.escape(str(list(range(1, n + 1))))


# -- games -------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["Pacman2000", "breakout2", "Bank Heist"])
def test_unknown_game(name):
    msg = rf"unknown game '{re.escape(name)}': allowed are the STORI games {re.escape(STORI)}"
    with pytest.raises(ValueError, match=msg):
        get_game(name)
    with pytest.raises(ValueError, match=msg):
        Config(game=name)
    with pytest.raises(ValueError, match=msg):
        preset("Breakout", "1").for_game(name)


@pytest.mark.parametrize("name", ["", None, 3])
def test_game_not_a_string(name):
    with pytest.raises(ValueError, match=r"game must be a non-empty string"):
        get_game(name)


def test_game_aliases():
    assert get_game("bank_heist") is get_game("BankHeist") is get_game("bankheist")
    assert get_game("Pong").num_actions == 6  # any ale-py game: game-agnostic modes only
    # one spec per game, however it is spelled, named from its ROM id
    assert get_game("pong") is get_game("Pong") and get_game("Pong").name == "Pong"
    assert get_game("space_invaders") is get_game("SpaceInvaders")
    assert get_game("space_invaders").name == "SpaceInvaders"
    with pytest.raises(ValueError, match=r"game must be a non-empty string, got \['Pong'\]"):
        get_game(["Pong"])


# -- game-specific modes -----------------------------------------------------------------------

@pytest.mark.parametrize("game", list(SPEC_MODE_COUNTS))
def test_unknown_blackout_ram_event_mode(game):
    n_blackout, n_ram, n_event = SPEC_MODE_COUNTS[game]
    for kind, n, what in (("blackout", n_blackout, "blackout modes"),
                          ("ram", n_ram, "RAM observation modes")):
        config = Config(observation=ObservationMask(kind, n + 1))
        for mode in (n, 1):  # the last and the first mode are fine
            Config(observation=ObservationMask(kind, mode), game=game)
        msg = (rf"Config\.observation\.mode {n + 1} is not one of {game}'s {what}: "
               rf"allowed {allowed(n)}")
        with pytest.raises(ValueError, match=msg):
            config.for_game(game)
        with pytest.raises(ValueError, match=msg):
            get_game(game).validate(config)
        drifted = Config(drift=ConceptDrift("sudden", 5, config))
        with pytest.raises(ValueError, match=r"Config\.drift\.secondary\.observation\.mode "
                                             rf"{n + 1} is not one of {game}'s {what}: "
                                             rf"allowed {allowed(n)}"):
            drifted.for_game(game)
        with pytest.raises(ValueError, match=rf"ObservationMask\.mode 0 is the spec's 'none' "
                                             rf"for kind '{kind}': leave the mask out"):
            ObservationMask(kind, 0)
        with pytest.raises(ValueError, match=rf"ObservationMask\.mode must be >= 1 for kind "
                                             rf"'{kind}', got -1"):
            ObservationMask(kind, -1)
    Config(event=RandomEvent(n_event, 0.1), game=game)
    with pytest.raises(ValueError, match=rf"Config\.event\.mode {n_event + 1} is not one of "
                                         rf"{game}'s event modes: allowed {allowed(n_event)}"):
        Config(event=RandomEvent(n_event + 1, 0.1), game=game)
    with pytest.raises(ValueError, match=r"Config\.drift\.secondary\.event\.mode"):
        Config(drift=ConceptDrift("cyclic", 5, Config(event=RandomEvent(n_event + 1, 0.1))),
               game=game)
    with pytest.raises(ValueError, match=r"RandomEvent\.mode must be >= 1"):
        RandomEvent(0, 0.1)


def test_modes_on_a_non_stori_game():
    Config(observation=ObservationMask("crop", 5), game="Pong")
    Config(action_noise=ActionNoise(0.3), game="Pong")
    with pytest.raises(ValueError, match=r"Config\.observation\.mode: Pong has no blackout modes"):
        Config(observation=ObservationMask("blackout", 1), game="Pong")
    with pytest.raises(ValueError, match=r"Config\.event\.mode: Pong has no event modes"):
        Config(event=RandomEvent(1, 0.5), game="Pong")


def test_mode_0_none_says_to_leave_the_mask_out():
    with pytest.raises(ValueError, match=r"mode 0 is the spec's 'none' for kind 'crop'"):
        ObservationMask("crop", 0)
    with pytest.raises(ValueError, match=r"mode 0 is the spec's 'none' for kind 'blackout'"):
        ObservationMask("blackout", 0, 1.0)


@pytest.mark.parametrize("kind", ["crop", "blackout", "ram"])
def test_reference_mode_0_is_the_specs_none(kind):
    """A reference '3.2' config of mode '0' hides nothing: it loads as the default game (3.1),
    its type and prob still checked; as a 2.2 secondary it is refused (3.1 is no secondary)."""
    for game in ("Breakout", "Boxing", "Gopher", "BankHeist", None):
        config = config_from_reference({"stochasticity_type": "3.2", "partial_observation": {
            "type": kind, "mode": "0", "prob": 0.5}}, game=game)
        assert config == Config(game=game) and config.type == "3.1"
    with pytest.raises(ValueError, match=r"'partial_observation\.prob': ObservationMask\.prob "
                                         rf"must be in {PROB}, got 1\.5"):
        config_from_reference({"stochasticity_type": "3.2", "partial_observation": {
            "type": kind, "mode": "0", "prob": 1.5}})
    with pytest.raises(ValueError, match=r"'partial_observation\.type' must be one of"):
        config_from_reference({"stochasticity_type": "3.2", "partial_observation": {
            "type": kind.upper(), "mode": "0"}})
    with pytest.raises(ValueError, match=r"'partial_observation\.mode' '0' is the spec's 'none': "
                                         r"as the secondary concept of a '2\.2' config it would "
                                         r"make concept 2 the default game \(3\.1\)"):
        config_from_reference(drift_ref(**{"partial_observation.type": kind,
                                           "partial_observation.mode": "0"}))


@pytest.mark.parametrize("mode", [6, -1])
def test_unknown_crop_mode(mode):
    with pytest.raises(ValueError, match=r"ObservationMask\.mode \(crop\) must be one of "
                                         rf"{re.escape('[1, 2, 3, 4, 5]')}, got {mode}"):
        ObservationMask("crop", mode)


@pytest.mark.parametrize("mode", ["1", 1.0, True, None])
def test_mode_not_an_int(mode):
    with pytest.raises(ValueError, match=r"ObservationMask\.mode must be an int"):
        ObservationMask("blackout", mode)
    with pytest.raises(ValueError, match=r"RandomEvent\.mode must be an int"):
        RandomEvent(mode, 0.5)


@pytest.mark.parametrize("kind", ["hide", "Crop", "", None])
def test_unknown_kind(kind):
    with pytest.raises(ValueError, match=r"ObservationMask\.kind must be one of "
                                         rf"{re.escape(str(['crop', 'blackout', 'ram', 'objects']))}, "
                                         rf"got {re.escape(repr(kind))}"):
        ObservationMask(kind, 1)


# -- probabilities -----------------------------------------------------------------------------

PROB_OWNERS = [
    ("ActionNoise", lambda p: ActionNoise(p)),
    ("RandomEvent", lambda p: RandomEvent(1, p)),
    ("ObservationMask", lambda p: ObservationMask("crop", 1, p)),
]


@pytest.mark.parametrize("owner,make", PROB_OWNERS, ids=[o for o, _ in PROB_OWNERS])
@pytest.mark.parametrize("p", [-0.1, 1.0001, 2, -1e-9, math.inf, -math.inf, math.nan])
def test_probability_outside_unit_interval(owner, make, p):
    with pytest.raises(ValueError, match=rf"{owner}\.prob must be in {PROB}, got "):
        make(p)


@pytest.mark.parametrize("owner,make", PROB_OWNERS, ids=[o for o, _ in PROB_OWNERS])
@pytest.mark.parametrize("p", ["0.3", None, True, [0.3], 1j])
def test_probability_not_a_number(owner, make, p):
    with pytest.raises(ValueError, match=rf"{owner}\.prob must be a number in {PROB}, got "
                                         rf"{re.escape(repr(p))}"):
        make(p)


@pytest.mark.parametrize("owner,make", PROB_OWNERS, ids=[o for o, _ in PROB_OWNERS])
def test_probability_bounds_are_allowed(owner, make):
    for p in (0, 0.0, 1, 1.0, 0.5):
        assert make(p).prob == float(p) and isinstance(make(p).prob, float)


def test_numpy_scalars_are_accepted_and_stored_as_python_numbers():
    noise = ActionNoise(np.float32(0.25), replacement_actions=np.arange(2))
    assert noise.prob == 0.25 and noise.replacement_actions == (0, 1)
    assert type(noise.replacement_actions[0]) is int
    mask = ObservationMask("crop", np.int64(5), np.float64(0.5))
    assert (mask.mode, mask.prob) == (5, 0.5) and type(mask.mode) is int
    assert RandomEvent(np.int32(1), 1).mode == 1
    drift = ConceptDrift("sudden", np.int64(7), SECONDARY_OK)
    assert drift.period == 7 and type(drift.period) is int


def test_a_huge_probability_or_a_non_sequence_of_actions_is_a_clear_error():
    with pytest.raises(ValueError, match=r"ActionNoise\.prob must be in \[0, 1\]"):
        ActionNoise(10**400)
    with pytest.raises(ValueError, match=r"replacement_actions must be a non-empty tuple .*got 3"):
        ActionNoise(0.3, replacement_actions=3)


def test_a_float32_probability_is_the_config_written_as_a_literal():
    """np.float32(0.3) is recorded as 0.3 (it was 0.30000001192092896, so a snapshot of one
    refused to restore into the other, and an event drawn in float64 fired a hair more often);
    a float32 whose shortest decimal rounds to another float32 keeps its exact value."""
    import jax.numpy as jnp

    for value in (np.float32(0.3), jnp.float32(0.3), np.array(0.3, np.float32)):
        assert ActionNoise(value) == ActionNoise(0.3) and ActionNoise(value).prob == 0.3
        assert ObservationMask("crop", 1, value).prob == 0.3
        assert RandomEvent(1, value).prob == 0.3
    assert ActionNoise(np.float32(1e-6)).prob == 1e-6 and ActionNoise(np.float32(1.0)).prob == 1.0
    assert ActionNoise(np.float16(0.3)).prob == float(np.float16(0.3))  # exact: 0.2998046875
    rare = np.array([0x15ae43fd], np.uint32).view(np.float32)[0]  # its decimal rounds up
    assert np.float32(check_probability("p", rare)) == rare  # (too rare to draw: 7e-26)
    assert ActionNoise(np.float64(0.1 + 0.2)).prob == 0.1 + 0.2  # float64: as given


@pytest.mark.parametrize("make", [
    lambda p: ActionNoise(p), lambda p: RandomEvent(1, p), lambda p: ObservationMask("crop", 1, p),
    lambda p: F.draw_mask_decisions(F.env_keys(jax.random.PRNGKey(0), 2), prob=p, per_frame=True,
                                    torch=False),
    lambda p: F.corrupt_actions(F.env_keys(jax.random.PRNGKey(0), 2), [0, 1], [0, 0], prob=p,
                                num_slots=1, replacement=(0, 1))])
def test_a_probability_below_the_draws_resolution_is_refused(make):
    """The draws are float32 uniforms, multiples of 2**-23: p = 1e-12 fired at 2**-23 (~1.2e-7),
    100,000 times as often as asked (the review's seed 674889 fired a p = 1e-12 event on the
    first frame)."""
    with pytest.raises(ValueError, match=r"prob must be 0 or in \[2\*\*-23, 1\] .*got 1e-12"):
        make(1e-12)
    make(0.0), make(2.0**-23), make(np.float32(1e-6))  # taken: 0 never fires, 2**-23 is a draw
    u = F.event_uniforms(F.env_keys(jax.random.PRNGKey(0), 4096), 4)
    assert (np.asarray(u) * 2**23 == np.round(np.asarray(u) * 2**23)).all()  # the resolution


def test_a_replacement_action_named_twice_is_refused():
    """A repeat would weigh the uniform draw (0 twice as often as 1 below)."""
    with pytest.raises(ValueError, match=r"ActionNoise\.replacement_actions must name each "
                                         r"action once, got \(0, 0, 1\)"):
        ActionNoise(0.3, replacement_actions=(0, 0, 1))
    assert ActionNoise(0.3, replacement_actions=[1, 0]).replacement_actions == (1, 0)


# -- concept drift -----------------------------------------------------------------------------

SECONDARY_OK = Config(action_noise=ActionNoise(0.3))


@pytest.mark.parametrize("period", [0, -1, -600])
def test_period_below_one(period):
    with pytest.raises(ValueError, match=rf"ConceptDrift\.period \(T\) must be >= 1 agent step, "
                                         rf"got {period}"):
        ConceptDrift("sudden", period, SECONDARY_OK)


@pytest.mark.parametrize("period", [1.5, 300.0, "300", True, None])
def test_period_not_an_int(period):
    with pytest.raises(ValueError, match=r"ConceptDrift\.period must be an int"):
        ConceptDrift("sudden", period, SECONDARY_OK)


@pytest.mark.parametrize("schedule", ["linear", "Sudden", "", None])
def test_unknown_schedule(schedule):
    with pytest.raises(ValueError, match=r"ConceptDrift\.schedule must be one of "
                                         rf"{re.escape(str(['sudden', 'cyclic', 'gradual']))}"):
        ConceptDrift(schedule, 10, SECONDARY_OK)


def test_drift_inside_drift():
    inner = Config(drift=ConceptDrift("sudden", 10, SECONDARY_OK))
    with pytest.raises(ValueError, match=r"ConceptDrift\.secondary cannot itself be a 2\.2 concept "
                                         rf"drift \(allowed secondary types: {SECONDARY}\)"):
        ConceptDrift("cyclic", 10, inner)


def test_default_as_secondary():
    with pytest.raises(ValueError, match=rf"ConceptDrift\.secondary must be of type {SECONDARY}, "
                                         r"got type '3\.1'"):
        ConceptDrift("sudden", 10, Config())
    with pytest.raises(ValueError, match=rf"ConceptDrift\.secondary must be of type {SECONDARY}, "
                                         r"got type '0'"):
        ConceptDrift("sudden", 10, Config(ram_observation=True))
    with pytest.raises(ValueError, match=rf"ConceptDrift\.secondary must be a Config of type "
                                         rf"{SECONDARY}"):
        ConceptDrift("sudden", 10, ActionNoise(0.3))
    for ok in (SECONDARY_OK, Config(event=RandomEvent(1, 0.1)),
               Config(observation=ObservationMask("crop", 5))):
        assert Config(drift=ConceptDrift("gradual", 3, ok)).type == "2.2"


def test_part_in_both_places():
    with pytest.raises(ValueError, match=r"Config\.action_noise is set both directly and in "
                                         r"drift\.secondary"):
        Config(action_noise=ActionNoise(0.1), drift=ConceptDrift("sudden", 5, SECONDARY_OK))


def test_secondary_settings_that_would_be_ignored():
    """Concept 2 cannot carry its own granularity or another game: nothing is silently dropped."""
    with pytest.raises(ValueError, match=r"Config\.drift\.secondary\.granularity 'step' is not "
                                         r"used: .* Config\.granularity \('frame'\)"):
        Config(drift=ConceptDrift("sudden", 5, Config(event=RandomEvent(1, 0.1),
                                                      granularity="step")))
    same = Config(drift=ConceptDrift("sudden", 5, Config(event=RandomEvent(1, 0.1),
                                                         granularity="step")), granularity="step")
    assert same.granularity == "step"
    boxing_secondary = Config(action_noise=ActionNoise(0.3), game="Boxing")
    with pytest.raises(ValueError, match=r"Config\.drift\.secondary is bound to game 'Boxing' "
                                         r"but Config\.game is 'BankHeist'"):
        Config(drift=ConceptDrift("sudden", 5, boxing_secondary), game="BankHeist")
    unbound = Config(drift=ConceptDrift("sudden", 5, boxing_secondary))
    with pytest.raises(ValueError, match=r"bound to game 'Boxing' but Config\.game is 'Gopher'"):
        unbound.for_game("Gopher")
    assert unbound.for_game("boxing").game == "Boxing"  # one spelling of each game


# -- type 0, config fields ---------------------------------------------------------------------

def test_type0_with_a_mask():
    with pytest.raises(ValueError, match=r"Config\.ram_observation \(type 0\) .* cannot be "
                                         r"combined with an observation mask \(type 3\.2\)"):
        Config(ram_observation=True, observation=ObservationMask("crop", 1))
    drifted_mask = ConceptDrift("sudden", 1, Config(observation=ObservationMask("blackout", 6)))
    with pytest.raises(ValueError, match=r"Config\.ram_observation \(type 0\) .* cannot be "
                                         r"combined with an observation mask \(type 3\.2\) in "
                                         r"drift\.secondary"):
        Config(ram_observation=True, drift=drifted_mask)
    assert Config(ram_observation=True).type == "0"
    with pytest.raises(ValueError, match=r"Config\.ram_observation must be True or False"):
        Config(ram_observation=1)


def test_config_fields():
    with pytest.raises(ValueError, match=r"Config\.granularity must be one of "
                                         rf"{re.escape(str(['frame', 'step']))}, got 'agent'"):
        Config(granularity="agent")
    with pytest.raises(ValueError, match=r"Config\.type must be one of "
                                         + re.escape("['0', '1', '2.1', '2.2', '3.1', '3.2', "
                                                     "'mixed']")):
        Config(type="9")
    with pytest.raises(ValueError, match=r"Config\.type '1' does not match its parts, which make "
                                         r"type '3\.1'"):
        Config(type="1")
    assert Config(type="1", action_noise=ActionNoise(0.1)).type == "1"
    with pytest.raises(ValueError, match=r"Config\.action_noise must be a ActionNoise or None"):
        Config(action_noise=0.3)
    with pytest.raises(ValueError, match=r"Config\.observation must be a ObservationMask or None"):
        Config(observation=RandomEvent(1, 0.5))


def test_action_noise_fields():
    with pytest.raises(ValueError, match=r"ActionNoise\.sticky must be True or False"):
        ActionNoise(0.3, sticky=1)
    for bad in ((), (-1,), (1, True), ("1",)):
        with pytest.raises(ValueError, match=r"ActionNoise\.replacement_actions must be a "
                                             r"non-empty tuple of action indices >= 0"):
            ActionNoise(0.3, replacement_actions=bad)
    with pytest.raises(ValueError, match=r"ActionNoise\.replacement_actions cannot be combined "
                                         r"with sticky=True"):
        ActionNoise(0.3, replacement_actions=(1,), sticky=True)
    with pytest.raises(ValueError, match=r"Config\.action_noise\.replacement_actions \[18\] out of "
                                         r"range: Boxing has actions 0\.\.17"):
        Config(action_noise=ActionNoise(0.3, replacement_actions=(0, 18)), game="Boxing")
    assert ActionNoise(0.3, replacement_actions=[3, 1]).replacement_actions == (3, 1)


# -- the reference format ----------------------------------------------------------------------

IS = "intrinsic_stochasticity"
DRIFT = f"{IS}.action_independent_concept_drift"


def ref(stype, **flat):
    return {"stochasticity_type": stype, **{k.replace("__", "."): v for k, v in flat.items()}}


def drift_ref(**override):
    d = {"stochasticity_type": "2.2", f"{DRIFT}.temporal_mode": "sudden",
         f"{DRIFT}.temporal_threshold": 300, f"{DRIFT}.secondary_concept_type": "3.2",
         "partial_observation.type": "blackout", "partial_observation.mode": "10",
         "partial_observation.prob": 1.0}
    d.update(override)
    return {k: v for k, v in d.items() if v is not ...}


@pytest.mark.parametrize("d", [None, [("stochasticity_type", "1")], "3.1", 3.1])
def test_reference_not_a_dict(d):
    with pytest.raises(ValueError, match=r"reference config must be a dict"):
        config_from_reference(d)


@pytest.mark.parametrize("stype", ["0", "4", "2.3", "3.2A", "", None])
def test_reference_bad_type(stype):
    with pytest.raises(ValueError, match=r"'stochasticity_type' must be one of "
                                         + re.escape("['1', '2.1', '2.2', '3.1', '3.2']")):
        config_from_reference({"stochasticity_type": stype})


@pytest.mark.parametrize("d,missing", [
    ({}, "stochasticity_type"),
    ({"stochasticity_type": "1"}, f"{IS}.action_dependent.stochastic_action_prob"),
    ({"stochasticity_type": "2.1", f"{IS}.action_independent_random.random_stochasticity_prob":
      0.1}, f"{IS}.action_independent_random.mode"),
    ({"stochasticity_type": "2.1", f"{IS}.action_independent_random.mode": "1"},
     f"{IS}.action_independent_random.random_stochasticity_prob"),
    ({"stochasticity_type": "3.2", "partial_observation.mode": "1"}, "partial_observation.type"),
    ({"stochasticity_type": "3.2", "partial_observation.type": "crop"},
     "partial_observation.mode"),
    (drift_ref(**{f"{DRIFT}.temporal_mode": ...}), f"{DRIFT}.temporal_mode"),
    (drift_ref(**{f"{DRIFT}.temporal_threshold": ...}), f"{DRIFT}.temporal_threshold"),
    (drift_ref(**{f"{DRIFT}.secondary_concept_type": ...}), f"{DRIFT}.secondary_concept_type"),
    (drift_ref(**{"partial_observation.type": ...}), "partial_observation.type"),
])
def test_reference_missing_key(d, missing):
    with pytest.raises(ValueError, match=rf"reference config is missing '{re.escape(missing)}'"):
        config_from_reference(d)
    nested = {}
    for key, value in d.items():  # the same dict, nested
        *path, last = key.split(".")
        node = nested
        for p in path:
            node = node.setdefault(p, {})
        node[last] = value
    with pytest.raises(ValueError, match=rf"reference config is missing '{re.escape(missing)}'"):
        config_from_reference(nested)


def test_reference_mask_prob_is_the_one_optional_value():
    """A left-out partial_observation.prob is ObservationMask's default, 1.0 (as documented);
    every other value the type reads is required (test_reference_missing_key)."""
    loaded = config_from_reference({"stochasticity_type": "3.2", "partial_observation.type":
                                    "blackout", "partial_observation.mode": "10"},
                                   game="BankHeist")
    assert loaded.observation == ObservationMask("blackout", 10, 1.0)


@pytest.mark.parametrize("key,value,what", [
    (f"{IS}.action_dependent.stochastic_action_prob", "abc", "a probability"),
    (f"{IS}.action_dependent.stochastic_action_prob", None, "a probability"),
    (f"{IS}.action_dependent.stochastic_action_prob", [0.3], "a probability"),
    (f"{IS}.action_dependent.stochastic_action_prob", True, "a probability"),
])
def test_reference_bad_value_type1(key, value, what):
    with pytest.raises(ValueError, match=rf"reference config '{re.escape(key)}' must be "
                                         rf"{what}, got {re.escape(repr(value))}"):
        config_from_reference({"stochasticity_type": "1", key: value})


@pytest.mark.parametrize("mode", ["x", "1.5", "", None, True, 2.5])
def test_reference_bad_mode(mode):
    key = f"{IS}.action_independent_random.mode"
    with pytest.raises(ValueError, match=rf"reference config '{re.escape(key)}' must be an "
                                         r"event mode"):
        config_from_reference({"stochasticity_type": "2.1", key: mode,
                               f"{IS}.action_independent_random.random_stochasticity_prob": 0.1})
    with pytest.raises(ValueError, match=r"reference config 'partial_observation\.mode' must be "
                                         r"a mode"):
        config_from_reference({"stochasticity_type": "3.2", "partial_observation.type": "crop",
                               "partial_observation.mode": mode})


@pytest.mark.parametrize("threshold", ["abc", "1.5", 300.5, None, True])
def test_reference_bad_threshold(threshold):
    with pytest.raises(ValueError, match=rf"reference config '{re.escape(DRIFT)}"
                                         r"\.temporal_threshold' must be an int number of agent "
                                         rf"steps, got {re.escape(repr(threshold))}"):
        config_from_reference(drift_ref(**{f"{DRIFT}.temporal_threshold": threshold}))


def test_reference_threshold_accepts_integral_values():
    for t in (300, "300", 300.0, " 300 "):
        config = config_from_reference(drift_ref(**{f"{DRIFT}.temporal_threshold": t}))
        assert config.drift.period == 300


@pytest.mark.parametrize("secondary", ["2.2", "3.1", "0", "4", ""])
def test_reference_bad_secondary(secondary):
    with pytest.raises(ValueError, match=rf"{re.escape(DRIFT)}\.secondary_concept_type' must be "
                                         rf"one of {SECONDARY}, got '{re.escape(secondary)}'"):
        config_from_reference(drift_ref(**{f"{DRIFT}.secondary_concept_type": secondary}))


def test_reference_values_checked_by_config():
    """Errors name the key the user wrote (and the Config field that checked it)."""
    threshold = re.escape(f"'{DRIFT}.temporal_threshold': ")
    with pytest.raises(ValueError, match=threshold + r"ConceptDrift\.period \(T\) must be >= 1"):
        config_from_reference(drift_ref(**{f"{DRIFT}.temporal_threshold": 0}))
    with pytest.raises(ValueError, match=threshold + r"ConceptDrift\.period \(T\) must be <= "
                                         r"2147483647 agent steps, got 3000000000"):
        config_from_reference(drift_ref(**{f"{DRIFT}.temporal_threshold": 3_000_000_000}))
    with pytest.raises(ValueError, match=re.escape(
            f"'{DRIFT}.temporal_mode' must be one of ['sudden', 'cyclic', 'gradual'], "
            "got 'Sudden'")):
        config_from_reference(drift_ref(**{f"{DRIFT}.temporal_mode": "Sudden"}))
    with pytest.raises(ValueError, match=re.escape(f"'{IS}.action_dependent.stochastic_action_prob"
                                                   "': ") + rf"ActionNoise\.prob must be in "
                                         rf"{PROB}, got 1\.5"):
        config_from_reference(ref("1", **{f"{IS}.action_dependent.stochastic_action_prob": 1.5}))
    with pytest.raises(ValueError, match=r"'partial_observation\.type' must be one of \['crop', "
                                         r"'blackout', 'ram'\], got 'hide'"):
        config_from_reference(ref("3.2", partial_observation__type="hide",
                                  partial_observation__mode="1"))
    with pytest.raises(ValueError, match=r"ObservationMask\.mode \(crop\) must be one of"):
        config_from_reference(ref("3.2", partial_observation__type="crop",
                                  partial_observation__mode="6"))
    with pytest.raises(ValueError, match=r"Config\.observation\.mode 12 is not one of Breakout's "
                                         rf"blackout modes: allowed {allowed(11)}"):
        config_from_reference(ref("3.2", partial_observation__type="blackout",
                                  partial_observation__mode="12"), game="Breakout")
    with pytest.raises(ValueError, match=r"Config\.drift\.secondary\.observation\.mode 12"):
        config_from_reference(drift_ref(**{"partial_observation.mode": "12"}), game="Breakout")
    with pytest.raises(ValueError, match=r"unknown game 'Nope'"):
        config_from_reference(ref("3.1"), game="Nope")


def test_a_game_is_named_one_way_however_it_is_spelled():
    assert Config(game="breakout").game == "Breakout"
    assert Config(game="BREAKOUT") == Config(game="Breakout")
    reference = {"stochasticity_type": "1",
                 "intrinsic_stochasticity": {"action_dependent": {"stochastic_action_prob": 0.3}}}
    assert config_from_reference(reference, game="bankheist") == preset("BankHeist", "1")


def test_zero_dimensional_arrays_are_numbers():
    """A sweep over np/jnp values works: 0-d numeric arrays are their scalar; others refused."""
    import jax
    import jax.numpy as jnp

    assert ActionNoise(jnp.float32(0.25)).prob == 0.25
    assert ActionNoise(np.array(0.5)).prob == 0.5
    assert ConceptDrift("sudden", jnp.int32(5), Config(event=RandomEvent(1, 0.1))).period == 5
    for bad in (jnp.array([0.3]), np.array(True), np.array("0.3")):
        with pytest.raises(ValueError, match="ActionNoise.prob must be a number in"):
            ActionNoise(bad)
    with pytest.raises(ValueError, match="ActionNoise.prob must be a number in"):
        ActionNoise(jax.random.key(0))  # a typed key is 0-d too, and no number
    with pytest.raises(ValueError, match="ActionNoise.prob must be a number in"):
        jax.jit(lambda p: ActionNoise(p).prob)(0.3)  # traced: no number yet


def test_a_drift_period_beyond_int32_is_refused_at_construction():
    """Episode steps are int32: T = 2**31 used to pass and fail at the first step inside JAX."""
    with pytest.raises(ValueError, match=r"ConceptDrift\.period \(T\) must be <= 2147483647 "
                                         r"agent steps, got 2147483648"):
        ConceptDrift("sudden", 2**31, Config(action_noise=ActionNoise(0.1)))
    assert ConceptDrift("sudden", 2**31 - 1, Config(action_noise=ActionNoise(0.1))).period \
        == 2**31 - 1


def test_reference_bad_event_probability_names_its_own_key():
    """A 2.1 config's bad probability is named by the key the user wrote (the event's), not
    the action-corruption key the loader shares code with."""
    key = f"{IS}.action_independent_random.random_stochasticity_prob"
    with pytest.raises(ValueError, match=re.escape(f"reference config '{key}': RandomEvent.prob")):
        config_from_reference({"stochasticity_type": "2.1",
                               f"{IS}.action_independent_random.mode": "1", key: 1.5})


# -- from a bad-input walk-through ----------------------------------------------------------------

CHOICE_FIELDS = [  # (owner, field, value, part made with that value)
    ("ObservationMask", "kind", "crop", lambda v: ObservationMask(v, 1)),
    ("ConceptDrift", "schedule", "sudden",
     lambda v: ConceptDrift(v, 3, Config(action_noise=ActionNoise(0.1)))),
    ("Config", "granularity", "step", lambda v: Config(granularity=v)),
]


@pytest.mark.parametrize("owner, field, value, make_part", CHOICE_FIELDS)
def test_a_choice_is_a_string_not_an_array_that_equals_one(owner, field, value, make_part):
    """A one-element array equals its string but is unhashable: refused up front, not inside
    jit; numpy's str_ is taken and stored as a plain str."""
    part = make_part(np.str_(value))
    assert type(getattr(part, field)) is str and getattr(part, field) == value
    hash(part)
    with pytest.raises(ValueError, match=rf"{owner}\.{field} must be one of .*, got array\("):
        make_part(np.array([value]))


@pytest.mark.parametrize("value", [0, None, False, [], 3.1])
def test_config_type_given_must_be_a_type_name(value):
    with pytest.raises(ValueError, match=r"Config\.type must be one of \['0', '1', '2\.1', '2\.2', "
                                         rf"'3\.1', '3\.2', 'mixed'\] \(or left out\), got "
                                         rf"{re.escape(repr(value))}"):
        Config(action_noise=ActionNoise(0.3), type=value)


@pytest.mark.parametrize("value", [{0: "a", 1: "b"}, {1, 2}, frozenset({1}), "01"])
def test_replacement_actions_are_a_sequence(value):
    with pytest.raises(ValueError, match=r"replacement_actions must be a non-empty tuple"):
        ActionNoise(0.3, value)


def test_reference_numbers_as_the_config_takes_them():
    """numpy ints are counts, a float32 probability keeps the value a preset gives it, and a
    number too large for a float is a named error (it was an OverflowError)."""
    prob_key = f"{IS}.action_dependent.stochastic_action_prob"
    for prob in (np.float32(0.3), np.float64(0.3), "0.3"):
        assert config_from_reference(ref("1", **{prob_key: prob}), game="Breakout") \
            == preset("Breakout", "1")
    for threshold in (np.int64(300), np.int32(300), np.float64(300.0)):
        assert config_from_reference(drift_ref(**{f"{DRIFT}.temporal_threshold": threshold})
                                     ).drift.period == 300
    with pytest.raises(ValueError, match=re.escape(f"'{prob_key}': ActionNoise.prob must be in "
                                                   "[0, 1], got 1000") + r".*\(401 characters\)"):
        config_from_reference(ref("1", **{prob_key: 10**400}))
    with pytest.raises(ValueError, match=r"temporal_threshold': ConceptDrift\.period \(T\) must be "
                                         r"<= 2147483647 agent steps, got 1000.*\(401 characters\)"):
        config_from_reference(drift_ref(**{f"{DRIFT}.temporal_threshold": 10**400}))
    with pytest.raises(ValueError, match=r"temporal_threshold' must be an int number of agent "
                                         r"steps, got inf"):
        config_from_reference(drift_ref(**{f"{DRIFT}.temporal_threshold": 1e400}))
