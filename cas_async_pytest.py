"""The pytest plugin of :mod:`cas_async.testing` (registered as the ``pytest11`` entry point).

Loaded by every pytest session of an environment where cas_async is installed, so
it does nothing until a test asks. It lives outside the ``cas_async`` package so
that loading it does not import cas_async (numpy, msgspec, ...): a session that
never uses it pays nothing. It registers the ``cas_virtual`` marker's name,
defines fixtures (which import cas_async when first used), and answers
pytest-asyncio's ``pytest_asyncio_loop_factories`` hook only once a test marked
``cas_virtual`` has been collected. Before that, and in sessions without such a
test, pytest-asyncio makes its loops exactly as it would without this plugin.
"""

from __future__ import annotations

import asyncio
import inspect
import sys
from collections.abc import AsyncIterator, Callable, Generator, Iterator, Mapping
from typing import TYPE_CHECKING, Any, Final

import pytest

if TYPE_CHECKING:
    from cas_async import FaultyTransport, MemoryTransport, UdpTransport
    from cas_async.testing import Robots

MARKER: Final = "cas_virtual"
DROPS_MARKER: Final = "cas_allow_drops"
_DEFAULT_FACTORY: Final = "asyncio"
_FIXTURE_LOOP_SCOPE: Final = "asyncio_default_fixture_loop_scope"


def pytest_addoption(parser: pytest.Parser, pluginmanager: pytest.PytestPluginManager) -> None:
    """Keeps the parser, to give pytest-asyncio's fixture loop scope a default at configure time."""
    pluginmanager.register(_FixtureLoopScope(parser), _FixtureLoopScope.__name__)


class _FixtureLoopScope:
    """Gives ``asyncio_default_fixture_loop_scope`` the default ``"function"`` (see the module).

    pytest-asyncio declares the option without a default, and warns when a project
    leaves it unset. Declaring it again, with a default, before any plugin has read
    it (this runs first among the ``pytest_configure`` hooks; the plugins have all
    declared their options by then) changes what an unset option reads as, and
    nothing else: a value from the project's configuration or from ``-o`` wins.
    """

    def __init__(self, parser: pytest.Parser) -> None:
        self._parser = parser

    @pytest.hookimpl(tryfirst=True)
    def pytest_configure(self, config: pytest.Config) -> None:
        if config.pluginmanager.hasplugin("asyncio"):  # pytest-asyncio, by its entry point
            self._parser.addini(
                _FIXTURE_LOOP_SCOPE,
                "default scope of the asyncio event loop used to execute async fixtures "
                "(default here, from the cas_async plugin: function)",
                type="string",
                default="function",
            )


def pytest_configure(config: pytest.Config) -> None:
    """Declares the markers (so ``--strict-markers`` sessions accept them)."""
    config.addinivalue_line(
        "markers",
        f"{MARKER}: run this async test on cas_async's virtual-time loop "
        "(asyncio.sleep and timeouts take no wall time; needs pytest-asyncio >= 1.4)",
    )
    config.addinivalue_line(
        "markers",
        f"{DROPS_MARKER}(*reasons): drop reasons the cas_robots fixture does not "
        "count as a failure in this test (e.g. 'unknown_robot', 'duplicate')",
    )


class _LoopFactories:
    """Answers pytest-asyncio's hook: the virtual-time loop for tests marked ``cas_virtual``."""

    @pytest.hookimpl(tryfirst=True)
    def pytest_asyncio_loop_factories(
        self, config: pytest.Config, item: pytest.Item
    ) -> Mapping[str, Callable[[], asyncio.AbstractEventLoop]] | None:
        if item.get_closest_marker(MARKER) is not None:
            from cas_async import VirtualTimeLoop

            return {MARKER: VirtualTimeLoop}
        # The implementations this test sees (a conftest applies to its own directory).
        if len(item.ihook.pytest_asyncio_loop_factories.get_hookimpls()) > 1:
            return None  # another plugin, or the project's conftest, decides
        # Nobody else answers, and pytest-asyncio requires an answer once anyone
        # implements the hook: the loop it would make without any (the policy's).
        return {_DEFAULT_FACTORY: asyncio.new_event_loop}


@pytest.hookimpl(tryfirst=True)
def pytest_collectreport(report: pytest.CollectReport) -> None:
    """A test module that could not import cas_async because a folder shadows it: says so."""
    if report.failed:
        _explain_shadow(report)


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_runtest_makereport(
    item: pytest.Item, call: pytest.CallInfo[None]
) -> Generator[None, pytest.TestReport, pytest.TestReport]:
    """A test that failed because a folder shadows cas_async (see :func:`_explain_shadow`)."""
    report = yield
    if report.failed:
        _explain_shadow(report)
    return report


