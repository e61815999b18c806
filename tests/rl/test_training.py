"""The training example runs, and learning moves the policy (its score is not judged here)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pettingzoo")

from examples.rl.gathering.train import LinearSoftmax, train


def test_a_few_hundred_steps_of_reinforce_move_the_policy() -> None:
    untrained = LinearSoftmax(seed=0).theta
    training = train(6, seed=0, overrides=["run.max_time=25"])  # at most 6 x 50 steps
    assert 100 <= training.steps <= 300
    assert len(training.returns) == 6
    theta = training.policy.theta
    assert np.all(np.isfinite(theta))
    assert not np.array_equal(theta, untrained)
    # Every action's row moved: the gradient reached the whole policy, not one corner.
    assert np.all(np.abs(theta - untrained).sum(axis=1) > 0)


def test_the_same_seed_trains_the_same_policy() -> None:
    first = train(2, seed=3, overrides=["run.max_time=10"])
    second = train(2, seed=3, overrides=["run.max_time=10"])
    assert np.array_equal(first.policy.theta, second.policy.theta)
    assert first.returns == second.returns
