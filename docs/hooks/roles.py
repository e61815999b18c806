"""A MkDocs hook: docstrings' Sphinx roles read as plain code in the API reference.

The docstrings name other objects the Sphinx way, ``:class:`Mission``` or
``:meth:`~Robot.start```, which Markdown renders as the role's text before the code
(``:class:Mission``). This drops the role and, as Sphinx does for ``~``, keeps only
the last part of a dotted name.
"""

from __future__ import annotations

import re
from typing import Any, Final

__all__ = ["on_page_content"]

ROLE: Final = re.compile(
    r":(?:py:)?(?:attr|class|const|data|exc|func|meth|mod|obj|ref):<code>(~?)([^<]*)</code>"
)


def _plain(match: re.Match[str]) -> str:
    short, name = match.groups()
    return f"<code>{name.rsplit('.', 1)[-1] if short else name}</code>"


def on_page_content(html: str, **_: Any) -> str:
    """The page's HTML without the roles' text."""
    return ROLE.sub(_plain, html)