def _explain_shadow(report: pytest.CollectReport | pytest.TestReport) -> None:
    """Adds what happened, and what to do, to a failure when ``cas_async`` is no package.

    Run from the folder that contains a clone of the repository, ``import cas_async``
    finds the clone's folder, which has no ``__init__.py``: an empty namespace package
    (see ``cas_async._cli._shadow``). Looked at only when something failed, and without
    importing cas_async.
    """
    import importlib.util

    module = sys.modules.get("cas_async")
    try:
        spec = module.__spec__ if module is not None else importlib.util.find_spec("cas_async")
    except (ImportError, ValueError):
        return
    if spec is None or spec.origin is not None or not spec.submodule_search_locations:
        return  # a package, or not there at all
    folder = next(iter(spec.submodule_search_locations))
    text = (
        f"cas_async is the folder {folder}, not the package: that folder has no "
        "__init__.py (a clone of the repository, seen from the folder that contains it), so "
        "Python imported it as an empty namespace package. Run pytest from inside the clone, "
        "or from any folder but the one that contains it, or install the package without -e."
    )
    longrepr = report.longrepr
    if isinstance(longrepr, pytest.ExceptionInfo) or longrepr is None:
        return
    if isinstance(longrepr, tuple):  # (path, line, message): a skip's
        return
    if hasattr(longrepr, "addsection"):  # a traceback's representation
        longrepr.addsection("cas_async is shadowed", text)
    else:  # a collection error's text
        report.longrepr = f"{longrepr}\n\n{text}"


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_pycollect_makeitem(
    collector: pytest.Module | pytest.Class, name: str, obj: object
) -> Iterator[Any]:
    """Before pytest-asyncio parametrizes a test marked ``cas_virtual``: be ready to give its loop.

    pytest-asyncio asks for loop factories while the function is being collected
    (in its own ``pytest_generate_tests``, which may run before this plugin's): the
    hook object is registered here, around the collection of the marked function.
    """
    try:
        marks = getattr(obj, "pytestmark", [])
    except Exception:  # an object with a strange __getattr__: none of ours
        marks = []
    if collector.get_closest_marker(MARKER) is not None or any(
        getattr(mark, "name", None) == MARKER for mark in marks
    ):
        _answer_loop_factories(collector.config)
    return (yield)


def _answer_loop_factories(config: pytest.Config) -> None:
    manager = config.pluginmanager
    if hasattr(manager.hook, "pytest_asyncio_loop_factories") and (
        manager.get_plugin(_LoopFactories.__name__) is None
    ):
        manager.register(_LoopFactories(), _LoopFactories.__name__)


@pytest.hookimpl(tryfirst=True)
def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    """A ``cas_virtual`` test must be ``async def``, with pytest-asyncio >= 1.4."""
    marker = metafunc.definition.get_closest_marker(MARKER)
    if marker is None:
        return
    if not inspect.iscoroutinefunction(metafunc.function):
        raise pytest.UsageError(
            f"{metafunc.definition.nodeid}: @pytest.mark.{MARKER} is for async def tests; "
            "a plain test can call cas_async.run(main(), virtual=True)"
        )
    manager = metafunc.config.pluginmanager
    if not hasattr(manager.hook, "pytest_asyncio_loop_factories"):
        raise pytest.UsageError(
            f"{metafunc.definition.nodeid}: @pytest.mark.{MARKER} needs pytest-asyncio >= 1.4 "
            "(its pytest_asyncio_loop_factories hook): not installed, or older"
        )
    _answer_loop_factories(metafunc.config)


# -- fixtures ---------------------------------------------------------------------------------


@pytest.fixture
def cas_memory() -> MemoryTransport:
    """A fresh in-memory transport (datagrams as bytes, as over a network)."""
    from cas_async import MemoryTransport

    return MemoryTransport()


@pytest.fixture
def cas_udp() -> UdpTransport:
    """A UDP transport on 127.0.0.1 whose robots bind ephemeral ports (real time only)."""
    from cas_async import UdpTransport

    return UdpTransport(host="127.0.0.1")


@pytest.fixture
def cas_lossy() -> Callable[..., FaultyTransport]:
    """Factory: ``cas_lossy(loss=0.1, duplicate=0.0, reorder=0.0, delay=(0, 0), seed=0)``.

    A seeded :class:`~cas_async.FaultyTransport` over a fresh memory transport: the
    same seed and the same sends give the same faults (deterministic on virtual time).
    """
    from cas_async import Faults, FaultyTransport, MemoryTransport

    def lossy(
        loss: float = 0.0,
        duplicate: float = 0.0,
        reorder: float = 0.0,
        delay: tuple[float, float] = (0.0, 0.0),
        seed: int = 0,
    ) -> FaultyTransport:
        faults = Faults(loss=loss, duplicate=duplicate, reorder=reorder, delay=delay)
        return FaultyTransport(MemoryTransport(), faults, seed=seed)

    return lossy


def _robots_fixture() -> Any:
    """``cas_robots``, an async fixture: defined only where pytest-asyncio is installed."""
    try:
        import pytest_asyncio
    except ImportError:  # pragma: no cover - the test extra installs it
        return None

    @pytest_asyncio.fixture(loop_scope="function")
    async def cas_robots(request: pytest.FixtureRequest) -> AsyncIterator[Robots]:
        """A :class:`~cas_async.testing.Robots` for the test, stopped and checked after it.

        ``robot = await cas_robots.start(1, [MyLayer()], transport=cas_memory)``;
        it lives in the test's loop (function scope: a test on a module-scoped loop
        starts its robots with a :class:`~cas_async.testing.Robots` of its own);
        ``await cas_robots.swarm(robots)``. When the test ends every robot is stopped;
        a layer that failed, or a drop for a reason not allowed (by
        ``@pytest.mark.cas_allow_drops("reason", ...)`` or
        ``cas_robots.allowed_drops``), fails the test (with the reasons and counts,
        per robot).
        """
        from cas_async.testing import Robots

        allowed = {
            reason for mark in request.node.iter_markers(DROPS_MARKER) for reason in mark.args
        }
        robots = Robots(allowed_drops=allowed)
        yield robots
        await robots.aclose()

    return cas_robots


cas_robots: Final = _robots_fixture()
