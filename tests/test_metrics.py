"""Information-theoretic helpers: closed form vs general formula vs empirical estimates."""

import numpy as np
import pytest

import stori_jax
from stori_jax.functional import corrupt_actions, env_keys
from stori_jax.metrics import (action_channel_capacity, channel_matrix,
                               empirical_action_information, mutual_information,
                               next_state_variance)


@pytest.mark.parametrize("n, p", [(4, 0.0), (4, 0.3), (18, 0.3), (8, 1.0), (2, 0.5)])
def test_closed_form_matches_the_general_formula(n, p):
    uniform = np.full(n, 1 / n)
    assert action_channel_capacity(n, p) == pytest.approx(
        mutual_information(uniform, channel_matrix(n, p)), abs=1e-12)


def test_capacity_limits_and_monotonicity():
    assert action_channel_capacity(4, 0.0) == pytest.approx(2.0)  # noiseless: log2 n
    assert action_channel_capacity(4, 1.0) == pytest.approx(0.0)  # executed independent of A
    caps = [action_channel_capacity(18, p) for p in np.linspace(0, 1, 11)]
    assert all(a > b for a, b in zip(caps, caps[1:]))
    # no other input distribution beats the uniform one on this symmetric channel
    rng = np.random.default_rng(0)
    for _ in range(50):
        px = rng.dirichlet(np.ones(4))
        assert mutual_information(px, channel_matrix(4, 0.3)) <= action_channel_capacity(4, 0.3) + 1e-12


def test_empirical_estimate_from_the_corruption_function_agrees():
    import jax

    n, p, b = 4, 0.3, 4096
    rng = np.random.default_rng(1)
    intended = rng.integers(0, n, b)
    executed, _ = corrupt_actions(env_keys(jax.random.PRNGKey(3), b), intended,
                                  np.zeros(b, np.int32), prob=p, num_slots=4,
                                  replacement=tuple(range(n)))
    pairs = np.repeat(intended[:, None], 4, 1)
    estimate = empirical_action_information(pairs, np.asarray(executed), n)
    assert estimate == pytest.approx(action_channel_capacity(n, p), abs=0.01)


def test_bankheist_replacement_channel_never_fires():
    m = channel_matrix(18, 0.3, replacement=range(10))
    np.testing.assert_allclose(m.sum(1), 1.0)
    assert m[17, 10:17].sum() == 0  # never replaced by a FIRE action
    assert 0 < mutual_information(np.full(18, 1 / 18), m) < np.log2(18)


def test_bad_inputs():
    with pytest.raises(ValueError, match=r"prob must be in \[0, 1\]"):
        action_channel_capacity(4, 1.5)
    with pytest.raises(ValueError, match="same size"):
        empirical_action_information([0, 1], [0], 4)
    with pytest.raises(ValueError, match=r"states must be \(T, B, D\)"):
        next_state_variance(np.zeros((3, 4)))


def test_next_state_variance_is_zero_without_noise_and_grows_with_events():
    """The paper's probe on BankHeist: repeat action 3 from the same start in every env."""
    def spread(config):
        with stori_jax.make("BankHeist", config=config, num_envs=4, seed=0, obs="ram",
                            num_workers=1) as env:
            env.reset()
            states = []
            for _ in range(40):
                obs, *_ = env.step(np.full(4, 3, np.int32))
                states.append(np.asarray(obs))
        return next_state_variance(np.stack(states))

    assert (spread(stori_jax.Config()) == 0).all()
    noisy = spread(stori_jax.Config(event=stori_jax.RandomEvent(mode=3, prob=0.05)))
    assert noisy[-1] > 0
