"""The naive way to run STORI today: one gymnasium Atari env per process (gymnasium's
AsyncVectorEnv), the perturbations written as per-env numpy wrappers.

Small and honest: frameskip=1 envs wrapped so that each agent step repeats the action for
``frame_skip`` frames, applies the perturbation per emulator frame (as the reference does), and
max-pools the last two screens.  A 2.2 preset's concept-2 parts act only on the agent steps its
schedule puts in concept 2 (counted from each episode's start), as in stori-jax, so both run the
same workload.  Randomness comes from a seeded numpy Generator per env.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

import ale_py

gym.register_envs(ale_py)


class StoriNumpyWrapper(gym.Wrapper):
    """Per-frame type-1 corruption, 2.1 events, 3.2 crop/blackout masks and RAM-obs rendering,
    implemented the straightforward way over one env."""

    def __init__(self, env, *, game, config, frame_skip: int, seed: int):
        super().__init__(env)
        self.ale = env.unwrapped.ale
        self.game = game
        self.frame_skip = frame_skip
        self.rng = np.random.default_rng(seed)
        parts = {type(p).__name__: (p, drifted) for _, p, drifted in config.components()}
        self.drift = config.drift
        self.drifted = {name: drifted for name, (_, drifted) in parts.items()}
        self.noise = parts.get("ActionNoise", (None,))[0]
        self.event = parts.get("RandomEvent", (None,))[0]
        self.mask = parts.get("ObservationMask", (None,))[0]
        self.rule = game.event_modes[self.event.mode] if self.event else None
        self.replacement = (np.array(game.replacement_actions(self.noise))
                            if self.noise else None)
        self.hidden = self.fill = None
        if self.mask is not None and self.mask.kind in ("crop", "blackout"):
            from stori_jax.functional.masks import CROP_REGIONS, TORCH_MODE, region_mask

            if self.mask.kind == "blackout":
                self.hidden, self.fill = region_mask(game.blackout_modes[self.mask.mode].regions)
            elif self.mask.mode != TORCH_MODE:
                self.hidden, self.fill = region_mask(CROP_REGIONS[self.mask.mode])
        ys, xs = np.mgrid[0:210, 0:160]
        self._ys, self._xs = ys, xs

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self.start_ram = self.ale.getRAM().copy()
        self.prev_ram = self.start_ram.copy()
        self.rule_state = self.rule.new_state() if self.rule else None
        self.carry = 0.0  # a cancelled hit's reward, taken off the next frame's (Boxing mode 2)
        self.episode_step = 0
        self.active = self._active_parts()
        return self._mask(obs), info

    def _active_parts(self) -> set:
        """The part types acting on this agent step: all of them, except that a 2.2 preset's
        concept-2 parts act only where its schedule (docs/spec.md section 3) says concept 2."""
        concept2 = False
        if self.drift is not None:
            k, period = self.episode_step, self.drift.period
            if self.drift.schedule == "sudden":
                concept2 = k >= period
            elif self.drift.schedule == "cyclic":
                concept2 = (k // period) % 2 == 1
            else:  # gradual
                concept2 = self.rng.random() < min(max((k - period) / period, 0.0), 1.0)
        return {name for name, drifted in self.drifted.items() if concept2 or not drifted}

    def _mask(self, frame):
        if (self.mask is None or "ObservationMask" not in self.active or self.mask.kind == "ram"
                or self.rng.random() >= self.mask.prob):
            return frame
        frame = frame.copy()
        if self.hidden is not None:
            frame[self.hidden] = self.fill[self.hidden]
        else:  # torch
            cx, cy = self.rng.integers(0, 160), self.rng.integers(0, 210)
            frame[(self._xs - cx) ** 2 + (self._ys - cy) ** 2 > 75 ** 2] = 0
        return frame

    def _render_ram_obs(self, frame):
        if (self.mask is None or "ObservationMask" not in self.active or self.mask.kind != "ram"
                or self.rng.random() >= self.mask.prob):
            return frame
        writes = self.game.ram_obs_modes[self.mask.mode].writes(self.ale.getRAM())
        if writes is None:
            return frame
        state = self.ale.cloneState()
        for address, value in writes.items():
            self.ale.setRAM(address, value)
        self.ale.act(0)
        frame = self.ale.getScreenRGB()
        self.ale.restoreState(state)
        return frame

    def step(self, action):
        total, screens = 0.0, []
        terminated = truncated = False
        info = {}
        self.active = self._active_parts()
        noise = self.noise if "ActionNoise" in self.active else None
        rule = self.rule if "RandomEvent" in self.active else None
        for f in range(self.frame_skip):
            a = action
            if noise is not None and self.rng.random() < noise.prob:
                a = int(self.rng.choice(self.replacement))
            if rule is not None and rule.pre_frame is not None:
                writes, _ = self.rule.pre_frame(self.start_ram, self.rule_state, self.rng.random(),
                                                self.event.prob, True)
                for address, value in writes.items():
                    self.ale.setRAM(address, value)
            obs, reward, terminated, truncated, info = self.env.step(a)
            reward, self.carry = reward + self.carry, 0.0
            if rule is not None and rule.post_frame is not None:
                ram = self.ale.getRAM()
                out = self.rule.post_frame(self.prev_ram, ram, self.start_ram, self.rule_state,
                                           self.rng.random(), self.rng.random(),
                                           self.event.prob, self.ale.getEpisodeFrameNumber())
                for address, value in out.writes.items():
                    self.ale.setRAM(address, value)
                if out.zero_reward:
                    if out.cancel_next_reward:  # the game answers a cancelled hit next frame
                        self.carry = reward
                    reward = 0.0
            if self.rule is not None and self.rule.post_frame is not None:  # in concept 1 too
                self.prev_ram = self.ale.getRAM().copy()
            total += reward
            if f >= self.frame_skip - 2:
                screens.append(self._mask(self._render_ram_obs(obs)))
            if terminated or truncated:
                break
        frame = np.maximum(screens[0], screens[-1]) if screens else obs
        self.episode_step += 1
        return frame, total, terminated, truncated, info


def check_supported(config) -> None:
    """Refuse a config this baseline cannot play as stori-jax does (the paper's presets are all
    playable): it perturbs per frame, draws uniform replacements and plays screens (a config
    has one part of each type, concept 2's included: Config refuses two)."""
    refused = []
    if config.granularity != "frame":
        refused.append(f"granularity {config.granularity!r} (it perturbs per frame)")
    if config.ram_observation:
        refused.append("ram_observation (it plays screens)")
    if any(getattr(part, "sticky", False) for _, part, _ in config.components()):
        refused.append("sticky action noise (it draws uniform replacements)")
    if refused:
        raise ValueError("the naive baseline cannot play this config: " + "; ".join(refused))


def make_naive_vector_env(game_name: str, config, num_envs: int, seed: int, frame_skip: int = 4):
    """gymnasium.vector.AsyncVectorEnv of wrapped frameskip=1 ALE envs, one process each."""
    from stori_jax.games import get_game

    check_supported(config)
    game = get_game(game_name)

    def thunk(i):
        def make():
            env = gym.make(f"ALE/{''.join(p.capitalize() for p in game.rom_id.split('_'))}-v5",
                           frameskip=1, repeat_action_probability=0.0, obs_type="rgb")
            return StoriNumpyWrapper(env, game=game, config=config, frame_skip=frame_skip,
                                     seed=seed * 100003 + i)
        return make

    return gym.vector.AsyncVectorEnv([thunk(i) for i in range(num_envs)], shared_memory=True,
                                     context="spawn")
