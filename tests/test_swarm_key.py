"""Swarm keys: where they come from, what is refused, and that the secret never shows."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import pytest

from cas_async import ConfigurationError, KeyFileWarning, SwarmKey

SECRET = bytes(range(32))
HEX = SECRET.hex()
ENV_VAR = SwarmKey.ENV_VAR

posix_only = pytest.mark.skipif(os.name != "posix", reason="file modes are POSIX")


def _key_file(tmp_path: Path, content: bytes, mode: int = 0o600) -> Path:
    path = tmp_path / "swarm.key"
    path.write_bytes(content)
    path.chmod(mode)
    return path


# -- the key itself ----------------------------------------------------------------------


def test_generate_makes_distinct_32_byte_keys() -> None:
    first, second = SwarmKey.generate(), SwarmKey.generate()
    assert len(first.secret) == len(second.secret) == 32
    assert first != second


@pytest.mark.parametrize(
    ("secret", "message"),
    [
        (b"x" * 15, r"at least 16 bytes, got 15; make one with SwarmKey\.generate\(\)"),
        (HEX, r"a swarm key is bytes, got str; use SwarmKey\.from_env\(\)"),
    ],
    ids=["too-short", "str"],
)
def test_a_bad_secret_is_refused(secret: object, message: str) -> None:
    with pytest.raises(ConfigurationError, match=message):
        SwarmKey(secret)  # type: ignore[arg-type]


def test_repr_and_str_never_show_the_secret() -> None:
    key = SwarmKey(SECRET)
    assert repr(key) == f"SwarmKey(<32 bytes, fingerprint {key.fingerprint}>)"
    for text in (repr(key), str(key), repr([key]), f"{key}"):
        assert HEX not in text
        assert repr(SECRET) not in text


def test_the_fingerprint_tells_keys_apart_and_equal_keys_match() -> None:
    key, same, other = SwarmKey(SECRET), SwarmKey(bytes(SECRET)), SwarmKey(b"\xff" * 32)
    assert key == same
    assert hash(key) == hash(same)
    assert key.fingerprint == same.fingerprint != other.fingerprint
    assert key != other
    assert len(key.fingerprint) == 8


def test_a_key_is_frozen() -> None:
    key = SwarmKey(SECRET)
    with pytest.raises(dataclasses.FrozenInstanceError):
        key.secret = b"y" * 32  # type: ignore[misc]


def test_hex_is_what_from_env_reads(monkeypatch: pytest.MonkeyPatch) -> None:
    key = SwarmKey.generate()
    monkeypatch.setenv(ENV_VAR, key.hex())
    assert SwarmKey.from_env() == key


# -- from the environment ----------------------------------------------------------------


@pytest.mark.parametrize(
    "value", [HEX, HEX.upper(), f"  {HEX}\n", HEX[:32]], ids=["hex", "upper", "spaces", "16-bytes"]
)
def test_from_env_reads_hex(monkeypatch: pytest.MonkeyPatch, value: str) -> None:
    monkeypatch.setenv(ENV_VAR, value)
    assert SwarmKey.from_env() == SwarmKey(bytes.fromhex(value.strip()))


@pytest.mark.parametrize("value", [None, "", "  \n"], ids=["unset", "empty", "blank"])
def test_from_env_is_none_without_a_value(monkeypatch: pytest.MonkeyPatch, value: str) -> None:
    if value is None:
        monkeypatch.delenv(ENV_VAR, raising=False)
    else:
        monkeypatch.setenv(ENV_VAR, value)
    assert SwarmKey.from_env() is None


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("correct-horse-battery-staple-0123456789", r"CAS_ASYNC_SWARM_KEY .* value is not hex"),
        (HEX + "a", r"CAS_ASYNC_SWARM_KEY .* value is not hex"),
        (HEX[:30], r"CAS_ASYNC_SWARM_KEY holds 30 hex digits; a swarm key needs at least 32"),
    ],
    ids=["not-hex", "odd-digits", "too-short"],
)
def test_from_env_refuses_a_bad_value_without_echoing_it(
    monkeypatch: pytest.MonkeyPatch, value: str, message: str
) -> None:
    monkeypatch.setenv(ENV_VAR, value)
    with pytest.raises(ConfigurationError, match=message) as caught:
        SwarmKey.from_env()
    assert value not in str(caught.value)
    assert value[:12] not in str(caught.value)


def test_from_env_reads_the_variable_named(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("LAB_KEY", HEX)
    monkeypatch.delenv(ENV_VAR, raising=False)
    assert SwarmKey.from_env("LAB_KEY") == SwarmKey(SECRET)
    monkeypatch.setenv("LAB_KEY", "nope")
    with pytest.raises(ConfigurationError, match="environment variable LAB_KEY"):
        SwarmKey.from_env("LAB_KEY")


# -- from a file -------------------------------------------------------------------------


@pytest.mark.parametrize(
    "content",
    [HEX.encode(), f"{HEX}\n".encode(), f"\n  {HEX.upper()}  \r\n".encode()],
    ids=["hex", "newline", "padded"],
)
def test_from_file_reads_hex(tmp_path: Path, content: bytes) -> None:
    assert SwarmKey.from_file(_key_file(tmp_path, content)) == SwarmKey(SECRET)


def test_from_file_takes_a_file_that_is_not_hex_as_raw_bytes(tmp_path: Path) -> None:
    raw = bytes(range(200, 232))  # not ASCII, so not hex
    assert SwarmKey.from_file(_key_file(tmp_path, raw)) == SwarmKey(raw)
    text = b"not hex but long enough\n"  # raw means byte for byte: the newline counts
    assert SwarmKey.from_file(_key_file(tmp_path, text)) == SwarmKey(text)


def test_from_file_accepts_a_str_path(tmp_path: Path) -> None:
    assert SwarmKey.from_file(str(_key_file(tmp_path, HEX.encode()))) == SwarmKey(SECRET)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (HEX[:30].encode(), r"holds 30 hex digits; a swarm key needs at least 32"),
        (b"\x00" * 15, r"holds 15 bytes; a swarm key needs at least 16 \(as raw bytes\)"),
        (b"", r"holds 0 bytes"),
    ],
    ids=["short-hex", "short-raw", "empty"],
)
def test_from_file_refuses_a_short_key_and_names_the_file(
    tmp_path: Path, content: bytes, message: str
) -> None:
    path = _key_file(tmp_path, content)
    with pytest.raises(ConfigurationError, match=message) as caught:
        SwarmKey.from_file(path)
    assert str(path) in str(caught.value)


@pytest.mark.parametrize("kind", ["missing", "directory"])
def test_from_file_names_a_file_it_cannot_read(tmp_path: Path, kind: str) -> None:
    path = tmp_path / "absent.key" if kind == "missing" else tmp_path
    with pytest.raises(ConfigurationError, match="cannot read the swarm key file") as caught:
        SwarmKey.from_file(path)
    assert str(path) in str(caught.value)


@posix_only
@pytest.mark.parametrize("mode", [0o640, 0o604, 0o620, 0o666], ids=oct)
def test_from_file_warns_when_others_may_read_the_key(tmp_path: Path, mode: int) -> None:
    path = _key_file(tmp_path, HEX.encode(), mode)
    with pytest.warns(KeyFileWarning, match=r"accessible to group or others .* chmod 600"):
        key = SwarmKey.from_file(path)
    assert key == SwarmKey(SECRET)  # still loaded: a warning, not a refusal


@posix_only
@pytest.mark.parametrize("mode", [0o600, 0o400], ids=oct)
def test_from_file_is_quiet_for_a_private_file(tmp_path: Path, mode: int) -> None:
    # pytest turns warnings into errors: reading without one is the assertion.
    assert SwarmKey.from_file(_key_file(tmp_path, HEX.encode(), mode)) == SwarmKey(SECRET)
