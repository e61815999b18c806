"""REINFORCE on the gathering, in numpy: ``python -m examples.rl.gathering.train``.

Every robot runs the same policy (parameters shared, as usual with identical
agents): a linear softmax over the nine actions, on the observation and a bias.
After each episode the policy moves along the policy gradient (REINFORCE,
Williams 1992): every action's log-probability, weighted by the return that
followed it (discounted by ``GAMMA``, normalised over the episode), one Adam
step. Training episodes have seeds 0, 1, 2, ...; the evaluation uses seeds
1000-1009 (the random baseline's, see :mod:`.baseline`), with the policy as it is.

Writes ``learning_curve.png`` and ``training.json`` to ``--out`` (default
``runs/rl-gathering``), and prints the trained policy against the random one.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt

from examples.rl.gathering.baseline import EVAL_SEEDS, random_baseline, summary
from examples.rl.gathering.env import ACTIONS, OBSERVATIONS, GatheringEnv, make_env
from examples.rl.rollout import Rollout, rollout

__all__ = ["LinearSoftmax", "Training", "main", "train"]

GAMMA: Final = 0.95
LEARNING_RATE: Final = 0.05
FEATURES: Final = OBSERVATIONS.shape[0] + 1  # the observation and a bias
Floats = npt.NDArray[np.float64]


class LinearSoftmax:
    """``pi(a | o) = softmax(theta @ [o, 1])[a]``, with Adam for the updates.

    Args:
        seed: seeds the sampling of actions.
    """

    def __init__(self, seed: int) -> None:
        self.theta: Floats = np.zeros((int(ACTIONS.n), FEATURES))
        self.rng = np.random.default_rng(seed)
        self.greedy = False
        self._moments = (np.zeros_like(self.theta), np.zeros_like(self.theta))
        self._updates = 0

    @staticmethod
    def features(observations: Sequence[npt.NDArray[np.float32]]) -> Floats:
        """One row per observation: the observation, then 1."""
        rows = np.asarray(observations, dtype=np.float64).reshape(len(observations), -1)
        return np.hstack([rows, np.ones((len(observations), 1))])

    def probabilities(self, phi: Floats) -> Floats:
        """One row of action probabilities per row of ``phi``."""
        logits: Floats = phi @ self.theta.T
        weights = np.exp(logits - logits.max(axis=1, keepdims=True))
        probabilities: Floats = weights / weights.sum(axis=1, keepdims=True)
        return probabilities

    def actions(self, phi: Floats) -> npt.NDArray[np.int64]:
        """Sampled (or, when ``greedy``, the likeliest) actions for the rows of ``phi``."""
        p = self.probabilities(phi)
        chosen: npt.NDArray[np.int64]
        if self.greedy:
            chosen = p.argmax(axis=1).astype(np.int64)
        else:  # inverse transform sampling, one uniform draw per row
            draws = self.rng.random((len(p), 1))
            below = (draws > p.cumsum(axis=1)).sum(axis=1)
            chosen = below.clip(max=p.shape[1] - 1).astype(np.int64)
        return chosen

    def __call__(self, observations: Mapping[str, npt.NDArray[np.float32]]) -> dict[str, np.int64]:
        agents = list(observations)
        chosen = self.actions(self.features([observations[a] for a in agents]))
        return {agent: np.int64(a) for agent, a in zip(agents, chosen, strict=True)}

    def step(self, gradient: Floats, rate: float = LEARNING_RATE) -> None:
        """One Adam step up ``gradient``."""
        beta1, beta2 = 0.9, 0.999
        first, second = self._moments
        first = beta1 * first + (1 - beta1) * gradient
        second = beta2 * second + (1 - beta2) * gradient**2
        self._moments = (first, second)
        self._updates += 1
        unbiased = first / (1 - beta1**self._updates)
        scale = np.sqrt(second / (1 - beta2**self._updates)) + 1e-8
        self.theta = self.theta + rate * unbiased / scale


def learn_from_episode(env: GatheringEnv, policy: LinearSoftmax, seed: int) -> tuple[float, int]:
    """One episode with ``policy``, then one REINFORCE update; the mean return and the steps."""
    observations, _ = env.reset(seed=seed)
    agents = list(env.agents)
    phis: list[Floats] = []
    chosen: list[npt.NDArray[np.int64]] = []
    rewards: list[Floats] = []
    while env.agents:
        phi = policy.features([observations[a] for a in agents])
        actions = policy.actions(phi)
        observations, reward, _, _, _ = env.step(
            {agent: np.int64(a) for agent, a in zip(agents, actions, strict=True)}
        )
        phis.append(phi)
        chosen.append(actions)
        rewards.append(np.array([reward[a] for a in agents]))
    r = np.array(rewards)  # (steps, agents)
    returns = np.zeros_like(r)
    running = np.zeros(len(agents))
    for t in range(len(r) - 1, -1, -1):
        running = r[t] + GAMMA * running
        returns[t] = running
    advantage = (returns - returns.mean()) / (returns.std() + 1e-8)
    phi_all = np.concatenate(phis)  # (steps * agents, features)
    a_all = np.concatenate(chosen)
    onehot = np.eye(policy.theta.shape[0])[a_all]
    gradient = ((onehot - policy.probabilities(phi_all)) * advantage.reshape(-1, 1)).T @ phi_all
    policy.step(gradient / len(a_all))
    return float(r.sum(axis=0).mean()), len(r)


@dataclass
class Training:
    """What a training run produced.

    Attributes:
        policy: the trained policy.
        returns: the mean return per robot of each training episode.
        steps: env steps taken in training.
        evaluations: ``(episodes trained, mean return on the evaluation seeds)``.
    """

    policy: LinearSoftmax
    returns: list[float] = field(default_factory=list)
    steps: int = 0
    evaluations: list[tuple[int, float]] = field(default_factory=list)


def evaluate(env: GatheringEnv, policy: LinearSoftmax, seeds: Sequence[int]) -> list[Rollout]:
    return [rollout(env, policy, seed) for seed in seeds]


def train(
    episodes: int,
    *,
    seed: int = 0,
    eval_every: int = 0,
    eval_seeds: Sequence[int] = EVAL_SEEDS,
    overrides: Sequence[str] = (),
    log: bool = False,
) -> Training:
    """Trains a fresh policy for ``episodes`` episodes (seeds 0, 1, ...).

    Args:
        episodes: training episodes.
        seed: seeds the policy's sampling.
        eval_every: evaluate every that many episodes (0: never).
        eval_seeds: the evaluation's seeds.
        overrides: ``--set`` strings for the scenario (a shorter ``run.max_time``...).
        log: print progress to stderr.
    """
    training = Training(LinearSoftmax(seed))
    with make_env(overrides=overrides) as env:
        for episode in range(episodes):
            if eval_every and episode % eval_every == 0:
                _evaluate_into(training, env, eval_seeds, episode, log)
            mean_return, steps = learn_from_episode(env, training.policy, episode)
            training.returns.append(mean_return)
            training.steps += steps
            if log:
                print(f"episode {episode}: return {mean_return:.2f}", file=sys.stderr)
        if eval_every:
            _evaluate_into(training, env, eval_seeds, episodes, log)
    return training


def _evaluate_into(
    training: Training, env: GatheringEnv, seeds: Sequence[int], episode: int, log: bool
) -> None:
    score = statistics.mean(r.mean_return for r in evaluate(env, training.policy, seeds))
    training.evaluations.append((episode, score))
    if log:
        print(f"after {episode} episodes: evaluation return {score:.2f}", file=sys.stderr)


def plot(training: Training, random_return: float, seeds: int, path: Path) -> Path:
    """The learning curve: training returns, evaluations, and the random policy's level."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(8, 5), dpi=100)
    FigureCanvasAgg(figure)
    axes = figure.add_subplot()
    episodes = np.arange(1, len(training.returns) + 1)
    axes.plot(episodes, training.returns, color="C0", alpha=0.3, label="training episode")
    window = min(20, len(training.returns))
    if window:
        smooth = np.convolve(training.returns, np.ones(window) / window, mode="valid")
        axes.plot(episodes[window - 1 :], smooth, color="C0", label=f"mean of {window}")
    if training.evaluations:
        xs, ys = zip(*training.evaluations, strict=True)
        axes.plot(xs, ys, "o-", color="C1", label=f"evaluation ({seeds} seeds)")
    axes.axhline(random_return, color="C3", linestyle="--", label=f"random policy ({seeds} seeds)")
    axes.set_xlabel("training episodes")
    axes.set_ylabel("return per robot")
    axes.set_title("REINFORCE on the gathering (5 robots, learned Plan layer)")
    axes.grid(True, alpha=0.4)
    axes.legend(loc="lower right")
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m examples.rl.gathering.train", description=__doc__
    )
    parser.add_argument("--episodes", type=int, default=300, help="training episodes")
    parser.add_argument("--eval-every", type=int, default=25, help="episodes between evaluations")
    parser.add_argument("--seed", type=int, default=0, help="seeds the policy's sampling")
    parser.add_argument(
        "--eval-episodes", type=int, default=len(EVAL_SEEDS), help="seeds 1000, ... to evaluate on"
    )
    parser.add_argument("--out", type=Path, default=Path("runs/rl-gathering"))
    args = parser.parse_args(argv)
    seeds = range(EVAL_SEEDS.start, EVAL_SEEDS.start + args.eval_episodes)
    started = time.perf_counter()
    random = random_baseline(seeds)
    random_return = statistics.mean(r.mean_return for r in random)
    training = train(
        args.episodes, seed=args.seed, eval_every=args.eval_every, eval_seeds=seeds, log=True
    )
    with make_env() as env:
        trained = evaluate(env, training.policy, seeds)
        training.policy.greedy = True
        greedy = evaluate(env, training.policy, seeds)
    wall = time.perf_counter() - started
    figure = plot(training, random_return, len(seeds), args.out / "learning_curve.png")
    record = {
        "episodes": args.episodes,
        "env_steps": training.steps,
        "wall_seconds": round(wall, 1),
        "random_return": random_return,
        "trained_return": statistics.mean(r.mean_return for r in trained),
        "greedy_return": statistics.mean(r.mean_return for r in greedy),
        "random_completed": sum(r.makespan is not None for r in random),
        "trained_completed": sum(r.makespan is not None for r in trained),
        "greedy_completed": sum(r.makespan is not None for r in greedy),
        "evaluations": training.evaluations,
        "theta": training.policy.theta.round(4).tolist(),
    }
    (args.out / "training.json").write_text(json.dumps(record, indent=2) + "\n")
    print(summary("random", random))
    print(summary("trained", trained))
    print(summary("greedy", greedy))
    print(f"{args.episodes} episodes, {training.steps} steps, {wall:.0f} s; wrote {figure}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
