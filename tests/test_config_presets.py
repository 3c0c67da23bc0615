"""The paper's 24 presets (docs/spec.md section 10) and the reference configuration format."""

from __future__ import annotations

import pytest

from stori_jax import (ActionNoise, Config, ConceptDrift, ObservationMask, RandomEvent,
                       describe_preset, get_game, list_presets, preset)
from stori_jax.reference_format import config_from_reference

# ---------------------------------------------------------------------------------------------
# docs/spec.md section 10, typed in: (game, name, definition in the spec's words, parts)
# ---------------------------------------------------------------------------------------------


def _noise(p):
    return {"action_noise": ActionNoise(prob=p)}


def _event(mode, p):
    return {"event": RandomEvent(mode=mode, prob=p)}


def _mask(kind, mode, p):
    return {"observation": ObservationMask(kind=kind, mode=mode, prob=p)}


def _drift(schedule, period, secondary_parts):
    return {"drift": ConceptDrift(schedule=schedule, period=period,
                                  secondary=Config(**secondary_parts))}


SPEC_PRESETS = [
    ("Breakout", "1", "type 1, p = 0.3", _noise(0.3), "1"),
    ("Breakout", "2.1", "event mode 2 (block-hit cancel, reward 0), p = 0.25", _event(2, 0.25),
     "2.1"),
    ("Breakout", "2.2", "sudden drift at T = 300 to 3.2A",
     _drift("sudden", 300, _mask("blackout", 10, 1.0)), "2.2"),
    ("Breakout", "3.1", "default", {}, "3.1"),
    ("Breakout", "3.2A", "blackout mode 10, p = 1.0", _mask("blackout", 10, 1.0), "3.2"),
    ("Breakout", "3.2B", "crop mode 1 (left half), p = 0.75", _mask("crop", 1, 0.75), "3.2"),
    ("Breakout", "3.2C", "crop mode 5 (torch), p = 1.0", _mask("crop", 5, 1.0), "3.2"),
    ("Boxing", "1", "type 1, p = 0.3", _noise(0.3), "1"),
    ("Boxing", "2.1", "event mode 1 (colour flip), p = 0.001", _event(1, 0.001), "2.1"),
    ("Boxing", "2.2", "sudden drift at T = 300 to 3.2C",
     _drift("sudden", 300, _mask("ram", 2, 0.7)), "2.2"),
    ("Boxing", "3.1", "default", {}, "3.1"),
    ("Boxing", "3.2A", "blackout mode 9 (scores + clock), p = 1.0", _mask("blackout", 9, 1.0),
     "3.2"),
    ("Boxing", "3.2B", "crop mode 2 (right half), p = 0.75", _mask("crop", 2, 0.75), "3.2"),
    ("Boxing", "3.2C", "RAM mode 2 (hide enemy), p = 0.7", _mask("ram", 2, 0.7), "3.2"),
    ("Gopher", "1", "type 1, p = 0.3", _noise(0.3), "1"),
    ("Gopher", "2.1", "event mode 2 (hole stays open, reward 0), p = 0.3", _event(2, 0.3), "2.1"),
    ("Gopher", "2.2", "cyclic drift, T = 600, to 3.2",
     _drift("cyclic", 600, _mask("blackout", 6, 1.0)), "2.2"),
    ("Gopher", "3.1", "default", {}, "3.1"),
    ("Gopher", "3.2", "blackout mode 6 (underground offset), p = 1.0", _mask("blackout", 6, 1.0),
     "3.2"),
    ("BankHeist", "1", "type 1, p = 0.3, replacement from actions 0..9", _noise(0.3), "1"),
    ("BankHeist", "2.1", "event mode 3 (city switch), p = 0.001", _event(3, 0.001), "2.1"),
    ("BankHeist", "2.2", "cyclic drift, T = 600, to 3.2",
     _drift("cyclic", 600, _mask("ram", 3, 0.75)), "2.2"),
    ("BankHeist", "3.1", "default", {}, "3.1"),
    ("BankHeist", "3.2", "RAM mode 3 (hide city blocks), p = 0.75", _mask("ram", 3, 0.75), "3.2"),
]
PRESET_IDS = [f"{g}-{n}" for g, n, *_ in SPEC_PRESETS]


