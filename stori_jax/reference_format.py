"""Load the reference STORI configuration format into :class:`stori_jax.Config`.

The reference format is a nested dict (or the same flattened with dotted keys), modes as strings::

    stochasticity_type: '1' | '2.1' | '2.2' | '3.1' | '3.2'
    intrinsic_stochasticity.action_dependent.stochastic_action_prob
    intrinsic_stochasticity.action_independent_random.mode / .random_stochasticity_prob
    intrinsic_stochasticity.action_independent_concept_drift.temporal_mode ('sudden'|'cyclic'|'gradual'),
        .temporal_threshold, .secondary_concept_type ('1'|'2.1'|'3.2')
    partial_observation.type ('crop'|'blackout'|'ram'), .mode, .prob (optional: 1.0, as
        ObservationMask's default; every other value is required)

A 2.2 config takes its secondary concept's parameters from the same dict's other sections.
``partial_observation.mode`` '0' is the specification's "none": a '3.2' config with it hides
nothing and loads as 3.1 (its type and prob are still checked); as the secondary concept of a
'2.2' config it would make concept 2 the default game, which the specification does not allow.

Every key above is accepted whatever ``stochasticity_type`` selects (the reference's config files
carry all sections); the sections of types that are not selected are read by nothing and their
values are not checked.  Any other key is an error, as is the same key given twice (nested and
dotted) with different values.
"""

from __future__ import annotations

import numbers
from typing import Any, Mapping

import numpy as np

from stori_jax.checks import check_draw_probability
from stori_jax.config import (DRIFT_SCHEDULES, SECONDARY_TYPES, ActionNoise, Config,
                              ConceptDrift, ObservationMask, RandomEvent)

_TYPES = ("1", "2.1", "2.2", "3.1", "3.2")
REFERENCE_MASK_KINDS = ("crop", "blackout", "ram")  # the reference's (objects is stori-jax's)
_ACTION = "intrinsic_stochasticity.action_dependent"
_RANDOM = "intrinsic_stochasticity.action_independent_random"
_DRIFT = "intrinsic_stochasticity.action_independent_concept_drift"
_OBS = "partial_observation"
KNOWN_KEYS = ("stochasticity_type",
              f"{_ACTION}.stochastic_action_prob",
              f"{_RANDOM}.mode", f"{_RANDOM}.random_stochasticity_prob",
              f"{_DRIFT}.temporal_mode", f"{_DRIFT}.temporal_threshold",
              f"{_DRIFT}.secondary_concept_type",
              f"{_OBS}.type", f"{_OBS}.mode", f"{_OBS}.prob")
# the Config field each key sets, as the errors of Config name it: the part's own check
# ("RandomEvent.mode") or the game's, by path ("Config[.drift.secondary].event.mode")
_FIELD_KEYS = {"ActionNoise.prob": f"{_ACTION}.stochastic_action_prob",
               "RandomEvent.mode": f"{_RANDOM}.mode", "event.mode": f"{_RANDOM}.mode",
               "RandomEvent.prob": f"{_RANDOM}.random_stochasticity_prob",
               "ConceptDrift.period": f"{_DRIFT}.temporal_threshold",
               "ObservationMask.mode": f"{_OBS}.mode", "observation.mode": f"{_OBS}.mode",
               "ObservationMask.prob": f"{_OBS}.prob"}


def _key_of(message: str) -> str | None:
    """The reference key whose value a Config error ``message`` (starting with the field) is
    about, if any."""
    field_path = message.split(" ", 1)[0]
    for field_name, key in _FIELD_KEYS.items():
        if field_path == field_name or field_path.endswith("." + field_name):
            return key
    return None


