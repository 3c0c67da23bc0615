"""When does a punch pay in Boxing 3.1?  Plays the random policy and prints, for each lag k,
P(reward > 0 at step t + k | FIRE at t) - P(reward > 0 at step t + k | no FIRE at t), and the
sum of those differences weighted by (gamma * lambda)^k for the updates in this folder's README.

    python baselines/results/boxing-probes/fire_timing.py   # ~1 min on 2 cores
"""

import ale_py
import jax.numpy as jnp
import numpy as np

import stori_jax
from baselines.ppo import PPOConfig

NUM_ENVS, STEPS, LAGS = 16, 4000, 16
# Boxing plays ALE's full action set, so an action's index is its ale_py.Action value.
NUM_ACTIONS = stori_jax.get_game("Boxing").num_actions
FIRE_ACTIONS = [a.value for a in ale_py.Action.__members__.values() if "FIRE" in a.name]
EVIDENCE = PPOConfig(game="Boxing", preset="3.1")  # gamma and gae_lambda of the evidence

rng = np.random.default_rng(0)
actions = rng.integers(NUM_ACTIONS, size=(STEPS, NUM_ENVS))
rewards = np.zeros((STEPS, NUM_ENVS))
with stori_jax.make("Boxing", "3.1", num_envs=NUM_ENVS, seed=3, obs="atari84") as env:
    env.reset()
    for t in range(STEPS):
        rewards[t] = np.asarray(env.step(jnp.asarray(actions[t], dtype=jnp.int32))[1])
fire = np.isin(actions, FIRE_ACTIONS)
print(f"reward events per step: +1 {np.mean(rewards > 0):.4f}, -1 {np.mean(rewards < 0):.4f}")
diffs = []
for k in range(LAGS):
    hit = rewards[k:] > 0
    diffs.append(hit[fire[:STEPS - k]].mean() - hit[~fire[:STEPS - k]].mean())
    print(f"k={k:2d}  {diffs[-1]:+.4f}")
for gamma_lambda in (EVIDENCE.gamma * EVIDENCE.gae_lambda, 0.95 * 0.9):  # 0.95, 0.9: a probe
    print(f"sum of (gamma*lambda)^k x difference, gamma*lambda={gamma_lambda:.3f}: "
          f"{sum(gamma_lambda ** k * d for k, d in enumerate(diffs)):+.4f}")