def test_list_presets_is_the_papers_24_in_order():
    pairs = list_presets()
    assert pairs == [(g, n) for g, n, *_ in SPEC_PRESETS]
    assert len(pairs) == 24 and len(set(pairs)) == 24
    assert all(isinstance(g, str) and isinstance(n, str) for g, n in pairs)


@pytest.mark.parametrize("game,name,words,parts,type_", SPEC_PRESETS, ids=PRESET_IDS)
def test_preset_matches_spec(game, name, words, parts, type_):
    config = preset(game, name)
    assert config == Config(**parts, game=game)
    assert config.type == type_ and config.game == game
    assert config.granularity == "frame" and config.ram_observation is False
    for field in ("action_noise", "event", "drift", "observation"):
        assert getattr(config, field) == parts.get(field), field
    if config.drift is not None:
        assert config.drift.secondary.type == "3.2"
    assert describe_preset(game, name) == words
    assert preset(game.lower(), name) == config  # game names are case-insensitive
    assert preset(get_game(game).rom_id, name) == config  # and ale-py ids ('bank_heist') name them
    get_game(game).validate(config)


def test_a_game_spelt_as_its_ale_id_takes_a_preset_everywhere():
    """make('bank_heist') worked while make('bank_heist', preset='1') was refused as an unknown
    game, in an error that listed 'BankHeist'."""
    import stori_jax
    from stori_jax.cli import main

    env = stori_jax.make("bank_heist", preset="1", num_envs=1, seed=0, num_workers=0)
    try:
        assert env.config == preset("BankHeist", "1")
    finally:
        env.close()
    assert main(["run", "bank_heist", "2.1", "--steps", "2", "--num-envs", "1",
                 "--num-workers", "0", "--quiet"]) == 0
    from stori_jax.cli import selected_presets  # suite --games bank_heist found no preset

    assert selected_presets(["bank_heist", "breakout"], ["1"]) == [("Breakout", "1"),
                                                                   ("BankHeist", "1")]
    with pytest.raises(ValueError, match=r"--presets: unknown \['9'\]; allowed for BankHeist"):
        selected_presets(["bank_heist"], ["9"])
    with pytest.raises(ValueError, match="unknown game 'pong' for presets"):
        preset("pong", "1")


def test_preset_details():
    # each 2.2 drifts to that game's 3.2 preset (Breakout 3.2A, Boxing 3.2C)
    for game, target in (("Breakout", "3.2A"), ("Boxing", "3.2C"), ("Gopher", "3.2"),
                         ("BankHeist", "3.2")):
        drift = preset(game, "2.2").drift
        assert drift.secondary.observation == preset(game, target).observation
    # BankHeist type 1 replaces from actions 0..9; the others from the whole minimal set
    for game, actions in (("BankHeist", tuple(range(10))), ("Breakout", tuple(range(4))),
                          ("Boxing", tuple(range(18))), ("Gopher", tuple(range(8)))):
        noise = preset(game, "1").action_noise
        assert noise.replacement_actions is None and noise.sticky is False
        assert get_game(game).replacement_actions(noise) == actions


def test_preset_names_match_whatever_their_case_as_game_names_do(tmp_path, capsys):
    """'3.2a' was refused while 'breakout' was accepted; every entry point now spells it as
    the paper does."""
    import stori_jax
    from baselines.ppo import PPOConfig
    from stori_jax.cli import main
    from stori_jax.presets import canonical_preset

    assert canonical_preset("breakout", "3.2a") == "3.2A"
    assert preset("Breakout", "3.2a") == preset("Breakout", "3.2A")
    assert describe_preset("boxing", "3.2c") == describe_preset("Boxing", "3.2C")
    assert PPOConfig(game="breakout", preset="3.2c").preset == "3.2C"
    with stori_jax.make("Breakout", "3.2b", num_envs=1, seed=0, num_workers=0) as env:
        assert env.config == preset("Breakout", "3.2B")
    assert main(["suite", "--games", "Boxing", "--presets", "3.2c", "--episodes", "1",
                 "--num-envs", "1", "--max-steps", "2", "--no-gallery", "--quiet",
                 "--out", str(tmp_path)]) == 0
    assert "| Boxing | 3.2C |" in (tmp_path / "table.md").read_text()


