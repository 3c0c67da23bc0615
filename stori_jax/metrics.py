"""Information-theoretic and variance helpers from the STORI paper (docs/spec.md sections 1, 11).

- ``action_channel_capacity(n, p)``: capacity I(A; Ã) in bits of the type-1 channel that replaces
  the intended action, with probability p, by one drawn uniformly from all n actions.
- ``channel_matrix`` / ``mutual_information``: the same for any replacement set and input
  distribution (e.g. BankHeist's replacements 0..9 of 18 actions).
- ``empirical_action_information(intended, executed, n)``: a plug-in estimate of I(A; Ã) from
  logged (intended, executed) pairs, e.g. from ``info["executed_action"]`` (leave out the rows
  where ``info["reset_step"]``: an env reset instead of stepped executed NOOPs, reported as 0).
  At frame granularity ``executed_action`` is (T, B, frame_skip), one action per frame: repeat
  the intended actions to match (``np.repeat(intended[..., None], frame_skip, -1)``), and keep
  only the slots below ``info["frames_played"]`` (those after an episode's last frame were not
  played: reported as 0).
- ``next_state_variance(states)``: the spread of next states reached under a fixed action, the
  quantity of the paper's variance-calibration probe.

Inputs are validated: a bad argument (wrong type, value or shape) is a ``ValueError`` that names
it, worded as everywhere else in the package (``stori_jax.checks``).  Action counts are limited
to ``MAX_ACTIONS`` (ALE has 18).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from stori_jax.checks import check_int, check_probability

MAX_ACTIONS = 1024  # ALE's full action set is 18; the (n, n) matrices stay small
_ATOL = 1e-6  # how far a distribution's sum may be from 1


def _check_num_actions(num_actions) -> int:
    return check_int("num_actions", num_actions, 1, MAX_ACTIONS)


def _check_actions(name: str, values, num_actions: int) -> np.ndarray:
    """Action ids as an int array, each in [0, num_actions - 1] (no negative wrap-around)."""
    a = np.asarray(values)
    if a.size and not np.issubdtype(a.dtype, np.integer):
        raise ValueError(f"{name} must be integer action ids, got dtype {a.dtype}")
    if a.size and (a.min() < 0 or a.max() >= num_actions):
        bad = sorted(set(a[(a < 0) | (a >= num_actions)].tolist()))
        raise ValueError(f"{name} must be action ids in [0, {num_actions - 1}], got {bad}")
    return a


def _check_distribution(name: str, p: np.ndarray, axis: int = -1) -> None:
    """Finite, non-negative and summing to 1 (within _ATOL) along ``axis``."""
    if not np.isfinite(p).all() or (p < 0).any():
        raise ValueError(f"{name} must be finite and non-negative")
    sums = p.sum(axis)
    if not np.allclose(sums, 1.0, rtol=0.0, atol=_ATOL):
        raise ValueError(f"{name} must sum to 1 (within {_ATOL:g}), got sum(s) "
                         f"{np.round(sums, 6).tolist()}")


def _as_float_array(name: str, x) -> np.ndarray:
    try:
        return np.asarray(x, np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be an array of numbers, got {x!r}") from None


def _entropy_bits(p: np.ndarray) -> float:
    p = np.asarray(p, np.float64)
    p = p[p > 0]
    return float(-(p * np.log2(p)).sum())


def channel_matrix(num_actions: int, prob: float,
                   replacement: Sequence[int] | None = None) -> np.ndarray:
    """P(executed = j | intended = i), (n, n): with prob ``prob`` a uniform draw from
    ``replacement`` (default: all actions), else the intended action.

    ``replacement`` is a sequence of action ids in [0, n - 1], drawn from uniformly by position as
    ``functional.corrupt_actions`` does, so a repeated id counts once per occurrence: ``[1, 1,
    2]`` replaces by 1 with prob 2p/3 (``ActionNoise.replacement_actions`` refuses repeats)."""
    prob = check_probability("prob", prob)
    num_actions = _check_num_actions(num_actions)
    if replacement is None:
        replacement = range(num_actions)
    elif isinstance(replacement, (str, bytes)) or not hasattr(replacement, "__iter__"):
        raise ValueError(f"replacement must be a sequence of action ids, got {replacement!r}")
    replacement = list(replacement)
    if any(isinstance(a, (bool, np.bool_)) or not isinstance(a, (int, np.integer))
           for a in replacement):
        raise ValueError(f"replacement must be int action ids, got {replacement!r}")
    if len(replacement) == 0:
        raise ValueError(f"replacement must be non-empty action ids in [0, {num_actions - 1}]")
    replacement = _check_actions("replacement", np.asarray(replacement, np.int64), num_actions)
    m = np.eye(num_actions) * (1.0 - prob)
    np.add.at(m, (slice(None), replacement), prob / len(replacement))  # repeats add up
    return m


def mutual_information(input_dist: np.ndarray, channel: np.ndarray) -> float:
    """I(A; Ã) in bits for input distribution P(A) (n,) and channel P(Ã | A) (n, m), whose rows
    are distributions; both must be non-negative and sum to 1 (within 1e-6)."""
    px = _as_float_array("input_dist", input_dist)
    ch = _as_float_array("channel", channel)
    if px.ndim != 1 or px.size == 0:
        raise ValueError(f"input_dist must be a non-empty 1-D distribution, got shape {px.shape}")
    if ch.ndim != 2 or ch.shape[0] != px.shape[0] or ch.shape[1] == 0:
        raise ValueError(f"channel must be ({px.shape[0]}, m) to match input_dist "
                         f"{px.shape}, got shape {ch.shape}")
    _check_distribution("input_dist", px)
    _check_distribution("channel rows", ch, axis=1)
    joint = px[:, None] * ch
    return _entropy_bits(px) + _entropy_bits(joint.sum(0)) - _entropy_bits(joint.ravel())


def action_channel_capacity(num_actions: int, prob: float) -> float:
    """Closed form, in bits: the channel is symmetric, so a uniform input achieves capacity,
    C = log2 n + (1 - p + p/n) log2(1 - p + p/n) + (n - 1)(p/n) log2(p/n)."""
    n, prob = _check_num_actions(num_actions), check_probability("prob", prob)
    stay, move = 1.0 - prob + prob / n, prob / n
    terms = [stay * np.log2(stay) if stay > 0 else 0.0,
             (n - 1) * move * np.log2(move) if move > 0 else 0.0]
    return float(np.log2(n) + sum(terms))


def empirical_action_information(intended, executed, num_actions: int) -> float:
    """Plug-in estimate of I(A; Ã) in bits from logged pairs: ``intended`` and ``executed`` are
    int action ids in [0, num_actions - 1] of the same shape (any shape; paired elementwise)."""
    num_actions = _check_num_actions(num_actions)
    a, e = np.asarray(intended), np.asarray(executed)
    if a.shape != e.shape or a.size == 0:
        raise ValueError("intended and executed must be non-empty and of the same size and "
                         f"shape, got shapes {a.shape} and {e.shape}")
    a = _check_actions("intended", a, num_actions).ravel()
    e = _check_actions("executed", e, num_actions).ravel()
    joint = np.zeros((num_actions, num_actions))
    np.add.at(joint, (a, e), 1.0)
    joint /= joint.sum()
    return _entropy_bits(joint.sum(1)) + _entropy_bits(joint.sum(0)) - _entropy_bits(joint.ravel())


def next_state_variance(states) -> np.ndarray:
    """Total variance across a batch of the states reached under the same action sequence from
    the same start: ``states`` (T, B, D) -> (T,), the sum over D of the variance over B.
    Zero for a deterministic game (3.1); it grows with exogenous noise (2.1)."""
    s = _as_float_array("states", states)
    if s.ndim != 3 or 0 in s.shape:
        raise ValueError(f"states must be (T, B, D) with T, B, D >= 1, got shape {s.shape}")
    if not np.isfinite(s).all():
        raise ValueError("states must be finite numbers, got NaN or infinity")
    return s.var(axis=1).sum(axis=-1)
