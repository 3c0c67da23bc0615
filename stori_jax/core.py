"""The JAX side of one env step: what happens before the emulators run and after.

``before_step`` draws everything random (executed actions, event uniforms, mask and RAM-obs
decisions, concept, reset no-ops); ``after_step`` masks and preprocesses the screens and updates
the env state.  Both are pure functions of (plan, state, inputs); a :class:`Plan`'s structure
is static, its numbers traced (see stori_jax.plan).
"""

from __future__ import annotations

import collections
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from stori_jax import functional as F
from stori_jax.backends.layout import (FINAL_OUTPUTS, RESET_RENDER_BITS, STEP_OUTPUTS,
                                      STEP_RENDER_BITS)
from stori_jax.checks import MAX_SEED, check_int, unless_traced
from stori_jax.functional.preprocess import (ATARI84, STACK, pack_stack, push_packed,
                                             unpack_stack)
from stori_jax.games import get_game
from stori_jax.objects import has_objects, hidden_pixels, objects_array
from stori_jax.pixels import OBSERVATION_LAYOUTS
from stori_jax.plan import Plan


class EnvState(NamedTuple):
    key: jax.Array
    episode_step: jax.Array    # (B,) agent steps taken in the current episode
    prev_executed: jax.Array   # (B,) last executed action (sticky actions)
    stack: jax.Array           # (B, 84, 84, 4) for atari84, else a (B,) placeholder


class Draws(NamedTuple):
    """Everything random about one step (drawn before the emulators run)."""

    executed: jax.Array        # (B, frame_skip) int32, what the emulators execute
    executed_slots: jax.Array  # (B, num_slots): per frame, or (B, 1) at step granularity
    corrupted: jax.Array       # (B, num_slots) bool
    event_u: jax.Array         # (B, frame_skip, 2) float32
    event_active: jax.Array    # (B,) uint8
    ram_render: jax.Array      # (B,) uint8 bits
    noops: jax.Array           # (B,) int32
    concept: jax.Array         # (B,) int32
    mask_apply: jax.Array      # (B, 2) bool, before the concept/new-episode gate
    mask_centres: jax.Array    # (B, 2, 2) int32
    step_active: jax.Array     # (B,) bool: the mask/RAM-obs component is on for this step


AGENT_STREAM = 0x61676E74  # "agnt": far above any env index the env's keys are folded with


def env_key(seed: int) -> jax.Array:
    """The root of an env's key chain: every draw of a run of ``seed`` comes from it."""
    return jax.random.PRNGKey(seed)


def agent_key(seed: int) -> jax.Array:
    """A key for an agent's own draws (action sampling, initialisation) beside an env of
    ``seed``.  Not ``jax.random.PRNGKey(seed)``: the env's chain starts there, and an agent
    splitting that key the env's way would sample its actions with the very keys the env's
    draws come from.  ``seed`` is an int in [0, 2^31 - 1], as an env's is (a larger one
    would alias a smaller one's key); a traced one (under jit or vmap) is taken as it is."""
    seed = unless_traced(check_int, "seed", seed, 0, MAX_SEED)
    return jax.random.fold_in(env_key(seed), AGENT_STREAM)


def initial_state(plan: Plan, seed: int) -> EnvState:
    b = plan.num_envs
    stack = (jnp.zeros((b, ATARI84, ATARI84, STACK), jnp.uint8) if plan.obs == "atari84"
             else jnp.zeros((b,), jnp.uint8))
    return EnvState(key=env_key(seed), episode_step=jnp.zeros((b,), jnp.int32),
                    prev_executed=jnp.zeros((b,), jnp.int32), stack=stack)


def _component_active(under_drift: bool, concept: jax.Array) -> jax.Array:
    return concept == 1 if under_drift else jnp.ones(concept.shape, bool)


