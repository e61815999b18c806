"""Random partners against the built-in choice: ``python -m examples.rl.fire_brigade.baseline``.

Over a few seeds, two policies drive the learned Strategy layer: the random one
(each robot picks one of the five actions at random every step) and the one that
always picks the first ranked robot, which is the time strategy itself. Prints,
per seed, each one's mean return per robot and makespan, then the means: a
trained policy has to beat the first, and can hope to beat the second.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from collections.abc import Mapping
from typing import Any

import numpy as np

from examples.rl.fire_brigade.env import ACTIONS, make_env
from examples.rl.rollout import Rollout, random_policy, rollout

__all__ = ["first_ranked", "main"]


def first_ranked(observations: Mapping[str, Any]) -> dict[str, np.int64]:
    """Action 0 for every robot: ask the soonest estimated delivery first (the time strategy)."""
    return dict.fromkeys(observations, np.int64(0))


def _makespan(r: Rollout) -> str:
    return "-" if r.makespan is None else f"{r.makespan:.2f} s"


def _line(name: str, rollouts: list[Rollout]) -> str:
    done = [r.makespan for r in rollouts if r.makespan is not None]
    makespan = f"{statistics.mean(done):.2f} s" if done else "-"
    return (
        f"{name:<13} mean return {statistics.mean(r.mean_return for r in rollouts):7.2f}   "
        f"completed {len(done)}/{len(rollouts)}   mean makespan {makespan}"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m examples.rl.fire_brigade.baseline", description=__doc__
    )
    parser.add_argument("--episodes", type=int, default=5, help="seeds 1, 2, ...")
    args = parser.parse_args(argv)
    seeds = range(1, args.episodes + 1)
    with make_env() as env:
        random = [rollout(env, random_policy(ACTIONS, seed), seed) for seed in seeds]
        builtin = [rollout(env, first_ranked, seed) for seed in seeds]
    for r, b in zip(random, builtin, strict=True):
        print(
            f"seed {r.seed}: random return {r.mean_return:6.2f} makespan {_makespan(r)}"
            f"   time strategy return {b.mean_return:6.2f} makespan {_makespan(b)}"
        )
    print(_line("random", random))
    print(_line("time strategy", builtin))
    return 0


if __name__ == "__main__":
    sys.exit(main())
