"""The package's comments and strings say what the code does, not which issue changed it: no issue numbers
(``issue 89``, ``#89``) and no ``before issue`` / ``since issue`` in any ``.py`` under ``torchrl_csirl/``."""
from __future__ import annotations

import io
import pathlib
import re
import tokenize

import pytest

PACKAGE = pathlib.Path(__file__).resolve().parents[1] / "torchrl_csirl"

#: in a comment or a string: an issue named by number, or the history of an issue
HISTORY = re.compile(r"\bissues?\s*#?\s*\d+|\b(?:before|since|after|until)\s+(?:the\s+)?issue\b", re.IGNORECASE)
#: in a comment only: an issue's or pull request's number (``#89``); a string's ``#`` is often a URL fragment
NUMBER_REFERENCE = re.compile(r"(?<![\w&])#\d{2,}\b")


def history_mentions(source: str) -> list[tuple[int, str]]:
    """``(line, text)`` of each comment or string of ``source`` that mentions an issue number or an issue's history.

    Examples:
        >>> history_mentions('x = 1  # the default, since issue 12\\n')
        [(1, '# the default, since issue 12')]
        >>> history_mentions("y = 'see #58'  # see #58\\n")
        [(1, '# see #58')]
        >>> history_mentions('url = "docs/benchmark.md#published-results"  # 2 issues: none here\\n')
        []
    """
    found = []
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT:
            patterns = (HISTORY, NUMBER_REFERENCE)
        elif token.type == tokenize.STRING or token.type == getattr(tokenize, "FSTRING_MIDDLE", -1):
            patterns = (HISTORY,)
        else:
            continue
        if any(p.search(token.string) for p in patterns):
            found.append((token.start[0], token.string))
    return found


def test_the_checker_finds_what_it_is_for():
    source = (
        "A = 1  # True before issue 89\n"
        "B = 2  # see issue #87\n"
        "C = 3  # (#110)\n"
        'def f():\n    """Kept since issue 12."""\n'
        "D = 4  # the issue's cap, 300 000 frames\n"
    )
    assert [line for line, _ in history_mentions(source)] == [1, 2, 3, 5]


@pytest.mark.parametrize("path", sorted(PACKAGE.rglob("*.py")), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_issue_history_in_the_package(path):
    mentions = history_mentions(path.read_text(encoding="utf-8"))
    assert not mentions, f"{path.relative_to(PACKAGE.parent)} mentions issues: " + "; ".join(
        f"line {line}: {text.strip()[:100]}" for line, text in mentions
    )
