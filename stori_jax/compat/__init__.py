"""Compatibility with other APIs: gymnasium's envs and ids (:mod:`stori_jax.compat.gymnasium`)
and ale-py's ``AtariEnv`` keywords and ``ALEInterface`` (:mod:`stori_jax.compat.ale`).

Nothing is imported here: ``import stori_jax`` registers the gymnasium ids itself.
"""
