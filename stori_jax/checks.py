"""Checks of scalar arguments, shared by every public entry point.

One wording and one exception type (``ValueError``, wrong type or out of range alike) for the
whole package, so that ``make``, the configs, ``rollout``, the metrics, the PPO config, the CLI
and the results loader describe bad input the same way.  Each check names the field and the
allowed values, and returns the value as a plain Python number or bool (numpy scalars and 0-d
numpy or JAX arrays, bfloat16 included, are accepted, so a sweep over ``jnp.linspace`` values
works).
"""
from __future__ import annotations

import math
import numbers
from typing import AbstractSet, Any, Mapping

import numpy as np


def _range_text(minimum, maximum) -> str:
    if minimum is not None and maximum is not None:
        return f"in [{minimum}, {maximum}]"
    if minimum is not None:
        return f">= {minimum}"
    if maximum is not None:
        return f"<= {maximum}"
    return ""


def shown(value: Any) -> str:
    """``repr(value)``, cut short if long (a 400-digit int, a big list)."""
    text = repr(value)
    return text if len(text) <= 60 else f"{text[:40]}... ({len(text)} characters)"


def _numeric_or_bool(dtype: Any) -> bool:
    """Whether ``dtype`` is a numpy or JAX int, float or bool dtype (bfloat16 and JAX's other
    ml_dtypes floats included: numpy gives them the kind 'V')."""
    kind = getattr(dtype, "kind", None)
    if kind in ("b", "i", "u", "f"):
        return True
    if kind != "V":
        return False
    import jax.numpy as jnp  # only a JAX (ml_dtypes) scalar gets here

    return bool(jnp.issubdtype(dtype, jnp.number))


def _unwrapped(value: Any) -> Any:
    """A 0-d numeric or bool array (numpy or JAX) as its Python scalar; anything else
    unchanged."""
    if getattr(value, "shape", None) == () and _numeric_or_bool(getattr(value, "dtype", None)) \
            and not isinstance(value, (numbers.Number, np.bool_)):
        try:
            return value.item()
        except Exception:  # noqa: BLE001 - a traced value has no number yet: refused below
            return value
    return value


MAX_INT32 = 2**31 - 1  # counts JAX and envpool hold as int32 (frames, no-ops, drift periods)
MAX_SEED = MAX_INT32  # JAX keys are 32-bit and envpool's seed an int32: a larger one would alias


def check_int(name: str, value: Any, minimum: int | None = None,
              maximum: int | None = None) -> int:
    """``value`` as an int in [minimum, maximum] (either bound may be None); bools refused."""
    bounds = _range_text(minimum, maximum)
    value = _unwrapped(value)
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an int{' ' + bounds if bounds else ''}, "
                         f"got {shown(value)}")
    value = int(value)
    if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
        raise ValueError(f"{name} must be {bounds}, got {shown(value)}")
    return value


def check_real(name: str, value: Any, minimum: float | None = None,
               maximum: float | None = None) -> float:
    """``value`` as a finite float in [minimum, maximum] (either bound may be None); bools,
    strings, NaN and infinities refused."""
    bounds = _range_text(minimum, maximum)
    if minimum is not None and maximum is not None:  # "in [a, b]" already says finite
        kind, wanted = "a number " + bounds, bounds
    else:
        kind = wanted = f"a finite number{' ' + bounds if bounds else ''}"
    value = _unwrapped(value)
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be {kind}, got {shown(value)}")
    try:
        number = float(value)
    except OverflowError:  # an int too large for a float
        raise ValueError(f"{name} must be {wanted}, got {shown(value)}") from None
    if (not math.isfinite(number) or (minimum is not None and number < minimum)
            or (maximum is not None and number > maximum)):
        raise ValueError(f"{name} must be {wanted}, got {number}")
    return number


def check_probability(name: str, value: Any) -> float:
    """``value`` as a float in [0, 1].  A float32 (numpy or JAX) becomes the shortest decimal
    that rounds to the same float32 (np.float32(0.3) -> 0.3, not 0.30000001192...), so that it
    prints, records and compares as the config written as a literal, and plays as it: the JAX
    draws compare in float32, the event draws in the workers in float64 against that decimal."""
    prob = check_real(name, value, 0, 1)
    if getattr(getattr(value, "dtype", None), "name", None) == "float32":
        decimal = float(np.format_float_positional(np.float32(prob), unique=True))
        if np.float32(decimal) == np.float32(prob):  # all but a rare double rounding
            prob = decimal
    return prob


DRAW_RESOLUTION = 2.0**-23  # a float32 uniform in [0, 1) is a multiple of this


