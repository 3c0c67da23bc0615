"""Pure, jittable, batched functions: key in, arrays out (no Python loop over envs or pixels).

Every random function takes a batch of per-env keys (shape (B,), one key per env, see
:func:`stori_jax.functional.keys.env_keys`) so that env i's randomness does not depend on the
batch size, the number of workers or the backend.
"""

from stori_jax.functional.actions import corrupt_actions
from stori_jax.functional.drift import concept_of, concept2_probability
from stori_jax.functional.keys import Purpose, env_keys, purpose_keys
from stori_jax.functional.labels import extract_labels
from stori_jax.functional.masks import (apply_masks, draw_mask_decisions, region_mask,
                                        torch_mask)
from stori_jax.functional.preprocess import (area_resize, atari84_frame, dreamer64, max_pool,
                                             pool_screens, push_frame, reset_stack, to_gray)
from stori_jax.functional.uniforms import event_uniforms

__all__ = [
    "corrupt_actions", "concept_of", "concept2_probability", "Purpose", "env_keys",
    "purpose_keys", "extract_labels", "apply_masks", "draw_mask_decisions", "region_mask",
    "torch_mask", "area_resize", "atari84_frame", "pool_screens", "dreamer64", "max_pool", "push_frame", "reset_stack",
    "to_gray", "event_uniforms",
]
