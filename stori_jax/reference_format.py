"""Load the reference STORI configuration format into :class:`stori_jax.Config`.

The reference format is a nested dict (or the same flattened with dotted keys), modes as strings::

    stochasticity_type: '1' | '2.1' | '2.2' | '3.1' | '3.2'
    intrinsic_stochasticity.action_dependent.stochastic_action_prob
    intrinsic_stochasticity.action_independent_random.mode / .random_stochasticity_prob
    intrinsic_stochasticity.action_independent_concept_drift.temporal_mode ('sudden'|'cyclic'),
        .temporal_threshold, .secondary_concept_type ('1'|'2.1'|'3.2')
    partial_observation.type ('crop'|'blackout'|'ram'), .mode, .prob

A 2.2 config takes its secondary concept's parameters from the same dict's other sections.
"""

from __future__ import annotations

from typing import Any, Mapping

from stori_jax.config import (ActionNoise, Config, ConceptDrift, ObservationMask, RandomEvent,
                              SECONDARY_TYPES)

_TYPES = ("1", "2.1", "2.2", "3.1", "3.2")
_ACTION = "intrinsic_stochasticity.action_dependent"
_RANDOM = "intrinsic_stochasticity.action_independent_random"
_DRIFT = "intrinsic_stochasticity.action_independent_concept_drift"
_OBS = "partial_observation"


def flatten(d: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested dict -> {dotted.key: value}; already-dotted keys pass through."""
    out: dict[str, Any] = {}
    for key, value in d.items():
        full = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(flatten(value, full + "."))
        else:
            out[full] = value
    return out


class _Reader:
    def __init__(self, flat: dict[str, Any]):
        self.flat = flat

    def get(self, key: str, cast, what: str):
        if key not in self.flat:
            raise ValueError(f"reference config is missing {key!r} ({what})")
        value = self.flat[key]
        try:
            return cast(value)
        except (TypeError, ValueError):
            raise ValueError(f"reference config {key!r} must be {what}, got {value!r}") from None


def _mode(value) -> int:
    text = str(value).strip()
    if not text.lstrip("-").isdigit():
        raise ValueError(text)
    return int(text)


def _probability(value) -> float:
    if isinstance(value, bool):  # float(True) would silently read as 1.0
        raise TypeError(value)
    return float(value)


def _count(value) -> int:
    """An int, an integral float (300.0) or a string of digits; not a bool, and never a float
    silently truncated (300.7)."""
    if isinstance(value, bool):
        raise TypeError(value)
    if isinstance(value, float) and not value.is_integer():
        raise ValueError(value)
    if not isinstance(value, (int, float, str)):
        raise TypeError(value)
    return int(value)


def _concept(kind: str, r: _Reader) -> Config:
    if kind == "1":
        return Config(action_noise=ActionNoise(
            prob=r.get(f"{_ACTION}.stochastic_action_prob", _probability, "a probability")))
    if kind == "2.1":
        return Config(event=RandomEvent(
            mode=r.get(f"{_RANDOM}.mode", _mode, "an event mode ('1', '2', ...)"),
            prob=r.get(f"{_RANDOM}.random_stochasticity_prob", _probability, "a probability")))
    if kind == "3.2":
        kind_ = r.get(f"{_OBS}.type", str, "'crop', 'blackout' or 'ram'")
        mode = r.get(f"{_OBS}.mode", _mode, "a mode ('1', '2', ...)")
        prob = (r.get(f"{_OBS}.prob", _probability, "a probability")
                if f"{_OBS}.prob" in r.flat else 1.0)
        return Config(observation=ObservationMask(kind=kind_, mode=mode, prob=prob))
    return Config()


def config_from_reference(d: Mapping[str, Any], game: str | None = None) -> Config:
    if not isinstance(d, Mapping):
        raise ValueError(f"reference config must be a dict (nested or dotted keys), got {d!r}")
    r = _Reader(flatten(d))
    kind = r.get("stochasticity_type", lambda v: str(v).strip(), f"one of {list(_TYPES)}")
    if kind not in _TYPES:
        raise ValueError(f"stochasticity_type must be one of {list(_TYPES)}, got {kind!r}")
    if kind == "2.2":
        secondary_type = r.get(f"{_DRIFT}.secondary_concept_type", lambda v: str(v).strip(),
                               f"one of {list(SECONDARY_TYPES)}")
        if secondary_type not in SECONDARY_TYPES:
            raise ValueError(f"{_DRIFT}.secondary_concept_type must be one of "
                             f"{list(SECONDARY_TYPES)}, got {secondary_type!r}")
        config = Config(drift=ConceptDrift(
            schedule=r.get(f"{_DRIFT}.temporal_mode", str, "'sudden' or 'cyclic'"),
            period=r.get(f"{_DRIFT}.temporal_threshold", _count, "an int number of agent steps"),
            secondary=_concept(secondary_type, r)))
    else:
        config = _concept(kind, r)
    return config.for_game(game) if game is not None else config
