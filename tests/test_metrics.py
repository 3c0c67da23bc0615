"""Information-theoretic helpers: closed form vs general formula vs empirical estimates."""

import numpy as np
import pytest

import stori_jax
from stori_jax.functional import corrupt_actions, env_keys
from stori_jax.metrics import (MAX_ACTIONS, action_channel_capacity, channel_matrix,
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
    # an empty batch gave NaN with a numpy warning; text and ragged lists numpy's own words
    with pytest.raises(ValueError, match=r"T, B, D >= 1, got shape \(2, 0, 3\)"):
        next_state_variance(np.zeros((2, 0, 3)))
    with pytest.raises(ValueError, match="states must be an array of numbers"):
        next_state_variance([[["a"]]])
    with pytest.raises(ValueError, match="states must be an array of numbers"):
        next_state_variance([[[1.0], [1.0, 2.0]]])
    with pytest.raises(ValueError, match="states must be finite numbers"):
        next_state_variance(np.full((1, 2, 3), np.nan))


def test_empirical_action_ids_are_validated():
    # -1 used to wrap around to the last action and give a wrong number
    with pytest.raises(ValueError, match=r"intended must be action ids in \[0, 3\], got \[-1\]"):
        empirical_action_information([0, 1, 2, -1], [0, 1, 2, 3], 4)
    with pytest.raises(ValueError, match=r"executed must be action ids in \[0, 3\], got \[4\]"):
        empirical_action_information([0, 1, 2, 3], [0, 1, 2, 4], 4)
    with pytest.raises(ValueError, match="intended must be integer action ids"):
        empirical_action_information([0.0, 1.0], [0, 1], 4)
    with pytest.raises(ValueError, match="same size and shape"):  # would pair the wrong elements
        empirical_action_information(np.zeros((2, 3), int), np.zeros((3, 2), int), 4)
    with pytest.raises(ValueError, match="non-empty"):
        empirical_action_information([], [], 4)
    with pytest.raises(ValueError, match="num_actions must be an int"):
        empirical_action_information([0], [0], 4.0)
    assert empirical_action_information(np.array([0, 1, 2, 3]), np.array([0, 1, 2, 3]),
                                        np.int64(4)) == pytest.approx(2.0)


def test_mutual_information_inputs_are_validated():
    with pytest.raises(ValueError, match=r"channel must be \(1, m\).*got shape \(2, 2\)"):
        mutual_information([1.0], np.eye(2))
    with pytest.raises(ValueError, match="input_dist must be a non-empty 1-D"):
        mutual_information(np.full((2, 2), 0.25), np.eye(2))
    with pytest.raises(ValueError, match="input_dist must be finite and non-negative"):
        mutual_information([1.5, -0.5], np.eye(2))
    with pytest.raises(ValueError, match="input_dist must be finite"):
        mutual_information([np.nan, 1.0], np.eye(2))
    with pytest.raises(ValueError, match=r"input_dist must sum to 1"):
        mutual_information([0.5, 0.4], np.eye(2))
    with pytest.raises(ValueError, match=r"channel rows must sum to 1"):
        mutual_information([0.5, 0.5], [[1.0, 0.0], [0.5, 0.4]])
    with pytest.raises(ValueError, match="channel rows must be finite and non-negative"):
        mutual_information([0.5, 0.5], [[1.5, -0.5], [0.0, 1.0]])
    with pytest.raises(ValueError, match="input_dist must be an array of numbers"):
        mutual_information(["a", "b"], np.eye(2))
    # a tiny rounding error is fine, and a channel may have a different output alphabet
    assert mutual_information([0.5, 0.5 + 1e-9], np.eye(2)) == pytest.approx(1.0)
    assert mutual_information([0.5, 0.5], [[1.0, 0.0, 0.0], [0.0, 0.5, 0.5]]) == pytest.approx(1.0)


def test_a_distribution_off_by_more_than_rounding_is_refused():
    """Sums are allowed 1e-6 of rounding, not 1e-4."""
    with pytest.raises(ValueError, match=r"input_dist must sum to 1 \(within 1e-06\)"):
        mutual_information([0.5, 0.5 + 1e-4], np.eye(2))
    with pytest.raises(ValueError, match=r"channel rows must sum to 1"):
        mutual_information([0.5, 0.5], [[1.0, 0.0], [0.0, 1.0 - 1e-4]])
    assert mutual_information([0.5, 0.5 + 1e-7], np.eye(2)) == pytest.approx(1.0, abs=1e-6)


def test_channel_matrix_replacement_is_validated_and_repeats_count():
    # functional.corrupt_actions draws uniformly from the replacement tuple by position, so a
    # repeated id weighs more; the rows used to sum to 1 - p/2 for [1, 1]
    m = channel_matrix(4, 0.3, [1, 1])
    np.testing.assert_allclose(m.sum(1), 1.0)
    np.testing.assert_allclose(m[0], [0.7, 0.3, 0.0, 0.0])
    np.testing.assert_allclose(channel_matrix(4, 0.3, [1, 1, 2])[3], [0, 0.2, 0.1, 0.7])
    np.testing.assert_allclose(channel_matrix(4, 0.3, np.arange(4)), channel_matrix(4, 0.3))
    with pytest.raises(ValueError,
                       match=r"replacement must be action ids in \[0, 3\], got \[-1, 5\]"):
        channel_matrix(4, 0.3, [-1, 0, 5])
    with pytest.raises(ValueError, match="replacement must be non-empty"):
        channel_matrix(4, 0.3, [])
    with pytest.raises(ValueError, match="replacement must be int action ids"):
        channel_matrix(4, 0.3, [1.0, 2.0])
    with pytest.raises(ValueError, match="replacement must be int action ids"):
        channel_matrix(4, 0.3, [True])
    with pytest.raises(ValueError, match="replacement must be a sequence of action ids"):
        channel_matrix(4, 0.3, "01")


@pytest.mark.parametrize("n, p, error, message", [
    (4, "0.3", ValueError, r"prob must be a number in \[0, 1\]"),
    (4, True, ValueError, r"prob must be a number in \[0, 1\]"),
    (4, float("nan"), ValueError, r"prob must be in \[0, 1\]"),
    (4, -0.1, ValueError, r"prob must be in \[0, 1\]"),
    (2.5, 0.3, ValueError, "num_actions must be an int"),
    ("4", 0.3, ValueError, "num_actions must be an int"),
    (0, 0.3, ValueError, r"num_actions must be in \[1, 1024\]"),
    (10 ** 6, 0.3, ValueError, r"num_actions must be in \[1, 1024\]"),
])
def test_capacity_and_channel_arguments_are_validated(n, p, error, message):
    for fn in (action_channel_capacity, channel_matrix):
        with pytest.raises(error, match=message):
            fn(n, p)


def test_capacity_accepts_numpy_scalars_and_the_bound():
    assert action_channel_capacity(np.int64(4), np.float32(0.0)) == pytest.approx(2.0)
    assert action_channel_capacity(MAX_ACTIONS, 0.0) == pytest.approx(np.log2(MAX_ACTIONS))
    assert action_channel_capacity(1, 0.5) == 0.0


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


def test_the_metrics_module_is_an_attribute_of_the_package():
    """``stori_jax.metrics``, as the README writes it, after a plain ``import stori_jax`` (in a
    fresh interpreter: this module's own import of it would hide a missing attribute)."""
    import subprocess
    import sys

    code = "import stori_jax; print(stori_jax.metrics.action_channel_capacity(4, 0.0))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert float(out.stdout) == pytest.approx(2.0)


def test_exact_values_of_the_action_information_and_the_state_variance():
    """Exact values where the estimators' terms differ: a constant intended (or executed)
    action carries no information, whatever the other side does (the symmetric uniform inputs
    above could not tell H(A) from H(Ã)); next_state_variance is the variance over the batch
    summed over D, not a standard deviation."""
    assert empirical_action_information([0, 0, 0, 0], [0, 1, 2, 3], 4) == pytest.approx(0.0)
    assert empirical_action_information([0, 1, 2, 3], [0, 0, 0, 0], 4) == pytest.approx(0.0)
    assert empirical_action_information([0, 1, 2, 3], [0, 1, 2, 3], 4) == pytest.approx(2.0)
    states = np.array([[[0.0, 1.0], [4.0, 1.0]], [[1.0, 0.0], [3.0, 6.0]]])  # (T=2, B=2, D=2)
    np.testing.assert_allclose(next_state_variance(states), [4.0, 1.0 + 9.0])
