"""The shape of the pages a reader meets first: README.md fits one screen, and the benchmark and study pages keep
their lines and table cells short enough to read (no training, no site build: the files are read as text)."""
from __future__ import annotations

import glob
import os
import re

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

README_MAX_LINES = 100
#: a prose line as rendered, table rows included; lines inside fenced code blocks are exempt, and HTML comments (the
#: verdict markers tests/test_page_verdicts.py reads) do not count, as the reader does not see them
PROSE_LINE_MAX_CHARS = 400
TABLE_CELL_MAX_WORDS = 40
COMMENT = re.compile(r"<!--.*?-->")

PAGES = ["docs/benchmark.md", *sorted(os.path.relpath(p, ROOT) for p in glob.glob(os.path.join(ROOT, "docs", "studies", "*.md")))]


def prose_lines(path: str) -> list[tuple[int, str]]:
    """``(line number, line)`` of every line of ``path`` outside fenced code blocks (```), the fences excluded, with
    its HTML comments removed."""
    out, in_code = [], False
    with open(os.path.join(ROOT, path), encoding="utf-8") as f:
        for number, line in enumerate(f.read().split("\n"), start=1):
            if line.lstrip().startswith("```"):
                in_code = not in_code
            elif not in_code:
                out.append((number, COMMENT.sub("", line)))
    return out


def test_pages_are_found() -> None:
    assert "docs/studies/outside-driving.md" in PAGES and len(PAGES) > 2


def test_readme_fits_one_screen() -> None:
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as f:
        lines = f.read().rstrip("\n").split("\n")
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines, at most {README_MAX_LINES}"


@pytest.mark.parametrize("path", PAGES)
def test_no_prose_line_is_too_long(path: str) -> None:
    long = [f"{path}:{n} ({len(line)} characters)" for n, line in prose_lines(path) if len(line) > PROSE_LINE_MAX_CHARS]
    assert not long, f"lines over {PROSE_LINE_MAX_CHARS} characters (split them; a table cell's detail goes under the table): {long}"


@pytest.mark.parametrize("path", PAGES)
def test_no_table_cell_is_too_long(path: str) -> None:
    long = []
    for n, line in prose_lines(path):
        if line.lstrip().startswith("|"):
            for cell in line.strip().strip("|").split(" | "):
                if len(cell.split()) > TABLE_CELL_MAX_WORDS:
                    long.append(f"{path}:{n} ({len(cell.split())} words: {cell[:60]}...)")
    assert not long, f"table cells over {TABLE_CELL_MAX_WORDS} words (move the detail under the table): {long}"


def test_prose_lines_skip_code_blocks(tmp_path) -> None:
    """A long command in a fenced block is not prose; the same line outside one is."""
    page = tmp_path / "page.md"
    long = "x" * (PROSE_LINE_MAX_CHARS + 1)
    page.write_text(f"text\n\n```bash\n{long}\n```\n\n{long}\n", encoding="utf-8")
    lines = prose_lines(str(page))  # an absolute path: os.path.join keeps it
    assert [n for n, line in lines if len(line) > PROSE_LINE_MAX_CHARS] == [7]
