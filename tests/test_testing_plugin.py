"""cas_async.testing as a user meets it: a pytest session of their own, with no conftest.

Each test writes a small test file into a fresh directory and runs pytest on it in
a subprocess (``pytester.runpytest_subprocess``), as a user's project would run:
the plugin comes from the installed entry point, nothing from this project's
conftest. The sessions use pytest-asyncio's default (strict) mode and settings
unless a test says otherwise.
"""

from __future__ import annotations

import textwrap

import pytest

pytestmark = pytest.mark.slow  # a pytest session in a subprocess per test

pytest_plugins = ["pytester"]

_INI = """
[pytest]
asyncio_mode = auto
asyncio_default_fixture_loop_scope = function
"""


def run(pytester: pytest.Pytester, source: str, *args: str, ini: str = _INI) -> pytest.RunResult:
    pytester.makeini(ini)
    pytester.makepyfile(test_user=textwrap.dedent(source))
    return pytester.runpytest_subprocess("-p", "no:cacheprovider", "-W", "error", *args)


def test_a_session_that_does_not_use_the_plugin_is_left_as_it_was(
    pytester: pytest.Pytester,
) -> None:
    result = run(
        pytester,
        """
        import asyncio

        async def test_the_loop_is_pytest_asyncio_s():
            loop = asyncio.get_running_loop()
            assert type(loop) is asyncio.SelectorEventLoop  # the default policy's, on POSIX
            t = loop.time()
            await asyncio.sleep(0.05)
            assert loop.time() - t >= 0.05  # real time passes

        def test_nothing_of_cas_async_was_imported():
            import sys
            assert "cas_async" not in sys.modules
        """,
        "-v",
    )
    result.assert_outcomes(passed=2)
    # Test ids unchanged (no visible parametrization), and no warning of any kind.
    result.stdout.fnmatch_lines(["*test_the_loop_is_pytest_asyncio_s PASSED*"])
    result.stdout.no_fnmatch_line("*[[]asyncio[]]*")
    result.stdout.no_fnmatch_line("*warning*")


def test_the_marker_runs_an_hour_of_virtual_time_in_no_time(pytester: pytest.Pytester) -> None:
    result = run(
        pytester,
        """
        import asyncio
        import time

        import pytest

        from cas_async import VirtualTimeLoop

        @pytest.mark.cas_virtual
        async def test_an_hour():
            started = time.perf_counter()
            loop = asyncio.get_running_loop()
            assert isinstance(loop, VirtualTimeLoop)
            await asyncio.sleep(3600)
            assert loop.time() == 3600.0
            assert time.perf_counter() - started < 60.0  # the hour was never waited for

        async def test_unmarked_tests_keep_their_loop():
            assert not isinstance(asyncio.get_running_loop(), VirtualTimeLoop)
        """,
        "-v",
    )
    result.assert_outcomes(passed=2)
    result.stdout.no_fnmatch_line("*[[]cas_virtual[]]*")  # ids unchanged


def test_the_marker_on_a_plain_test_is_a_usage_error(pytester: pytest.Pytester) -> None:
    result = run(
        pytester,
        """
        import pytest

        @pytest.mark.cas_virtual
        def test_not_async():
            pass
        """,
    )
    assert result.ret != 0
    result.stdout.fnmatch_lines(["*cas_virtual is for async def tests*"])


def test_the_robots_fixture_fails_a_test_whose_layer_fails(pytester: pytest.Pytester) -> None:
    result = run(
        pytester,
        """
        import asyncio

        import pytest

        from cas_async import Layer, message, Message

        @message
        class Ping(Message):
            n: int

        class Breaks(Layer):
            async def handle_msg(self, msg):
                raise ValueError("broken on purpose")

        class Sends(Layer):
            pass

        @pytest.mark.cas_virtual
        async def test_a_layer_breaks(cas_robots, cas_memory):
            await cas_robots.start(2, [Breaks()], transport=cas_memory, messages=[Ping])
            sender = Sends()
            await cas_robots.start(1, [sender], transport=cas_memory, messages=[Ping])
            sender.send(2, Ping(1))
            await asyncio.sleep(1.0)
        """,
    )
    result.assert_outcomes(passed=1, errors=1)  # the test body passed; its teardown did not
    result.stdout.fnmatch_lines(["*LayerError*", "*broken on purpose*"])


