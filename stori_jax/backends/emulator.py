"""One env's emulation, in whichever process runs it (a worker, or the calling process for its
own share): an ALE emulator, the STORI bookkeeping of its episodes, and the frame work on its
screens (``stori_jax.pixels``).

Deterministic: everything random arrives in the shared buffers (executed actions, event
uniforms, RAM-obs render decisions, reset no-ops).  Imports numpy, ale-py and the game tables
only (no JAX), so a worker starts fast.
"""

from __future__ import annotations

import copy
import pickle
from dataclasses import dataclass

import numpy as np

from stori_jax.backends import ale_cache
from stori_jax.backends.layout import RESET_RENDER_BITS, SCREEN, STEP_RENDER_BITS
from stori_jax.games.base import ram_write_rule
from stori_jax.pixels import OBSERVE


def emulator_seed(seed: int, index: int) -> int:
    """The ALE seed of env ``index`` of a batch seeded ``seed``: a function of the two alone, so
    a seed gives the same emulators however the batch is split between processes."""
    return int(np.random.SeedSequence([seed, index]).generate_state(1)[0] & 0x7FFFFFFF)


@dataclass(frozen=True)
class EmulatorSpec:
    """Everything a process's emulators need besides the shared buffers (picklable):
    ``envs``, the batch indices of this process's envs; ``seeds``, their ALE seeds."""

    game: str
    envs: tuple[int, ...]
    seeds: tuple[int, ...]
    frame_skip: int
    per_frame: bool
    event_mode: int | None
    event_prob: float
    ram_obs_mode: int | None
    want_screens: bool
    max_episode_frames: int
    autoreset: bool = True
    # how this process hands its screens over (stori_jax.pixels): "pair" (both, as made),
    # "pooled" (max-pooled into slot 0 here), or the observation made here ("atari84",
    # "dreamer64"), the screens staying in this process
    frames_layout: str = "pair"
    want_screen_ram: bool = False  # the RAM each handed-over screen was made from (objects)
    ram_event: tuple | None = None  # a RamEvent's (address, values, when): the event rule