@functools.partial(jax.jit, static_argnames=("resetting",))
def before_step(plan: Plan, state: EnvState, actions: jax.Array, resetting: bool = False):
    """(new state, Draws) for one agent step (or, with ``resetting``, for a reset of all envs)."""
    b, skip = plan.num_envs, plan.frame_skip
    key, step_key = jax.random.split(state.key)
    keys = F.env_keys(step_key, b)
    if plan.drift_schedule is not None and not resetting:
        concept = F.concept_of(F.purpose_keys(keys, F.Purpose.DRIFT), state.episode_step,
                               plan.drift_schedule, plan.drift_period)
    else:
        concept = jnp.zeros((b,), jnp.int32)

    actions = jnp.asarray(actions, jnp.int32)
    if plan.noise is not None:
        n = plan.noise
        slots, corrupted = F.corrupt_actions(
            F.purpose_keys(keys, F.Purpose.ACTIONS), actions, state.prev_executed,
            prob=n.prob, num_slots=plan.num_slots, sticky=n.sticky,
            replacement=None if n.sticky else n.replacement,
            active=_component_active(n.under_drift, concept))
    else:
        slots = jnp.broadcast_to(actions[:, None], (b, plan.num_slots))
        corrupted = jnp.zeros((b, plan.num_slots), bool)
    executed = slots if plan.per_frame else jnp.repeat(slots, skip, axis=1)

    if plan.event is not None:
        event_u = F.event_uniforms(F.purpose_keys(keys, F.Purpose.EVENTS), skip)
        event_active = _component_active(plan.event.under_drift, concept)
    else:
        event_u = jnp.ones((b, skip, 2), jnp.float32)
        event_active = jnp.zeros((b,), bool)

    mask_apply = jnp.zeros((b, 2), bool)
    centres = jnp.zeros((b, 2, 2), jnp.int32)
    step_active = jnp.zeros((b,), bool)
    ram_render = jnp.zeros((b,), jnp.uint8)
    if plan.mask is not None:
        m = plan.mask
        mask_apply, centres = F.draw_mask_decisions(
            F.purpose_keys(keys, F.Purpose.OBSERVATION), prob=m.prob, per_frame=plan.per_frame,
            torch=m.torch)
        step_active = _component_active(m.under_drift, concept) & (not resetting)
        if m.kind == "ram":
            # the first obs of an episode is seen under concept 1 (episode step 0)
            reset_on = not m.under_drift
            bits = jnp.zeros((b,), jnp.int32)
            for slot in range(2):
                bits |= jnp.where(mask_apply[:, slot] & step_active, STEP_RENDER_BITS[slot], 0)
            if reset_on:
                # a reset shows one emulator frame (in both slots): one decision for it
                bits |= jnp.where(mask_apply[:, 1], RESET_RENDER_BITS[0] | RESET_RENDER_BITS[1],
                                  0)
            ram_render = bits.astype(jnp.uint8)

    if plan.noop_max > 0:
        noops = jax.vmap(lambda k: jax.random.randint(k, (), 0, plan.noop_max + 1, jnp.int32))(
            F.purpose_keys(keys, F.Purpose.NOOPS))
    else:
        noops = jnp.zeros((b,), jnp.int32)

    new_state = state._replace(key=key, prev_executed=executed[:, -1])
    draws = Draws(executed=executed, executed_slots=slots, corrupted=corrupted, event_u=event_u,
                  event_active=event_active.astype(jnp.uint8), ram_render=ram_render,
                  noops=noops.astype(jnp.int32), concept=concept, mask_apply=mask_apply,
                  mask_centres=centres, step_active=step_active)
    return new_state, draws


# What the backend returned for one step (numpy views; copied out by ``after_step``): the
# emulators' outputs of backends.layout.STEP_BUFFERS.  The final_* ones (an autoresetting
# env's step where an episode ended: what frames, single_frame and ram held before the
# autoreset) are None where no episode ended (the same step compiled without them).
WorkerOutputs = collections.namedtuple("WorkerOutputs", STEP_OUTPUTS + FINAL_OUTPUTS,
                                       defaults=(None,) * len(FINAL_OUTPUTS))