def check_draw_probability(name: str, value: Any) -> float:
    """``value`` as a probability that a float32 uniform ``u`` plays (it fires when ``u < p``):
    0, or in [2**-23, 1].  The draws are multiples of 2**-23, so ``p`` fires at ``p`` rounded up
    to one (a relative excess below 2**-23 / p: 1.2e-4 at p = 0.001); a smaller positive ``p``
    would fire at 2**-23, up to 1e5 times as often as asked, and is refused."""
    prob = check_probability(name, value)
    if 0 < prob < DRAW_RESOLUTION:
        raise ValueError(f"{name} must be 0 or in [2**-23, 1] (~1.19e-07: the draws are float32 "
                         f"uniforms, multiples of 2**-23, so a smaller probability would fire at "
                         f"2**-23), got {prob!r}")
    return prob


def check_bool(name: str, value: Any) -> bool:
    """``value`` as a bool: True or False (numpy's, and a 0-d bool array, too), not a truthy
    string or number."""
    value = _unwrapped(value)
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise ValueError(f"{name} must be True or False, got {shown(value)}")


def check_action_indices(name: str, values: Any,
                         what: str = "a non-empty sequence of action indices >= 0") -> tuple:
    """``values`` as a tuple of ints >= 0, in order: the table a uniform draw indexes (a dict,
    set or string would pick the order or be characters, so they are refused)."""
    try:
        actions = (() if isinstance(values, (Mapping, AbstractSet, str, bytes))
                   else tuple(_unwrapped(a) for a in values))
    except TypeError:
        actions = ()
    if not actions or any(isinstance(a, bool) or not isinstance(a, numbers.Integral) or a < 0
                          for a in actions):
        raise ValueError(f"{name} must be {what}, got {shown(values)}")
    return tuple(int(a) for a in actions)


def check_dtype(name: str, array: Any, kinds: str, wanted: str) -> None:
    """A ValueError naming ``name`` unless ``array``'s dtype is of one of numpy's ``kinds``
    ('b' bool, 'i' 'u' ints, 'f' floats; 'B' for uint8 alone); its dtype is known inside
    ``jit`` too, so the pure functions check it always."""
    dtype = getattr(array, "dtype", None)
    if dtype is None:
        try:
            dtype = np.asarray(array).dtype
        except Exception:  # noqa: BLE001 - anything not array-like
            raise ValueError(f"{name} must be an array of {wanted}, got {shown(array)}") from None
    dtype = np.dtype(dtype)
    if dtype.kind not in kinds and not (dtype == np.uint8 and "B" in kinds):
        raise ValueError(f"{name} must be an array of {wanted}, got dtype {dtype}")


def unless_traced(check, name: str, value: Any, *bounds):
    """``check(name, value, *bounds)``, or ``value`` as it is inside a JAX transformation (a
    traced value has no number to check yet): for the arguments of the pure functions."""
    import jax

    return value if isinstance(value, jax.core.Tracer) else check(name, value, *bounds)


def check_actions(actions, num_envs: int, num_actions: int):
    """A batch of actions checked on the host: shape (num_envs,), an integer dtype, values in
    [0, num_actions); returned as int32 numpy."""
    import jax

    expected = f"shape ({num_envs},) of ints in [0, {num_actions - 1}]"
    if isinstance(actions, jax.core.Tracer):
        raise ValueError("actions are traced: env.step / env.send cannot run inside jax.jit, "
                         "vmap or lax.scan (they step emulator processes from the host); "
                         "inside a traced function step through env.xla() (README, 'Stepping "
                         "inside jax.jit')")
    if np.ma.isMaskedArray(actions):  # np.asarray would step its masked entries' values
        raise ValueError(f"actions must be a plain array of {expected}, not a masked array "
                         "(its masked entries would be stepped with the values they hide)")
    try:
        a = np.asarray(actions)
    except Exception as e:  # noqa: BLE001 - anything not array-like
        raise ValueError(f"actions must be an array of {expected}, got {actions!r}") from e
    if actions is None or a.dtype.kind in "OSUV":  # None, strings, objects: not numbers
        raise ValueError(f"actions must be an array of {expected}, got "
                         f"{type(actions).__name__} {actions!r:.60}")
    if a.shape != (num_envs,):
        raise ValueError(f"actions must have {expected}, got shape {a.shape}")
    if a.dtype.kind not in "iu" or (isinstance(actions, (list, tuple)) and any(
            isinstance(x, (bool, np.bool_)) for x in actions)):
        raise ValueError(f"actions must have an integer dtype ({expected}), got {a.dtype}"
                         + (" with bools" if a.dtype.kind in "iu" else ""))
    if a.size and (a.min() < 0 or a.max() >= num_actions):
        raise ValueError(f"actions out of range: expected {expected}, got values "
                         f"{a.min()}..{a.max()}")
    return a.astype(np.int32)
