"""Type 1: action corruption (uniform replacement from a set, or sticky repeat)."""

from __future__ import annotations

from typing import Sequence

import jax
import jax.numpy as jnp

from stori_jax.checks import (check_action_indices, check_bool, check_draw_probability,
                              check_dtype, check_int, unless_traced)


def corrupt_actions(keys: jax.Array, actions: jax.Array, prev_executed: jax.Array, *,
                    prob: float, num_slots: int, replacement: Sequence[int] | None = None,
                    sticky: bool = False, active: jax.Array | None = None):
    """Executed actions for one agent step.

    keys (B,), actions (B,) intended, prev_executed (B,) the last executed action (for sticky).
    ``num_slots`` = frame_skip at ``frame`` granularity (an independent draw per emulator frame)
    or 1 at ``step`` granularity.  ``active`` (B,) bool switches corruption off per env (drift).

    Returns (executed (B, num_slots) int32, corrupted (B, num_slots) bool) where ``corrupted``
    marks the slots on which the channel fired (a replacement was drawn or the previous action
    repeated; a uniform replacement may equal the intended action).
    """
    prob = unless_traced(check_draw_probability, "prob", prob)
    num_slots = check_int("num_slots", num_slots, 1)
    sticky = check_bool("sticky", sticky)
    if sticky and replacement is not None:
        raise ValueError("corrupt_actions: replacement must be None when sticky=True (sticky "
                         "repeats the previous executed action)")
    if not sticky:
        replacement = check_action_indices(
            "replacement", replacement,
            "a non-empty sequence of action indices >= 0 when sticky=False")
    for name, array in (("actions", actions), ("prev_executed", prev_executed)):
        check_dtype(name, array, "iu", "action indices (an integer dtype; a float would be "
                    "truncated)")
    actions = jnp.asarray(actions, jnp.int32)
    prev_executed = jnp.asarray(prev_executed, jnp.int32)

    def one_env(key, action, prev):
        k_fire, k_choice = jax.random.split(key)
        fire = jax.random.uniform(k_fire, (num_slots,), jnp.float32) < prob
        if sticky:
            # executed[f] = executed[f-1] if fire[f] else action  => repeats `prev` only while
            # every slot so far fired, afterwards it repeats `action` itself.
            stuck = jnp.cumprod(fire.astype(jnp.int32)).astype(bool)
            executed = jnp.where(stuck, prev, action)
        else:
            table = jnp.asarray(replacement, jnp.int32)
            choice = table[jax.random.randint(k_choice, (num_slots,), 0, table.shape[0],
                                                jnp.int32)]
            executed = jnp.where(fire, choice, action)
        return executed, fire

    executed, fired = jax.vmap(one_env)(keys, actions, prev_executed)
    if active is not None:
        check_dtype("active", active, "b", "bools (B,)")
        on = jnp.asarray(active, bool)[:, None]
        executed = jnp.where(on, executed, actions[:, None])
        fired = fired & on
    return executed.astype(jnp.int32), fired
