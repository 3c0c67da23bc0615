"""Information-theoretic and variance helpers from the STORI paper (STORI_SPEC sections 1, 11).

- ``action_channel_capacity(n, p)``: capacity I(A; Ã) in bits of the type-1 channel that replaces
  the intended action, with probability p, by one drawn uniformly from all n actions.
- ``channel_matrix`` / ``mutual_information``: the same for any replacement set and input
  distribution (e.g. BankHeist's replacements 0..9 of 18 actions).
- ``empirical_action_information(intended, executed, n)``: a plug-in estimate of I(A; Ã) from
  logged (intended, executed) pairs, e.g. from ``info["executed_action"]``.
- ``next_state_variance(states)``: the spread of next states reached under a fixed action, the
  quantity of the paper's variance-calibration probe.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np


def _entropy_bits(p: np.ndarray) -> float:
    p = np.asarray(p, np.float64)
    p = p[p > 0]
    return float(-(p * np.log2(p)).sum())


def channel_matrix(num_actions: int, prob: float,
                   replacement: Sequence[int] | None = None) -> np.ndarray:
    """P(executed = j | intended = i), (n, n): with prob ``prob`` a uniform draw from
    ``replacement`` (default: all actions), else the intended action."""
    if not 0.0 <= prob <= 1.0:
        raise ValueError(f"prob must be in [0, 1], got {prob}")
    if num_actions < 1:
        raise ValueError(f"num_actions must be >= 1, got {num_actions}")
    replacement = list(range(num_actions)) if replacement is None else list(replacement)
    if not replacement or min(replacement) < 0 or max(replacement) >= num_actions:
        raise ValueError(f"replacement must be non-empty indices in [0, {num_actions - 1}]")
    m = np.eye(num_actions) * (1.0 - prob)
    m[:, replacement] += prob / len(replacement)
    return m


def mutual_information(input_dist: np.ndarray, channel: np.ndarray) -> float:
    """I(A; Ã) in bits for input distribution P(A) (n,) and channel P(Ã | A) (n, n)."""
    px = np.asarray(input_dist, np.float64)
    joint = px[:, None] * np.asarray(channel, np.float64)
    return _entropy_bits(px) + _entropy_bits(joint.sum(0)) - _entropy_bits(joint.ravel())


def action_channel_capacity(num_actions: int, prob: float) -> float:
    """Closed form, in bits: the channel is symmetric, so a uniform input achieves capacity,
    C = log2 n + (1 - p + p/n) log2(1 - p + p/n) + (n - 1)(p/n) log2(p/n)."""
    channel_matrix(num_actions, prob)  # validates
    n = num_actions
    stay, move = 1.0 - prob + prob / n, prob / n
    terms = [stay * np.log2(stay) if stay > 0 else 0.0,
             (n - 1) * move * np.log2(move) if move > 0 else 0.0]
    return float(np.log2(n) + sum(terms))


def empirical_action_information(intended, executed, num_actions: int) -> float:
    """Plug-in estimate of I(A; Ã) in bits from logged pairs (any shapes, flattened alike)."""
    a = np.asarray(intended).ravel()
    e = np.asarray(executed).ravel()
    if a.shape != e.shape or a.size == 0:
        raise ValueError("intended and executed must be non-empty and of the same size")
    joint = np.zeros((num_actions, num_actions))
    np.add.at(joint, (a, e), 1.0)
    joint /= joint.sum()
    return _entropy_bits(joint.sum(1)) + _entropy_bits(joint.sum(0)) - _entropy_bits(joint.ravel())


def next_state_variance(states) -> np.ndarray:
    """Total variance across a batch of the states reached under the same action sequence from
    the same start: ``states`` (T, B, D) -> (T,), the sum over D of the variance over B.
    Zero for a deterministic game (3.1); it grows with exogenous noise (2.1)."""
    s = np.asarray(states, np.float64)
    if s.ndim != 3:
        raise ValueError(f"states must be (T, B, D), got shape {s.shape}")
    return s.var(axis=1).sum(axis=-1)