class Emulator:
    """One ALE emulator and its per-episode STORI bookkeeping."""

    def __init__(self, spec: EmulatorSpec, game, seed: int, index: int, views: dict):
        from ale_py import roms

        self.rom_path = roms.get_rom_path(game.rom_id)
        self.ale = ale = ale_cache.acquire(self.rom_path, spec.max_episode_frames, seed)
        self.actions = list(ale.getMinimalActionSet())
        self.noop = self.actions[0]
        self.spec = spec
        self.i = index
        self.rule = (game.event_modes[spec.event_mode] if spec.event_mode is not None
                     else ram_write_rule(*spec.ram_event) if spec.ram_event is not None else None)
        self.ram_obs = game.ram_obs_modes[spec.ram_obs_mode] if spec.ram_obs_mode is not None else None
        self.v = views
        self.ram = views["ram"][index]          # true RAM, written in place
        self.observe = OBSERVE.get(spec.frames_layout)  # the frame work done here, if any
        if self.observe is None:  # the screens are handed over: written where the parent reads
            self.frames = views["frames"][:, index]  # (2, 210, 160, 3), each slot contiguous
        else:
            self.frames = np.zeros((2,) + SCREEN, np.uint8)
        self.screen_ram = views["screen_ram"][index]  # (2, 128): each screen's RAM
        self.prev_ram = np.zeros(128, np.uint8)
        self.start_ram = np.zeros(128, np.uint8)

    # -- episode boundaries -------------------------------------------------------------------

    def reset(self) -> None:
        ale, v, i = self.ale, self.v, self.i
        ale.reset_game()
        # the episode-start RAM is read right after the reset, before the no-ops (which move
        # the game on: Boxing's enemy walks away from its start corner)
        ale.getRAM(self.start_ram)
        for _ in range(int(v["noops"][i])):
            ale.act(self.noop)
            if ale.game_over():
                ale.reset_game()
                ale.getRAM(self.start_ram)
        ale.getRAM(self.prev_ram)
        self.rule_state = self.rule.new_state() if self.rule is not None else None
        self.carry = 0.0
        self.episode_return = 0.0
        self.episode_length = 0
        rendered = 0
        v["single_frame"][i] = 1
        if self.spec.want_screen_ram:
            ale.getRAM(self.screen_ram[0])
            self.screen_ram[1] = self.screen_ram[0]
        if self.spec.want_screens:
            ale.getScreenRGB(self.frames[0])
            self.frames[1] = self.frames[0]
            for slot, bit in enumerate(RESET_RENDER_BITS):
                if v["ram_render"][i] & bit and self.render_ram_obs(slot):
                    rendered |= 1 << slot
            self.publish()
        ale.getRAM(self.ram)
        v["ram_rendered"][i] = rendered
        v["lives"][i] = ale.lives()

    def start_episode(self, batch_seed: int | None = None) -> None:
        """A reset the parent asked for (not an autoreset): it reports no step's outcome, so
        the previous step's reward, ends, events and episode totals do not carry over.  With
        ``batch_seed``, the emulator first starts afresh as env ``i`` of a batch of that seed
        (ALE applies its seed when it loads the ROM: a reload is a new emulator)."""
        if batch_seed is not None:
            ale_cache.reload(self.ale, self.rom_path, self.spec.max_episode_frames,
                             emulator_seed(batch_seed, self.i))
        for name in ("reward", "terminated", "truncated", "event_fired", "episode_return",
                     "episode_length", "frames_played"):
            self.v[name][self.i] = 0
        self.reset()

    def release(self) -> None:
        """Give the ALE emulator back for reuse (``ale_cache``): this one is done."""
        if self.ale is not None:
            ale_cache.release(self.ale, self.rom_path, self.spec.max_episode_frames)
            self.ale = None

    # -- snapshots --------------------------------------------------------------------------

    def snapshot(self) -> dict:
        """This emulator's whole state (ALE with its RNG, and the STORI bookkeeping), picklable."""
        return dict(ale=pickle.dumps(self.ale.cloneState(include_rng=True)),
                    prev_ram=self.prev_ram.copy(), start_ram=self.start_ram.copy(),
                    rule_state=copy.deepcopy(self.rule_state), carry=self.carry,
                    episode_return=self.episode_return, episode_length=self.episode_length,
                    max_episode_frames=self.spec.max_episode_frames)  # an ALE setting, not state

    def restore(self, snap: dict) -> None:
        self.ale.restoreState(pickle.loads(snap["ale"]))
        self.prev_ram[:] = snap["prev_ram"]
        self.start_ram[:] = snap["start_ram"]
        self.rule_state = copy.deepcopy(snap["rule_state"])
        self.carry = snap["carry"]
        self.episode_return = snap["episode_return"]
        self.episode_length = snap["episode_length"]
        self.ale.getRAM(self.ram)

    def publish(self, final: bool = False) -> None:
        """Hand the step's screens over as ``frames_layout`` says (into ``final_frames``: an
        ended episode's, before the autoreset overwrites them)."""
        layout = self.spec.frames_layout
        if self.observe is not None:
            self.observe(self.frames, self.v["final_frames" if final else "frames"][self.i])
            return
        if layout == "pooled":
            np.maximum(self.frames[0], self.frames[1], out=self.frames[0])
        if final:
            self.v["final_frames"][:, self.i] = self.frames

    def render_ram_obs(self, slot: int, event_active: bool = False) -> bool:
        """Screen ``slot`` <- the next frame under NOOP of a RAM-modified copy of the game.
        False where nothing was rendered: the mode's condition does not hold, or the episode
        has ended (ALE emulates no frame past an episode's end, so the screen stays true).
        ``event_active``: an event is on, so the next frame, like every true one, first gets
        its rule's standing writes (Boxing's colour flip, which the game undoes every frame),
        then the mode's own."""
        ale = self.ale
        if ale.game_over():  # a game over or the frame cap
            return False
        ale.getRAM(self.ram)
        writes = self.ram_obs.writes(self.ram)
        if writes is None:
            return False
        standing = {}
        if event_active and self.rule is not None and self.rule.pre_frame is not None:
            # decide=False: re-apply the standing effect only, no draw (EventRule's contract)
            standing, _ = self.rule.pre_frame(self.start_ram, dict(self.rule_state), 1.0,
                                              self.spec.event_prob, False)
        state = ale.cloneState()
        for address, value in {**standing, **writes}.items():
            ale.setRAM(address, value)
        ale.act(self.noop)
        ale.getScreenRGB(self.frames[slot])
        ale.restoreState(state)
        return True

    # -- one agent step -----------------------------------------------------------------------

    def step(self) -> None:
        ale, v, i, spec = self.ale, self.v, self.i, self.spec
        if v["reset_first"][i]:
            self.start_episode()
            return
        skip, per_frame = spec.frame_skip, spec.per_frame
        executed = v["executed"][i]
        u = v["event_u"][i]
        rule = self.rule
        active = bool(v["event_active"][i]) and rule is not None
        render_bits = int(v["ram_render"][i])
        total = interval = 0.0
        fired = rendered = 0
        terminated = truncated = False
        for f in range(skip):
            draw = f if per_frame else 0
            if active and rule.pre_frame is not None:
                writes, hit = rule.pre_frame(self.start_ram, self.rule_state, float(u[draw, 0]),
                                             spec.event_prob, per_frame or f == 0)
                for address, value in writes.items():
                    ale.setRAM(address, value)
                fired += hit
            interval += ale.act(self.actions[executed[f]]) + self.carry
            self.carry = 0.0
            terminated = ale.game_over(with_truncation=False)
            truncated = ale.game_truncated()
            done = terminated or truncated
            if spec.want_screen_ram and (f >= skip - 2 or done):
                # the RAM the frame was drawn from (before an event rule's writes after it)
                ale.getRAM(self.screen_ram[1 if f == skip - 1 or done else 0])
            if per_frame or f == skip - 1 or done:
                if rule is not None and rule.post_frame is not None:
                    ale.getRAM(self.ram)
                    if active:
                        out = rule.post_frame(self.prev_ram, self.ram, self.start_ram,
                                              self.rule_state, float(u[draw, 0]),
                                              float(u[draw, 1]), spec.event_prob,
                                              ale.getEpisodeFrameNumber())
                        for address, value in out.writes.items():
                            ale.setRAM(address, value)
                            self.ram[address] = value
                        if out.zero_reward:
                            if out.cancel_next_reward:
                                self.carry = interval
                            interval = 0.0
                        fired += out.fired
                    self.prev_ram[:] = self.ram
                total += interval
                interval = 0.0
            ends_early = done and f < skip - 1  # observed (after an autoreset: as final_*)
            if spec.want_screens and (f >= skip - 2 or ends_early):
                # slot 1: the step's last frame (the episode's last, where it ends early)
                slot = 1 if f == skip - 1 or ends_early else 0
                ale.getScreenRGB(self.frames[slot])
                if render_bits & STEP_RENDER_BITS[slot] and self.render_ram_obs(slot, active):
                    rendered |= 1 << slot
            if done:
                break
        # one emulator frame makes the observation (both slots): frame_skip 1, or an episode
        # that ended before the step's last frame (the screens before it are not this step's)
        single = skip == 1 or ends_early
        if spec.want_screens and single:
            self.frames[0] = self.frames[1]
        if spec.want_screen_ram and single:
            self.screen_ram[0] = self.screen_ram[1]
        v["single_frame"][i] = single
        v["frames_played"][i] = f + 1
        self.episode_return += total
        self.episode_length += 1
        v["reward"][i] = total
        v["terminated"][i] = terminated
        v["truncated"][i] = truncated
        v["event_fired"][i] = fired
        done = terminated or truncated
        v["episode_return"][i] = self.episode_return if done else 0.0
        v["episode_length"][i] = self.episode_length if done else 0
        if done and spec.autoreset:
            # the ended episode's last observation, then the next episode's first one
            if spec.want_screens:
                self.publish(final=True)
            v["final_single_frame"][i] = single
            ale.getRAM(v["final_ram"][i])
            if spec.want_screen_ram:
                v["final_screen_ram"][i] = self.screen_ram
            self.reset()
        else:
            if spec.want_screens:
                self.publish()
            v["ram_rendered"][i] = rendered
            ale.getRAM(self.ram)
            v["lives"][i] = ale.lives()


def make_emulators(spec: EmulatorSpec, views: dict) -> list[Emulator]:
    """The emulators of ``spec``, in batch order."""
    from stori_jax.games import get_game

    game = get_game(spec.game)
    return [Emulator(spec, game, seed, i, views) for i, seed in zip(spec.envs, spec.seeds,
                                                                  strict=True)]