def test_the_robots_fixture_reports_unexpected_drops_by_robot_and_reason(
    pytester: pytest.Pytester,
) -> None:
    result = run(
        pytester,
        """
        import asyncio

        import pytest

        from cas_async import Layer, message, Message

        @message
        class Ping(Message):
            n: int

        class Quiet(Layer):
            pass

        @pytest.mark.cas_virtual
        async def test_drops(cas_robots, cas_memory):
            sender = Quiet()
            await cas_robots.start(1, [sender], transport=cas_memory, messages=[Ping])
            sender.send(7, Ping(1))  # nobody is robot 7: counted unknown_robot
            await asyncio.sleep(0.1)

        @pytest.mark.cas_virtual
        async def test_allowed(cas_robots, cas_memory):
            cas_robots.allowed_drops.add("unknown_robot")
            sender = Quiet()
            await cas_robots.start(1, [sender], transport=cas_memory, messages=[Ping])
            sender.send(7, Ping(1))
        """,
    )
    result.assert_outcomes(passed=2, errors=1)
    result.stdout.fnmatch_lines(["*UnexpectedDrops*", "*robot 1: {'unknown_robot': 1}*"])


def test_the_marker_works_on_a_module_and_a_class(pytester: pytest.Pytester) -> None:
    result = run(
        pytester,
        """
        import asyncio

        import pytest

        from cas_async import VirtualTimeLoop

        pytestmark = pytest.mark.cas_virtual

        async def test_module_level():
            assert isinstance(asyncio.get_running_loop(), VirtualTimeLoop)

        class TestGroup:
            async def test_in_a_class(self):
                await asyncio.sleep(86400)
                assert asyncio.get_running_loop().time() == 86400.0
        """,
    )
    result.assert_outcomes(passed=2)


def test_a_project_that_leaves_the_fixture_loop_scope_unset_gets_no_warning(
    pytester: pytest.Pytester,
) -> None:
    # pytest-asyncio warns (an error under -W error) when a project leaves
    # asyncio_default_fixture_loop_scope unset: the plugin gives it the default "function".
    result = run(
        pytester,
        """
        import asyncio

        import pytest
        import pytest_asyncio

        from cas_async import VirtualTimeLoop

        @pytest_asyncio.fixture
        async def the_loop():
            return asyncio.get_running_loop()

        @pytest.mark.cas_virtual
        async def test_a_fixture_shares_the_virtual_loop(the_loop):
            assert the_loop is asyncio.get_running_loop()
            assert isinstance(the_loop, VirtualTimeLoop)
        """,
        ini="[pytest]\nasyncio_mode = auto\n",
    )
    result.assert_outcomes(passed=1)
    result.stdout.fnmatch_lines(["*asyncio_default_fixture_loop_scope=function*"])
    result.stdout.no_fnmatch_line("*PytestDeprecationWarning*")


def test_a_project_s_own_fixture_loop_scope_wins(pytester: pytest.Pytester) -> None:
    result = run(
        pytester,
        """
        async def test_nothing():
            pass
        """,
        ini="[pytest]\nasyncio_mode = auto\nasyncio_default_fixture_loop_scope = module\n",
    )
    result.assert_outcomes(passed=1)
    result.stdout.fnmatch_lines(["*asyncio_default_fixture_loop_scope=module*"])


def test_forgetting_the_marker_is_answered_by_naming_it(pytester: pytest.Pytester) -> None:
    result = run(
        pytester,
        """
        from cas_async import Layer, MemoryTransport, Robot, VirtualClock

        async def test_virtual_clock_without_the_marker():
            robot = Robot(1, [Layer()], transport=MemoryTransport(), clock=VirtualClock())
            async with robot:
                pass
        """,
    )
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(
        ["*VirtualClock needs the virtual-time event loop: mark the test @pytest.mark.cas_virtual*"]
    )
