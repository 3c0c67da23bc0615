"""When does a punch pay in Boxing 3.1?  Plays the random policy and prints, for each lag k,
P(reward > 0 at step t + k | FIRE at t) - P(reward > 0 at step t + k | no FIRE at t), and the
sum of those differences weighted by (gamma * lambda)^k for the updates in this folder's README,
and, by the horizontal gap between the boxers (RAM labels), how often a FIRE lands two steps later.

    python baselines/results/boxing-probes/fire_timing.py   # ~1 min on 2 cores
"""

import jax.numpy as jnp
import numpy as np

import stori_jax
from baselines import ppo

NUM_ENVS, STEPS, LAGS = 16, 4000, 16
# Boxing plays ALE's full action set, so an action's index is its ale_py.Action value.
NUM_ACTIONS = stori_jax.get_game("Boxing").num_actions
FIRE_ACTIONS = np.flatnonzero(ppo.DIRECTION_AND_FIRE[:, 1])
EVIDENCE = ppo.PPOConfig(game="Boxing", preset="3.1")  # gamma and gae_lambda of the evidence

rng = np.random.default_rng(0)
actions = rng.integers(NUM_ACTIONS, size=(STEPS, NUM_ENVS))
rewards = np.zeros((STEPS, NUM_ENVS))
gap = np.zeros((STEPS, NUM_ENVS), np.int32)  # enemy_x - player_x when the action was chosen
with stori_jax.make("Boxing", "3.1", num_envs=NUM_ENVS, seed=3, obs="atari84") as env:
    _, info = env.reset()
    for t in range(STEPS):
        labels = info["labels"]
        gap[t] = np.asarray(labels["enemy_x"], np.int32) - np.asarray(labels["player_x"], np.int32)
        _, reward, _, _, info = env.step(jnp.asarray(actions[t], dtype=jnp.int32))
        rewards[t] = np.asarray(reward)
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

print("P(reward > 0 two steps later) by horizontal gap enemy_x - player_x (RAM units):")
lands, chosen = rewards[2:] > 0, gap[:-2]
for low, high in ((-999, 0), (0, 16), (16, 28), (28, 40), (40, 999)):
    near = (chosen >= low) & (chosen < high)
    print(f"  gap [{low:4d}, {high:3d}): after FIRE {lands[near & fire[:-2]].mean():.3f}, "
          f"after no FIRE {lands[near & ~fire[:-2]].mean():.3f}, share of steps {near.mean():.2f}")