def test_unknown_preset_and_game():
    with pytest.raises(ValueError, match=r"unknown preset '3\.2A' for Gopher: allowed "
                                         r"\['1', '2\.1', '2\.2', '3\.1', '3\.2'\]"):
        preset("Gopher", "3.2A")
    with pytest.raises(ValueError, match=r"unknown preset '4' for Breakout: allowed \['1', "
                                         r"'2\.1', '2\.2', '3\.1', '3\.2A', '3\.2B', '3\.2C'\]"):
        preset("Breakout", "4")
    with pytest.raises(ValueError, match=r"unknown game 'Pong' for presets: allowed "
                                         r"\['BankHeist', 'Boxing', 'Breakout', 'Gopher'\]"):
        preset("Pong", "1")
    with pytest.raises(ValueError, match=r"unknown preset"):
        describe_preset("Boxing", "3.2")
    for number in (2.1, 1):  # str(2.1) would be a preset's name: a number is refused
        with pytest.raises(ValueError, match=r"preset must be a name \(a string\) of Breakout: "
                                             r"allowed .* got " + str(number)):
            preset("Breakout", number)


# ---------------------------------------------------------------------------------------------
# The reference format (section 10): nested dict and flat dotted keys, modes as strings
# ---------------------------------------------------------------------------------------------

IS = "intrinsic_stochasticity"


def reference_dict(stype, *, action_prob=None, event=None, drift=None, observation=None,
                   full=False):
    """A reference config. ``full`` fills every section (as the reference's config files do) with
    values that the selected type must ignore."""
    d = {"stochasticity_type": stype}
    intrinsic = {}
    if full:
        intrinsic = {
            "action_dependent": {"stochastic_action_prob": 0.9},
            "action_independent_random": {"mode": "1", "random_stochasticity_prob": 0.9},
            "action_independent_concept_drift": {"temporal_mode": "cyclic",
                                                 "temporal_threshold": 7,
                                                 "secondary_concept_type": "1"},
        }
        d["partial_observation"] = {"type": "crop", "mode": "3", "prob": 0.9}
    if action_prob is not None:
        intrinsic.setdefault("action_dependent", {})["stochastic_action_prob"] = action_prob
    if event is not None:
        intrinsic["action_independent_random"] = {"mode": event[0],
                                                  "random_stochasticity_prob": event[1]}
    if drift is not None:
        intrinsic["action_independent_concept_drift"] = {
            "temporal_mode": drift[0], "temporal_threshold": drift[1],
            "secondary_concept_type": drift[2]}
    if observation is not None:
        d["partial_observation"] = dict(zip(("type", "mode", "prob"), observation))
    if intrinsic:
        d[IS] = intrinsic
    return d


