"""envpool's Python API over stori_jax: ``import envpool_bridge as envpool``, then
``envpool.make("Breakout-3.1-v5", ...)`` (docs/drop-in.md).  The envpool *backend* of
``stori_jax.make(..., backend="envpool")`` is ``stori_jax.backends.envpool``."""

from envpool_bridge.facade import make  # noqa: F401

__all__ = ["make"]
