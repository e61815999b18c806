"""The random policy's baseline on the gathering: ``python -m examples.rl.gathering.baseline``.

Each robot picks one of the nine actions at random every step. Prints, per seed,
the mean return per robot, how the episode ended and its makespan, then the means:
what the training (``python -m examples.rl.gathering.train``) must beat.
"""

from __future__ import annotations

import argparse
import statistics
import sys

from examples.rl.gathering.env import ACTIONS, make_env
from examples.rl.rollout import Rollout, random_policy, rollout

__all__ = ["EVAL_SEEDS", "main", "random_baseline", "summary"]

EVAL_SEEDS = range(1000, 1010)
"""The seeds the baseline and the trained policy are compared on (training uses others)."""


def random_baseline(seeds: range = EVAL_SEEDS, policy_seed: int = 0) -> list[Rollout]:
    """One episode of the random policy per seed."""
    policy = random_policy(ACTIONS, policy_seed)
    with make_env() as env:
        return [rollout(env, policy, seed) for seed in seeds]


def summary(name: str, rollouts: list[Rollout]) -> str:
    """One line: mean return, episodes completed, mean makespan of those."""
    done = [r.makespan for r in rollouts if r.makespan is not None]
    makespan = f"{statistics.mean(done):.1f} s" if done else "-"
    return (
        f"{name:<10} mean return {statistics.mean(r.mean_return for r in rollouts):7.2f}   "
        f"completed {len(done)}/{len(rollouts)}   mean makespan {makespan}"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m examples.rl.gathering.baseline", description=__doc__
    )
    parser.add_argument("--episodes", type=int, default=len(EVAL_SEEDS), help="seeds 1000, ...")
    args = parser.parse_args(argv)
    rollouts = random_baseline(range(EVAL_SEEDS.start, EVAL_SEEDS.start + args.episodes))
    for r in rollouts:
        makespan = "-" if r.makespan is None else f"{r.makespan:.1f} s"
        print(f"seed {r.seed}: return {r.mean_return:7.2f}  {r.status:<10} makespan {makespan}")
    print(summary("random", rollouts))
    return 0


if __name__ == "__main__":
    sys.exit(main())
