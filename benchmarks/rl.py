"""Learning environments: steps per second, and where a step's time goes (the ``rl`` extra).

Not a framework-against-baseline comparison, and not part of ``python -m benchmarks``::

    python -m benchmarks.rl [--env gathering,fire_brigade] [--robots 25,100,1000]
                            [--steps 20] [--runs 3] [--no-profile]

Two environments of ``examples/rl``, each at every ``--robots`` count:

* ``gathering``: the learned Plan layer, ``robots.count`` robots; every robot drives
  one leg per step (an internal request and a motion each), random headings.
* ``fire_brigade``: the learned Strategy layer on the scale scenarios' world
  (``apps/fire_brigade/scenarios/scale_25.toml``, one 10 x 10 cell with 2 Generators
  and 2 Sinks per 25 Transporters, cells side by side): ``--robots`` Transporters and
  their stations; partner searches, requests and hand-overs between robots; the
  buckets are too many to be delivered within the steps measured.

Each run resets the env (timed: building the swarm), takes one step (timed: the
robots start, and the gathering's robots all tell each other where they are), then
``--steps`` steps with random actions: steps per second is those steps over their
wall time, the median of ``--runs`` runs (seeds 0, 1, ...).

Then one more run under ``cProfile`` splits the steps' time by where the code
lives: the runtime (``cas_async``, with ``cas_async.rl`` shown apart as ``env``,
and asyncio's event loop), the app (``apps/`` and ``examples/``: its layers, the
learned one included), the environment's callbacks (``observe``, ``reward`` and
``act``, in ``examples/rl/*/env.py``) and this driver. Time in builtins and
third-party code (numpy, gymnasium) counts for whoever called it. The profiler
slows every call down alike, so the split is a share, not a time.

One table and exactly one JSON line per case on stdout; progress goes to stderr.
"""

from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Final

import numpy as np

from ._table import print_aligned

ROOT: Final = Path(__file__).resolve().parent.parent
SCALE: Final = ROOT / "apps" / "fire_brigade" / "scenarios" / "scale_25.toml"
ENVS: Final = ("gathering", "fire_brigade")
COUNTS: Final = (25, 100, 1000)
CATEGORIES: Final = ("runtime", "env", "app", "callbacks", "driver", "other")
CALLBACKS: Final = tuple(str(ROOT / "examples" / "rl" / name / "env.py") for name in ENVS)
"""Where the environments' observe, reward and act live."""


def make(env: str, robots: int) -> Any:
    """The env named ``env`` with ``robots`` robots (Transporters, for the Fire Brigade)."""
    if env == "gathering":
        from examples.rl.gathering.env import make_env as gathering

        return gathering(overrides=[f"robots.count={robots}", "run.max_time=1000"])
    from examples.rl.fire_brigade.env import make_env as fire_brigade

    cells = max(1, round(robots / 25))
    return fire_brigade(
        SCALE,
        overrides=[
            f"stations.repeat={cells}",
            f"transporters.count={robots}",
            f"world.width={10.0 * cells}",
            f"transporters.spawn_max=[{10.0 * cells - 1}, 7.0]",
            f"mission.buckets={1000 * cells}",  # more than the steps can deliver
            "run.max_time=1000",
        ],
    )


def run_once(env: Any, seed: int, steps: int) -> tuple[float, float, float]:
    """``(reset seconds, first step seconds, steps per second)`` of one episode's start."""
    rng = np.random.default_rng(seed)
    n = env.action_space(env.possible_agents[0]).n
    started = time.perf_counter()
    env.reset(seed=seed)
    built = time.perf_counter()
    env.step(_actions(env, rng, n))
    first = time.perf_counter()
    plans = [_actions(env, rng, n) for _ in range(steps)]  # drawn before the clock starts
    stepping = time.perf_counter()
    for actions in plans:
        env.step(actions)
    done = time.perf_counter()
    if len(env.agents) != len(env.possible_agents):
        raise RuntimeError(f"the episode ended within {steps + 1} steps: measure fewer")
    return built - started, first - built, steps / (done - stepping)


def _actions(env: Any, rng: np.random.Generator, n: int) -> dict[str, np.int64]:
    return {
        agent: np.int64(a)
        for agent, a in zip(env.agents, rng.integers(n, size=len(env.agents)), strict=True)
    }


def profile_split(env: Any, steps: int) -> dict[str, float]:
    """Shares of the steps' time by :data:`CATEGORIES`, under ``cProfile``."""
    rng = np.random.default_rng(99)
    n = env.action_space(env.possible_agents[0]).n
    env.reset(seed=99)
    env.step(_actions(env, rng, n))
    plans = [_actions(env, rng, n) for _ in range(steps)]
    profiler = cProfile.Profile()
    profiler.enable()
    for actions in plans:
        env.step(actions)
    profiler.disable()
    seconds = split(pstats.Stats(profiler))
    total = sum(seconds.values()) or 1.0
    return {category: seconds[category] / total for category in CATEGORIES}