def observe(plan: Plan, game, draws: Draws, frames, ram, ram_rendered, single_frame,
            new_episode, screen_ram):
    """(observation, masked) of one set of the workers' screens (or RAM): the step's mask
    decisions applied (gated by the concept, or, for the first frame of an episode, by whether
    the mask shows on resets), then preprocessed (atari84: one frame, not yet stacked)."""
    masked = jnp.zeros((plan.num_envs,), bool)
    if plan.mask is not None and plan.mask.kind == "ram":
        masked = ram_rendered != 0
    if plan.frames_layout in OBSERVATION_LAYOUTS:  # made by the emulating processes (no mask)
        return frames + jnp.uint8(0), masked
    if plan.mask is not None and plan.mask.kind != "ram" and plan.screens:
        m = plan.mask
        reset_on = not m.under_drift
        gate = jnp.where(new_episode, reset_on, draws.step_active)
        pair = plan.frames_layout == "pair"
        # a pooled screen gets one decision per step (the backend pools only when that is exact)
        slots = ([frames[0], frames[1]] if pair else [F.pool_screens(frames, plan.frames_layout)])
        masked_slots = []
        # one emulator frame in both slots of a pair (the first obs of an episode, frame_skip
        # 1, an early end) gets one decision (and one torch centre), slot 1's, like any frame
        single = new_episode | (single_frame != 0)
        for j, screen in enumerate(slots):
            k = jnp.where(single & pair, 1, j)  # a pooled screen: slot 0's, always
            apply = jnp.take_along_axis(draws.mask_apply, k[:, None], 1) & gate[:, None]
            if m.torch:
                centres = jnp.take_along_axis(draws.mask_centres, k[:, None, None], 1)
                screen = F.apply_masks(screen[:, None], apply, centres=centres)[:, 0]
            elif m.kind == "objects":  # this screen's boxes, from its own RAM (a pair always)
                hidden = (hidden_pixels(plan.game, screen_ram[:, j], m.classes)
                          & apply[:, :, None])
                screen = jnp.where(hidden[..., None], jnp.uint8(0), screen)
            else:
                hidden, fill = plan.static_mask(game)
                screen = F.apply_masks(screen[:, None], apply, hidden=hidden, fill=fill)[:, 0]
            masked_slots.append(screen)
            masked = masked | apply[:, 0]
        screen = (jnp.maximum(masked_slots[0], masked_slots[1]) if pair else masked_slots[0])
    else:
        screen = F.pool_screens(frames, plan.frames_layout) if plan.screens else None

    if plan.obs == "raw":
        obs = screen
    elif plan.obs == "atari84":
        obs = F.atari84_frame(screen)  # stacked by push_frames (a separate compilation)
    elif plan.obs == "dreamer64":
        obs = F.dreamer64(screen)
    elif plan.obs == "objects":
        obs = objects_array(plan.game, ram)
    else:
        obs = ram + jnp.uint8(0)
    return obs, masked


def final_observations(plan: Plan, game, draws: Draws, out: WorkerOutputs, obs):
    """info["final_obs"] of an autoresetting env (atari84: its newest frame, stacked by
    :func:`push_frames`): where the step ended an episode, the observation it ended on (a
    stepped frame, not an episode's first), as the env with ``autoreset=False`` returns it;
    elsewhere a copy of ``obs`` (its own buffer, as every output is).  Without the final_*
    outputs (no episode ended this step): the copy alone."""
    if out.final_frames is None:
        return obs + jnp.uint8(0)
    final, _ = observe(plan, game, draws, out.final_frames, out.final_ram, out.ram_rendered,
                       out.final_single_frame, jnp.zeros((plan.num_envs,), bool),
                       out.final_screen_ram)
    done = ended(out)
    return jnp.where(jnp.reshape(done, done.shape + (1,) * (obs.ndim - 1)), final, obs)


@functools.partial(jax.jit, static_argnames=("game", "autoreset"))
def step_objects(game: str, autoreset: bool, ram, final_ram, done) -> dict:
    """info["objects"] (type 0, on every game with an object table) and, with ``autoreset``,
    info["final_objects"]: where the step ended an episode (``done``, see :func:`ended`), the
    objects of the RAM it ended on (``final_ram``; None where no episode ended), as
    info["final_obs"] is its observation,
    elsewhere a copy.  Compiled apart from ``after_step``: one compilation per game and batch
    size serves every config of the game."""
    info = {"objects": objects_array(game, ram)}
    if autoreset:
        info["final_objects"] = (info["objects"] + 0 if final_ram is None else
                                 jnp.where(done[:, None, None], objects_array(game, final_ram),
                                           info["objects"]))
    return info


def ended(out: WorkerOutputs):
    """(B,) bool where the step ended an episode (numpy for numpy outputs)."""
    return (out.terminated != 0) | (out.truncated != 0)