def flatten(d: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested dict -> {dotted.key: value}; already-dotted keys pass through.  A key given twice
    (e.g. nested and dotted) with different values is a ``ValueError``."""
    out: dict[str, Any] = {}
    for key, value in d.items():
        full = f"{prefix}{key}"
        items = (flatten(value, full + ".").items() if isinstance(value, Mapping)
                 else [(full, value)])
        for k, v in items:
            if k in out and not _same(out[k], v):
                raise ValueError(f"reference config gives {k!r} twice with different values "
                                 f"({out[k]!r} and {v!r}); give it once")
            out[k] = v
    return out


def _same(a, b) -> bool:
    try:
        return bool(a == b)
    except (TypeError, ValueError):  # e.g. arrays, whose == is elementwise
        return a is b


class _Reader:
    def __init__(self, flat: dict[str, Any]):
        self.flat = flat

    def get(self, key: str, cast, what: str):
        if key not in self.flat:
            raise ValueError(f"reference config is missing {key!r} ({what})")
        value = self.flat[key]
        try:
            return cast(value)
        except (TypeError, ValueError, OverflowError):  # OverflowError: int(1e400), float(10**400)
            raise ValueError(f"reference config {key!r} must be {what}, got {value!r}") from None

    def choice(self, key: str, allowed) -> str:
        """The string ``key`` holds, one of ``allowed`` (spelt exactly)."""
        what = "one of " + str(list(allowed))
        value = self.get(key, lambda v: str(v).strip(), what)
        if value not in allowed:
            raise ValueError(f"reference config {key!r} must be {what}, got {value!r}")
        return value


def _mode(value) -> int:
    text = str(value).strip()
    if not text.lstrip("-").isdigit():
        raise ValueError(text)
    return int(text)


def _probability(value):
    """A number as given (the Config's check takes numpy and float32 values as ``preset`` does),
    or a string of one; not a bool (float(True) would silently read as 1.0)."""
    if isinstance(value, str):
        return float(value)
    if isinstance(value, bool) or not (isinstance(value, numbers.Real)
                                       or getattr(value, "shape", None) == ()):  # 0-d arrays
        raise TypeError(value)
    return value


def _count(value) -> int:
    """An int (numpy's too), an integral float (300.0) or a string of digits; not a bool, and
    never a float silently truncated (300.7)."""
    if isinstance(value, (bool, np.bool_)):
        raise TypeError(value)
    if isinstance(value, numbers.Real) and not isinstance(value, numbers.Integral) \
            and not float(value).is_integer():
        raise ValueError(value)
    if not isinstance(value, (numbers.Real, str)):
        raise TypeError(value)
    return int(value)


_NO_MASK = 0  # partial_observation.mode of the spec's "none" in every mask table


def _concept(kind: str, r: _Reader) -> Config:
    if kind == "1":
        return Config(action_noise=ActionNoise(
            prob=r.get(f"{_ACTION}.stochastic_action_prob", _probability, "a probability")))
    if kind == "2.1":
        return Config(event=RandomEvent(
            mode=r.get(f"{_RANDOM}.mode", _mode, "an event mode ('1', '2', ...)"),
            prob=r.get(f"{_RANDOM}.random_stochasticity_prob", _probability, "a probability")))
    if kind == "3.2":
        kind_ = r.choice(f"{_OBS}.type", REFERENCE_MASK_KINDS)
        mode = r.get(f"{_OBS}.mode", _mode, "a mode ('1', '2', ...)")
        prob = (r.get(f"{_OBS}.prob", _probability, "a probability")
                if f"{_OBS}.prob" in r.flat else 1.0)
        if mode == _NO_MASK:  # the spec's "none": nothing hidden, the default game
            check_draw_probability("ObservationMask.prob", prob)
            return Config()
        return Config(observation=ObservationMask(kind=kind_, mode=mode, prob=prob))
    return Config()


def config_from_reference(d: Mapping[str, Any], game: str | None = None) -> Config:
    """The :class:`Config` of a reference config ``d`` (nested, dotted or a mix), bound to
    ``game`` if given.

    Only the sections of the selected ``stochasticity_type`` are read (for 2.2 also its
    secondary concept's section); the other sections of the format are accepted and ignored, as
    the reference does, since its config files carry all of them.  Unknown keys, and a key given
    both nested and dotted with different values, are a ``ValueError``.
    """
    if not isinstance(d, Mapping):
        raise ValueError(f"reference config must be a dict (nested or dotted keys), got {d!r}")
    flat = flatten(d)
    unknown = [k for k in flat if k not in KNOWN_KEYS]
    if unknown:
        raise ValueError(f"reference config has unknown key(s) {unknown}; "
                         f"known keys: {list(KNOWN_KEYS)}")
    r = _Reader(flat)
    try:
        kind = r.choice("stochasticity_type", _TYPES)
        if kind == "2.2":
            secondary_type = r.choice(f"{_DRIFT}.secondary_concept_type", SECONDARY_TYPES)
            secondary = _concept(secondary_type, r)
            if secondary.type == "3.1":  # a '3.2' secondary of mode '0'
                raise ValueError(f"reference config '{_OBS}.mode' '0' is the spec's 'none': as "
                                 "the secondary concept of a '2.2' config it would make concept 2 "
                                 "the default game (3.1), which is not a valid secondary; give a "
                                 "mode >= 1")
            config = Config(drift=ConceptDrift(
                schedule=r.choice(f"{_DRIFT}.temporal_mode", DRIFT_SCHEDULES),
                period=r.get(f"{_DRIFT}.temporal_threshold", _count,
                             "an int number of agent steps"),
                secondary=secondary))
        else:
            config = _concept(kind, r)
        return config.for_game(game) if game is not None else config
    except ValueError as error:  # name the key the user wrote, not only the Config field
        key = _key_of(str(error))
        if key is None:
            raise
        raise ValueError(f"reference config {key!r}: {error}") from None
