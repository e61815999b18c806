"""Stack fingerprints: what changes them, what does not, and one codec per stack and thread."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
from pathlib import Path
from typing import Annotated

import msgspec
import pytest

from cas_async import Message
from cas_async._wire._fingerprint import describe_fingerprint
from cas_async.transport import Codec


class FpInt(Message):
    v: int


class FpStr(Message):
    v: str


class FpList(Message):
    v: list[int]


class FpFloats(Message):
    v: list[float]


class FpBounded(Message):
    v: Annotated[int, msgspec.Meta(ge=0)]


class FpBoundedMore(Message):
    v: Annotated[int, msgspec.Meta(ge=1)]


EVERY = (FpInt, FpStr, FpList, FpFloats, FpBounded, FpBoundedMore)


def fingerprint(layers: int, *classes: type[Message]) -> int:
    return Codec.for_stack(layers, classes).fingerprint


def test_the_fingerprint_changes_with_the_layer_count_and_says_it() -> None:
    prints = {fingerprint(layers, FpInt) for layers in range(1, 10)}
    assert len(prints) == 9
    assert fingerprint(5, FpInt) >> 24 == 5
    assert describe_fingerprint(fingerprint(5, FpInt)).startswith("5 layers, message set 0x")


@pytest.mark.parametrize(
    ("one", "other"),
    [
        pytest.param([FpInt], [FpInt, FpStr], id="one-more-message"),
        pytest.param([FpInt], [FpStr], id="another-message"),
        pytest.param([], [FpInt], id="none-at-all"),
        pytest.param([FpList], [FpFloats], id="another-field-type"),
        pytest.param([FpInt], [FpBounded], id="a-bound"),
        pytest.param([FpBounded], [FpBoundedMore], id="another-bound"),
        pytest.param(list(EVERY), list(EVERY[:-1]), id="one-less"),
    ],
)
def test_the_fingerprint_changes_with_the_message_set(
    one: list[type[Message]], other: list[type[Message]]
) -> None:
    assert fingerprint(2, *one) != fingerprint(2, *other)


def test_the_fingerprint_does_not_depend_on_the_order_of_classes() -> None:
    assert fingerprint(3, *EVERY[::-1]) == fingerprint(3, *EVERY)
    assert fingerprint(2, FpInt, FpStr, FpList) == fingerprint(2, FpList, FpInt, FpStr)


def test_the_fingerprint_is_the_same_in_another_process() -> None:
    code = (
        "import json\n"
        "from apps.box_moving import messages as box\n"  # imported first here, not there
        "from apps.fire_brigade.messages import MESSAGES\n"
        "from cas_async.transport import Codec\n"
        "print(json.dumps([Codec.for_stack(5, MESSAGES).fingerprint,"
        " Codec.for_stack(4, box.MESSAGES).fingerprint]))"
    )
    root = Path(__file__).resolve().parents[1]
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    from apps.box_moving import messages as box
    from apps.fire_brigade.messages import MESSAGES

    ours = [fingerprint(5, *MESSAGES), fingerprint(4, *box.MESSAGES)]
    assert json.loads(done.stdout) == ours


SCRIPT = """
import json
from cas_async import Message, message
from cas_async.transport import Codec

@message(name="fp-test.Ping")
class Ping(Message):
    n: int

class Pong(Message):
    n: int

if __name__ == "__main__":
    print(json.dumps([Codec.for_stack(2, [Ping]).fingerprint,
                      Codec.for_stack(2, [Pong]).fingerprint]))
"""


def test_a_script_run_by_its_path_agrees_with_its_importers_on_named_classes(
    tmp_path: Path,
) -> None:
    (tmp_path / "fp_script.py").write_text(SCRIPT)

    def run(*argv: str) -> list[int]:
        done = subprocess.run(
            [sys.executable, *argv], cwd=tmp_path, capture_output=True, text=True, timeout=120
        )
        assert done.returncode == 0, done.stderr
        found: list[int] = json.loads(done.stdout)
        return found

    script = run("fp_script.py")  # its classes are __main__.Ping and __main__.Pong
    imported = run(
        "-c",
        "import json, fp_script as m\nfrom cas_async.transport import Codec\n"
        "print(json.dumps([Codec.for_stack(2, [c]).fingerprint for c in (m.Ping, m.Pong)]))",
    )
    assert script[0] == imported[0]  # named: the same tag wherever it is defined
    assert script[1] != imported[1]  # __main__.Pong against fp_script.Pong


# --- one codec per stack and thread ------------------------------------------------------------


def test_robots_of_one_stack_in_one_thread_share_one_codec() -> None:
    class SharedA(Message):
        x: int

    stack = (SharedA,)
    first = Codec.shared(2, stack, 1400)
    assert Codec.shared(2, stack, 1400) is first
    assert Codec.shared(3, stack, 1400) is not first  # another layer count
    assert Codec.shared(2, stack, 9000) is not first  # another datagram limit
    assert first.fingerprint == Codec.for_stack(2, stack, 1400).fingerprint
    everything = Codec.shared(2, None)
    assert Codec.shared(2, None) is everything

    class SharedB(Message):
        y: int

    assert SharedB in Codec.shared(2, None).message_classes  # a new class: a new stack
    assert SharedB not in everything.message_classes
    elsewhere: list[Codec] = []
    thread = threading.Thread(target=lambda: elsewhere.append(Codec.shared(2, stack, 1400)))
    thread.start()
    thread.join(60)
    assert elsewhere
    assert elsewhere[0] is not first
    assert elsewhere[0].fingerprint == first.fingerprint