def split(stats: pstats.Stats) -> dict[str, float]:
    """Own time by category; code of no category counts for its callers, by their share."""
    table: dict[Any, Any] = stats.stats  # type: ignore[attr-defined]
    memo: dict[Any, dict[str, float]] = {}

    def owners(func: Any, seen: frozenset[Any]) -> dict[str, float]:
        if func in memo:
            return memo[func]
        own = category(func[0])
        if own is not None:
            found = {own: 1.0}
        else:
            callers = table.get(func, (0, 0, 0.0, 0.0, {}))[4]
            weights = {c: entry[2] for c, entry in callers.items() if c not in seen}
            total = sum(weights.values())
            if not total:
                found = {"other": 1.0}
            else:
                found = {}
                for caller, weight in weights.items():
                    for name, share in owners(caller, seen | {func}).items():
                        found[name] = found.get(name, 0.0) + share * weight / total
        memo[func] = found
        return found

    seconds = dict.fromkeys(CATEGORIES, 0.0)
    for func, (_, _, own_time, _, _) in table.items():
        for name, share in owners(func, frozenset()).items():
            seconds[name] += own_time * share
    return seconds


def category(filename: str) -> str | None:
    """Where a function's file belongs (``None``: to whoever called it)."""
    path = filename.replace("\\", "/")
    if "/cas_async/rl/" in path:
        return "env"
    if "/cas_async/" in path or "/asyncio/" in path or path.endswith("/selectors.py"):
        return "runtime"
    if path in CALLBACKS:
        return "callbacks"
    if str(ROOT / "apps") in path or str(ROOT / "examples") in path:
        return "app"
    if str(ROOT / "benchmarks") in path:
        return "driver"
    return None


def case(env_name: str, robots: int, steps: int, runs: int, profile: bool) -> dict[str, Any]:
    env = make(env_name, robots)
    try:
        results = []
        for run in range(runs):
            results.append(run_once(env, run, steps))
            print(
                f"  {env_name} {robots}: run {run + 1}: {results[-1][2]:.1f} steps/s",
                file=sys.stderr,
            )
        shares = profile_split(env, steps) if profile else None
        agents = len(env.possible_agents)
    finally:
        env.close()
    row: dict[str, Any] = {
        "name": "rl_steps",
        "env": env_name,
        "robots": agents,
        "steps": steps,
        "runs": runs,
        "dt": env.dt,
        "reset_s": round(statistics.median(r[0] for r in results), 4),
        "first_step_s": round(statistics.median(r[1] for r in results), 4),
        "steps_per_s": round(statistics.median(r[2] for r in results), 2),
        "steps_per_s_runs": [round(r[2], 2) for r in results],
    }
    if shares is not None:
        row["share"] = {name: round(value, 3) for name, value in shares.items()}
    return row


def print_table(rows: Sequence[dict[str, Any]]) -> None:
    header = "env robots reset_s 1st_step_s steps/s runtime (env) app callbacks driver"
    lines = [tuple(name.replace("_", " ") for name in header.split())]
    for row in rows:
        share = row.get("share")

        def pct(name: str, share: dict[str, float] | None = share) -> str:
            return "-" if share is None else f"{share[name]:.0%}"

        runtime = None if share is None else share["runtime"] + share["env"]
        lines.append((
            row["env"], str(row["robots"]), f"{row['reset_s']:.3f}", f"{row['first_step_s']:.3f}",
            f"{row['steps_per_s']:.1f}", "-" if runtime is None else f"{runtime:.0%}",
            pct("env"), pct("app"), pct("callbacks"), pct("driver"),
        ))  # fmt: skip
    print_aligned(lines, left=(0,))


def _names(text: str, known: Sequence[str]) -> list[str]:
    names = [name.strip() for name in text.split(",") if name.strip()]
    unknown = [name for name in names if name not in known]
    if unknown:
        raise argparse.ArgumentTypeError(f"unknown {unknown}; expected some of {list(known)}")
    return names


def _counts(text: str) -> list[int]:
    try:
        counts = [int(part) for part in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected counts such as 25,100, got {text!r}") from None
    if any(count < 1 for count in counts):
        raise argparse.ArgumentTypeError(f"counts must be at least 1, got {text!r}")
    return counts


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.rl", description=__doc__)
    envs: Callable[[str], list[str]] = lambda text: _names(text, ENVS)  # noqa: E731
    parser.add_argument("--env", type=envs, default=list(ENVS), help="gathering,fire_brigade")
    parser.add_argument("--robots", type=_counts, default=list(COUNTS), help="e.g. 25,100,1000")
    parser.add_argument("--steps", type=int, default=20, help="steps timed per run")
    parser.add_argument("--runs", type=int, default=3, help="runs per case (median reported)")
    parser.add_argument("--no-profile", action="store_true", help="skip the profiled run")
    args = parser.parse_args(argv)
    if args.steps < 1 or args.runs < 1:
        parser.error("--steps and --runs must be at least 1")
    rows = [
        case(env, robots, args.steps, args.runs, not args.no_profile)
        for env in args.env
        for robots in args.robots
    ]
    print_table(rows)
    for row in rows:
        print(json.dumps(row))
    return 0


if __name__ == "__main__":
    sys.exit(main())