@jax.jit
def after_step(plan: Plan, state: EnvState, draws: Draws, out: WorkerOutputs, new_episode,
               reset_step):
    """(new state, obs, reward, terminated, truncated, info) from the workers' outputs, in one
    compiled call (every output is a fresh array: the workers' buffers may be reused).

    ``new_episode`` (B,) bool marks envs whose observation is the first of an episode;
    ``reset_step`` those that were reset instead of stepped (next-step autoreset)."""
    game = get_game(plan.game)
    obs, masked = observe(plan, game, draws, out.frames, out.ram, out.ram_rendered,
                          out.single_frame, new_episode, out.screen_ram)
    slots_out = (lambda x: x) if plan.per_frame else (lambda x: x[:, 0])
    # an env reset instead of stepped played no-ops (NOOP), not this step's drawn actions, and
    # its first observation is seen under concept 1
    stepped = ~jnp.asarray(reset_step, bool)
    # the slots ALE played: none where the env was reset instead (frames_played 0), and (at
    # frame granularity) none after the frame its episode ended on
    played = jnp.arange(plan.num_slots)[None, :] < out.frames_played[:, None]
    info = {
        "executed_action": slots_out(jnp.where(played, draws.executed_slots, 0)),
        "action_corrupted": slots_out(draws.corrupted & played),
        "event_fired": out.event_fired + 0,
        "concept": jnp.where(stepped, draws.concept, 0),
        "obs_masked": masked,
        "lives": out.lives + 0,
        "ram": out.ram + jnp.uint8(0),
        "labels": F.extract_labels(game, out.ram),
        "episode_return": out.episode_return + 0,
        "episode_length": out.episode_length + 0,
        "reset_step": reset_step,
        "frames_played": out.frames_played + 0,
    }
    if plan.autoreset:
        info["final_obs"] = final_observations(plan, game, draws, out, obs)
    episode_step = jnp.where(new_episode, 0, state.episode_step + 1)
    # a new episode starts from NOOP (action 0), as after env.reset(): sticky actions never
    # repeat the last action of the episode before
    prev_executed = jnp.where(new_episode, 0, state.prev_executed)
    new_state = state._replace(episode_step=episode_step, prev_executed=prev_executed)
    return (new_state, obs, out.reward + 0, out.terminated != 0, out.truncated != 0, info)


def finish_step(plan: Plan, state: EnvState, draws: Draws, out: WorkerOutputs, reset_first):
    """The end of a step, shared by ``Env`` (numpy outputs of the workers) and the traced
    step of ``env.xla()``: (new state, (obs, reward, terminated, truncated, info), the envs
    due for a reset on the next step).  ``reset_first`` (B,) bool marks envs that were reset
    instead of stepped (next-step autoreset, or a reset of all)."""
    done = ended(out)
    new_episode = reset_first | done if plan.autoreset else reset_first
    state, obs, reward, terminated, truncated, info = after_step(
        plan, state, draws, out, new_episode, reset_first)
    final_obs = info.pop("final_obs", None)
    if has_objects(plan.game):
        info.update(step_objects(plan.game, plan.autoreset, out.ram, out.final_ram, done))
    if final_obs is not None:
        info["final_obs"] = final_obs
    if plan.obs == "atari84":
        if isinstance(obs, jax.core.Tracer):  # traced with its caller: keep the two apart
            obs = jax.lax.optimization_barrier(obs)
        final = info.pop("final_obs", None)
        stack, obs, final = push_frames(state.stack, obs, new_episode, final, done)
        state = state._replace(stack=stack)
        if plan.autoreset:
            info["final_obs"] = final
    pending = done if not plan.autoreset else done & False
    return state, (obs, reward, terminated, truncated, info), pending


@jax.jit
def push_frames(stack, frame, new_episode, final_frame=None, done=None):
    """The atari84 frame stack.  Compiled on its own: fused with the resize above, XLA would
    recompute the resize for each of the 4 stack slots of a new episode (measured 4x slower).
    (the env's stack, the observation, the final observation): two buffers for the first two,
    so that a caller who donates the observation to a jit of its own leaves the env's state
    intact.  The final observation (None without ``final_frame``, the newest frame of
    :func:`final_observations`): where ``done``, ``final_frame`` pushed onto the stack the
    episode ended with, elsewhere a third copy of the observation."""
    packed = pack_stack(stack)
    new_stack = push_packed(packed, frame, new_episode)
    if final_frame is None:
        return unpack_stack(new_stack), unpack_stack(new_stack), None
    final = jnp.where(done[:, None, None], push_packed(packed, final_frame), new_stack)
    return unpack_stack(new_stack), unpack_stack(new_stack), unpack_stack(final)
