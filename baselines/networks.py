"""What every agent's network is built from: the Atari conv torsos (``NETWORKS``, ``TORSOS``,
:class:`Conv`, :func:`conv_torso`) and DrQ/RAD's random shift of frame stacks
(:func:`random_shift`).  Tuning one agent's network or augmentation is a change to its own
file; a change here changes every agent."""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

NETWORKS = ("nature", "nips", "tiny")
TORSOS = {  # (features, kernel, stride) per conv layer, then the dense layer's width
    "nature": ([(32, 8, 4), (64, 4, 2), (64, 3, 1)], 512),  # Mnih 2015
    "nips": ([(16, 8, 4), (32, 4, 2)], 256),  # Mnih 2013, 3x cheaper
    "tiny": ([(8, 8, 4)], 32),
}


def space_to_depth(x: jax.Array, block: int) -> jax.Array:
    n, h, w, c = x.shape
    x = x.reshape(n, h // block, block, w // block, block, c).transpose(0, 1, 3, 2, 4, 5)
    return x.reshape(n, h // block, w // block, block * block * c)


def patches(x: jax.Array, size: int) -> jax.Array:
    """Every ``size`` x ``size`` window (stride 1, VALID) flattened into the channel axis."""
    n, h, w, c = x.shape
    oh, ow = h - size + 1, w - size + 1
    return jnp.concatenate([x[:, i:i + oh, j:j + ow] for i in range(size) for j in range(size)],
                           axis=-1)


class Conv(nn.Module):
    """A VALID convolution written as space-to-depth + window gather + one matmul: the same
    function as ``nn.Conv(features, (k, k), (s, s))`` (weights in another order), about twice as
    fast to train on a CPU, where XLA's strided convolutions are slow."""

    features: int
    kernel: int
    stride: int

    @nn.compact
    def __call__(self, x):
        if self.kernel % self.stride or x.shape[1] % self.stride or x.shape[2] % self.stride:
            raise ValueError(f"Conv needs kernel and input divisible by the stride, got kernel "
                             f"{self.kernel}, stride {self.stride}, input {x.shape[1:3]}")
        x = patches(space_to_depth(x, self.stride), self.kernel // self.stride)
        return nn.Dense(self.features, kernel_init=nn.initializers.orthogonal(np.sqrt(2)))(x)


def conv_torso(obs: jax.Array, network: str) -> jax.Array:
    """(B, features): the conv layers of ``TORSOS[network]`` (ReLU after each) on frame stacks
    in pixel units, flattened.  Called inside a module's ``nn.compact`` method, whose
    parameters they become (``Conv_0``, ``Conv_1``, ...); the dense layer is the agent's."""
    convs, _ = TORSOS[network]
    x = obs.astype(jnp.float32) / 255.0
    for features, kernel, stride in convs:
        x = nn.relu(Conv(features, kernel, stride)(x))
    return x.reshape(x.shape[0], -1)


def random_shift(obs: jax.Array, key, pad: int) -> jax.Array:
    """DrQ's image augmentation: each (H, W, C) frame stack of the batch padded by ``pad``
    pixels (edges repeated) and cropped back to (H, W) at its own random offset, so the whole
    stack moves by up to ``pad`` pixels in each direction."""
    n, h, w, c = obs.shape
    padded = jnp.pad(obs, ((0, 0), (pad, pad), (pad, pad), (0, 0)), mode="edge")
    offsets = jax.random.randint(key, (n, 2), 0, 2 * pad + 1)
    return jax.vmap(lambda frame, at: jax.lax.dynamic_slice(frame, (at[0], at[1], 0), (h, w, c)))(
        padded, offsets)
