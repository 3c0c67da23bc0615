"""A step handed back in chunks (the JAX work of one chunk runs while the emulators run the next):
the chunking, like the split over processes, changes nothing but the speed; a step interrupted
between chunks resumes as if it had never stopped."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import stori_jax
from stori_jax.backends.subproc import assign_envs

from _env_support import make, random_actions, run_env, to_numpy


def test_every_env_is_emulated_once_and_one_chunk_is_the_plain_split():
    for num_envs, workers, inline, chunks in [(8, 1, 3, 2), (7, 2, 2, 3), (5, 3, 0, 5),
                                              (6, 1, 5, 2), (9, 0, 9, 2)]:
        here, theirs = assign_envs(num_envs, workers, inline, chunks)
        everyone = [i for chunk in here for i in chunk] + [
            i for worker in theirs for chunk in worker for i in chunk]
        assert sorted(everyone) == list(range(num_envs))
        assert sum(map(len, here)) == inline
    here, theirs = assign_envs(10, 2, 4, 1)  # one chunk: the envs here first, then contiguous
    assert here == [(0, 1, 2, 3)] and theirs == [[(4, 5, 6)], [(7, 8, 9)]]


CASES = {
    # type 1 and a torch mask drawn per frame, autoreset with final_obs, 84x84 stacks
    "breakout-3.2C-atari84": dict(game="Breakout", preset="3.2C", obs="atari84"),
    # events in the RAM and RAM-obs renders, raw screens, no autoreset
    "boxing-mixed-raw": dict(game="Boxing", obs="raw", autoreset=False, config=stori_jax.Config(
        action_noise=stori_jax.ActionNoise(0.3), event=stori_jax.RandomEvent(1, 0.3),
        observation=stori_jax.ObservationMask("ram", 2, 0.5))),
}


def _run(case, **split):
    case = dict(CASES[case])
    game, preset, config = case.pop("game"), case.pop("preset", None), case.pop("config", None)
    kw = dict(num_envs=5, seed=3, max_episode_frames=60, **case, **split)
    env = stori_jax.make(game, preset, config=config, **kw)
    try:
        return run_env(env, random_actions(env.num_actions, 30, 5, seed=1))
    finally:
        env.close()


@pytest.mark.parametrize("case", CASES)
def test_a_run_is_bit_identical_whatever_the_chunks(case):
    reference = _run(case, num_workers=1, inline_envs=0, chunks=1)
    for split in (dict(num_workers=1, inline_envs=2, chunks=2),
                  dict(num_workers=2, inline_envs=1, chunks=3),
                  dict(num_workers=0, chunks=5)):
        other = _run(case, **split)
        for a, b in zip(jax.tree.leaves((reference.reset_obs, reference.reset_info,
                                         reference.obs, reference.reward, reference.info)),
                        jax.tree.leaves((other.reset_obs, other.reset_info, other.obs,
                                         other.reward, other.info))):
            np.testing.assert_array_equal(a, b, err_msg=f"{case} {split}")
    assert reference.done.any()  # episodes ended (and restarted) within the run


@pytest.mark.parametrize("where", ["second chunk's wait", "first chunk's JAX work"])
def test_a_step_interrupted_between_chunks_stays_in_flight_and_finishes_as_its_twin(where):
    kw = dict(num_envs=4, num_workers=1, inline_envs=1, chunks=2, obs="atari84")
    env, twin = make("Breakout", **kw), make("Breakout", **kw)
    try:
        env.reset(), twin.reset()
        actions = np.array([1, 2, 3, 1], np.int32)
        for a in (actions, actions[::-1]):
            env.step(a), twin.step(a)
        fired = []
        real_wait, real_finish = env.backend._wait_all, env._finish_part

        def finish(*args):
            if where == "first chunk's JAX work" and not fired:
                fired.append(True)
                raise KeyboardInterrupt
            return real_finish(*args)

        def wait(*args, **kwargs):  # the wait for the second chunk, once the first is done
            if where == "second chunk's wait" and not fired and env._in_flight[3]:
                fired.append(True)
                raise KeyboardInterrupt
            return real_wait(*args, **kwargs)

        env._finish_part, env.backend._wait_all = finish, wait
        env.send(actions)
        with pytest.raises(KeyboardInterrupt):
            env.recv()
        assert fired
        assert env.phase is stori_jax.Phase.IN_FLIGHT
        got, expected = to_numpy(env.recv()), to_numpy(twin.step(actions))
        for x, y in zip(jax.tree.leaves(got), jax.tree.leaves(expected)):
            np.testing.assert_array_equal(x, y)
        for a in (actions, actions[::-1]):  # and it goes on as the twin
            np.testing.assert_array_equal(np.asarray(env.step(a)[0]), np.asarray(twin.step(a)[0]))
    finally:
        env.close()
        twin.close()
