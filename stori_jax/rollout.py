"""Batched rollouts of a JAX policy: ``rollout(env, policy_fn, params, key, num_steps)``."""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp

from stori_jax.checks import check_int, shown


class Trajectory(NamedTuple):
    """Stacked over time: every leaf has a leading (T, B) shape; ``last_obs`` is (B, ...).
    To go on: ``rollout(env, policy_fn, params, traj.last_key, n, obs=traj.last_obs)``."""

    obs: jax.Array          # the observation each action was chosen from
    action: jax.Array
    reward: jax.Array
    terminated: jax.Array
    truncated: jax.Array
    info: dict
    last_obs: jax.Array     # the observation after the final step
    last_key: jax.Array     # the key after the final step's split: the next rollout's key


def _is_prng_key(key) -> bool:
    """A typed key (jax.random.key) or legacy uint32 key data of shape (2,)."""
    if not isinstance(key, jax.Array):
        return False
    if jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        return key.shape == ()
    return key.shape == (2,) and key.dtype == jnp.uint32


def rollout(env, policy_fn: Callable[[Any, jax.Array, jax.Array], jax.Array], params,
            key: jax.Array, num_steps: int, *, obs: jax.Array | None = None,
            seed: int | None = None) -> Trajectory:
    """Run ``num_steps`` agent steps of ``env`` under ``policy_fn(params, obs, key) -> (B,)``.

    Starts from ``obs`` when given (continuing a run), else resets the env: ``reset(seed=seed)``
    with a ``seed`` (the run of ``make(..., seed=seed)``, however the env was used before), a
    plain ``reset()`` without (the env's streams go on: a second rollout plays other episodes).
    The policy is jitted here; its randomness comes from ``key`` (split once per step), so the
    same key, params and seed give the same trajectory.  Give the agent a key of its own, such as
    ``stori_jax.agent_key(seed)``: an env of ``seed`` draws from the chain of
    ``jax.random.PRNGKey(seed)``, split as here, so that key would sample the policy's actions
    with the env's own step keys.
    """
    from stori_jax.env import Env

    if not isinstance(env, Env):
        raise ValueError(f"env must be a batched stori_jax.Env (stori_jax.make), got "
                         f"{type(env).__name__}")
    num_steps = check_int("num_steps", num_steps, 1)
    if not _is_prng_key(key):
        given = (f"an array of shape {key.shape} and dtype {key.dtype}"
                 if isinstance(key, jax.Array) else shown(key))
        raise ValueError(f"key must be a JAX PRNG key (jax.random.key(seed) or "
                         f"jax.random.PRNGKey(seed)), got {given}")
    if obs is not None and seed is not None:
        raise ValueError("rollout takes obs (go on from the env's current observation) or seed "
                         "(reset the env with that seed first), not both")
    policy = jax.jit(policy_fn)
    if obs is None:
        obs, _ = env.reset(seed=seed)
    else:
        space = env.observation_space
        if not hasattr(obs, "dtype") or tuple(obs.shape) != space.shape \
                or jnp.result_type(obs) != space.dtype:  # a list has no dtype of its own
            raise ValueError(f"obs must be the env's current observation, of shape {space.shape} "
                             f"and dtype {space.dtype} (the last step's), got "
                             + (f"shape {tuple(obs.shape)} and dtype {obs.dtype}"
                                if hasattr(obs, "dtype") else shown(obs)))
    steps = []
    for _ in range(num_steps):
        key, step_key = jax.random.split(key)
        actions = policy(params, obs, step_key)
        next_obs, reward, terminated, truncated, info = env.step(actions)
        steps.append((obs, actions, reward, terminated, truncated, info))
        obs = next_obs
    stacked = jax.tree.map(lambda *xs: jnp.stack(xs), *steps)
    return Trajectory(*stacked, last_obs=obs, last_key=key)