def dotted(d, prefix=""):
    """Flatten a nested dict into dotted keys (written here, independently of the library)."""
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(dotted(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


REFERENCE_PRESETS = {  # (game, preset): reference dict(s) for it, modes as strings
    ("Breakout", "1"): dict(stype="1", action_prob=0.3),
    ("Breakout", "2.1"): dict(stype="2.1", event=("2", 0.25)),
    ("Breakout", "2.2"): dict(stype="2.2", drift=("sudden", 300, "3.2"),
                              observation=("blackout", "10", 1.0)),
    ("Breakout", "3.1"): dict(stype="3.1"),
    ("Breakout", "3.2A"): dict(stype="3.2", observation=("blackout", "10", 1.0)),
    ("Breakout", "3.2B"): dict(stype="3.2", observation=("crop", "1", 0.75)),
    ("Breakout", "3.2C"): dict(stype="3.2", observation=("crop", "5", 1.0)),
    ("Boxing", "2.1"): dict(stype="2.1", event=("1", 0.001)),
    ("Boxing", "2.2"): dict(stype="2.2", drift=("sudden", 300, "3.2"),
                            observation=("ram", "2", 0.7)),
    ("Boxing", "3.2A"): dict(stype="3.2", observation=("blackout", "9", 1.0)),
    ("Gopher", "2.1"): dict(stype="2.1", event=("2", 0.3)),
    ("Gopher", "2.2"): dict(stype="2.2", drift=("cyclic", 600, "3.2"),
                            observation=("blackout", "6", 1.0)),
    ("BankHeist", "1"): dict(stype="1", action_prob=0.3),
    ("BankHeist", "2.1"): dict(stype="2.1", event=("3", 0.001)),
    ("BankHeist", "2.2"): dict(stype="2.2", drift=("cyclic", 600, "3.2"),
                               observation=("ram", "3", 0.75)),
    ("BankHeist", "3.2"): dict(stype="3.2", observation=("ram", "3", 0.75)),
}


@pytest.mark.parametrize("key", list(REFERENCE_PRESETS), ids=[f"{g}-{n}" for g, n in
                                                               REFERENCE_PRESETS])
@pytest.mark.parametrize("full", [False, True], ids=["minimal", "full"])
def test_reference_format_gives_the_presets(key, full):
    game, name = key
    kw = REFERENCE_PRESETS[key]
    d = reference_dict(kw["stype"], full=full, **{k: v for k, v in kw.items() if k != "stype"})
    expected = preset(game, name)
    nested = config_from_reference(d, game=game)
    flat = config_from_reference(dotted(d), game=game)
    assert nested == expected
    assert flat == expected
    assert config_from_reference(d, game=game) == expected
    # without a game the config is the same, unbound
    assert config_from_reference(d) == expected.replace(game=None)
    # a mix of nested and dotted keys is read too
    if IS in d:
        mixed = {k: v for k, v in d.items() if k != IS}
        mixed.update(dotted({IS: d[IS]}))
        assert config_from_reference(mixed, game=game) == expected


def test_reference_drift_with_secondary_1_and_2_1():
    d = reference_dict("2.2", action_prob=0.2, drift=("cyclic", 50, "1"))
    expected = Config(drift=ConceptDrift("cyclic", 50, Config(action_noise=ActionNoise(0.2))))
    assert config_from_reference(d) == expected
    assert config_from_reference(dotted(d), game="Boxing") == expected.for_game("Boxing")
    d = reference_dict("2.2", event=("3", 0.05), drift=("sudden", 10, "2.1"), full=True)
    expected = Config(drift=ConceptDrift("sudden", 10, Config(event=RandomEvent(3, 0.05))))
    assert config_from_reference(d, game="BankHeist") == expected.for_game("BankHeist")
    assert config_from_reference(dotted(d)) == expected
    # the threshold may be given as a string of digits
    d["intrinsic_stochasticity"]["action_independent_concept_drift"]["temporal_threshold"] = "10"
    assert config_from_reference(d) == expected


def test_reference_observation_prob_defaults_to_1():
    d = {"stochasticity_type": "3.2", "partial_observation": {"type": "crop", "mode": "4"}}
    assert config_from_reference(d) == Config(observation=ObservationMask("crop", 4, 1.0))


def test_reference_values_as_numbers_and_strings():
    d = {"stochasticity_type": 1, f"{IS}.action_dependent.stochastic_action_prob": "0.25"}
    assert config_from_reference(d) == Config(action_noise=ActionNoise(0.25))
    d = {"stochasticity_type": "2.1", f"{IS}.action_independent_random.mode": 2,
         f"{IS}.action_independent_random.random_stochasticity_prob": 0.5}
    assert config_from_reference(d) == Config(event=RandomEvent(2, 0.5))



def test_reference_unknown_keys_are_rejected():
    # the misspelled/unknown probability key used to be dropped, giving prob=1.0
    d = {"stochasticity_type": "3.2", "partial_observation.type": "crop",
         "partial_observation.mode": "1", "partial_observation.probability": 0.25}
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['partial_observation.probability'\]"
                                         r".*known keys: .*'partial_observation.prob'"):
        config_from_reference(d)
    nested = {"stochasticity_type": "1", IS: {"action_dependent": {"stochastic_action_prob": 0.3,
                                                                   "sticky": True}}}
    with pytest.raises(ValueError, match=rf"unknown key\(s\) \['{IS}.action_dependent.sticky'\]"):
        config_from_reference(nested)
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['partial_observation'\]"):
        config_from_reference({"stochasticity_type": "3.1", "partial_observation": "crop"})
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['stochasticity'\]"):
        config_from_reference({"stochasticity_type": "3.1", "stochasticity": "1"})


def test_reference_sections_of_unselected_types_are_accepted_and_unused():
    # a real reference config carries every section; only the selected type's is read
    d = reference_dict("1", action_prob=0.3, full=True)
    d["partial_observation"]["mode"] = "0"  # not read for type 1, so not checked
    assert config_from_reference(d) == Config(action_noise=ActionNoise(0.3))
    assert config_from_reference(dotted(d)) == Config(action_noise=ActionNoise(0.3))


def test_reference_conflicting_nested_and_dotted_keys_are_rejected():
    key = "partial_observation.prob"
    d = {"stochasticity_type": "3.2",
         "partial_observation": {"type": "crop", "mode": "1", "prob": 0.5}, key: 0.25}
    with pytest.raises(ValueError, match=rf"gives '{key}' twice with different values "
                                         r"\(0.5 and 0.25\)"):
        config_from_reference(d)
    d = {key: 0.25, "stochasticity_type": "3.2",  # the other order too
         "partial_observation": {"type": "crop", "mode": "1", "prob": 0.5}}
    with pytest.raises(ValueError, match=rf"gives '{key}' twice"):
        config_from_reference(d)
    d = {"stochasticity_type": "1", IS: {"action_dependent.stochastic_action_prob": 0.3,
                                         "action_dependent": {"stochastic_action_prob": 0.2}}}
    with pytest.raises(ValueError, match=r"stochastic_action_prob' twice"):
        config_from_reference(d)
    # the same value given twice is not a conflict
    d = {"stochasticity_type": "3.2", "partial_observation": {"type": "crop", "mode": "1",
                                                              "prob": 0.5}, key: 0.5}
    assert config_from_reference(d) == Config(observation=ObservationMask("crop", 1, 0.5))


def test_the_presets_without_a_random_draw():
    """A preset draws nothing at random when it has no action noise or event, masks only at
    p = 1 and no torch, and no gradual drift (eval's note that a greedy policy plays one
    episode rests on it)."""
    deterministic = {(game, name) for game, name in list_presets()
                     if preset(game, name).is_deterministic()}
    assert deterministic == {("Breakout", "2.2"), ("Breakout", "3.1"), ("Breakout", "3.2A"),
                             ("Boxing", "3.1"), ("Boxing", "3.2A"), ("Gopher", "2.2"),
                             ("Gopher", "3.1"), ("Gopher", "3.2"), ("BankHeist", "3.1")}
    torch = Config(observation=ObservationMask("crop", 5, 1.0))
    gradual = Config(drift=ConceptDrift("gradual", 10, Config(
        observation=ObservationMask("blackout", 1, 1.0))))
    never = Config(action_noise=ActionNoise(0.0), event=RandomEvent(1, 0.0),
                   observation=ObservationMask("crop", 1, 0.0))
    assert not torch.is_deterministic() and not gradual.is_deterministic()
    assert never.is_deterministic()
