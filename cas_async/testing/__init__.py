"""Testing your layers and swarms: helpers, and a pytest plugin that needs no conftest.

Installing cas_async registers the plugin (module ``cas_async_pytest``, entry point
``pytest11``). It gives a test, on request only:

* the marker ``@pytest.mark.cas_virtual``: the ``async def`` test runs on the
  virtual-time loop, so ``await asyncio.sleep(3600)`` and an hour of a swarm's work
  take milliseconds, the same way every time (pytest-asyncio 1.4 or later; in its
  strict mode, mark the test ``@pytest.mark.asyncio`` too);
* the fixture ``cas_robots``: a :class:`Robots` that starts robots and swarms for the
  test and, when the test ends, stops them and fails the test if a layer failed or a
  robot dropped a message for a reason the test did not allow;
* the fixtures ``cas_memory`` (:class:`~cas_async.MemoryTransport`), ``cas_udp``
  (:class:`~cas_async.UdpTransport` on 127.0.0.1, ephemeral ports) and ``cas_lossy``
  (a factory of seeded :class:`~cas_async.FaultyTransport` over memory).

A session that uses none of them is left as it was: the plugin changes no loop,
policy or warning filter, and imports cas_async only when a test asks for it.

The helpers work in any asyncio test, with or without the plugin:
:func:`wait_all_tasks_blocked`, :func:`run_until`, :class:`Recorder`,
:func:`assert_roundtrip`, :func:`strategy_for` (Hypothesis strategies of messages),
:class:`LayerHarness` (one layer between scripted neighbours and peers),
:func:`run_scenario_file` (a whole scenario) and :func:`peer_process` (a peer in
another process).
"""

from ._harness import LayerHarness, Script
from ._peers import peer_process
from ._recorder import Recorder
from ._robots import Robots, UnexpectedDrops
from ._roundtrip import assert_roundtrip
from ._scenario_files import ScenarioOutcome, run_scenario_file
from ._strategies import strategy_for
from ._waiting import RunUntilTimeout, run_until, wait_all_tasks_blocked

__all__ = [
    "LayerHarness",
    "Recorder",
    "Robots",
    "RunUntilTimeout",
    "ScenarioOutcome",
    "Script",
    "UnexpectedDrops",
    "assert_roundtrip",
    "peer_process",
    "run_scenario_file",
    "run_until",
    "strategy_for",
    "wait_all_tasks_blocked",
]
