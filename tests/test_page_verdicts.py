"""The pages' verdict words against their records: every verdict between two seed sets carries a marker, and the
words after it are the rule's (``torchrl_csirl.analysis.verdicts``), recomputed from the records it names.

A marker is an HTML comment (Markdown renders it to nothing) right before the verdict's wording::

    <!-- verdict section=pointmaze a=docs/runs/pointmaze-fixed/*/summary.json
         b=docs/runs/pointmaze/PointMaze_UMaze-v3-csirl-s*/summary.json metric=accomplish_rate -->

``a`` and ``b`` are globs relative to the repository root (several joined by ``|``: one side drawn from two record
groups), one record (``summary.json``) a seed; the difference is
``mean(a) - mean(b)`` of ``metric``. The markers of one ``section`` on one page are one family: Holm's correction
across them (:func:`~torchrl_csirl.analysis.verdicts.compare_family`). ``verdict-family`` declares comparisons of the
family that the prose does not state one by one (a table's cells), and is not checked against the text.
``each=NAME:v1,v2`` (repeatable) makes one comparison for every combination of the values, ``{NAME}`` in the globs
replaced by each value, in order (the last ``each`` varying fastest); a checked marker's text then holds their
verdicts in that order.

The text after a marker (to the next marker, at most :data:`REACH` characters) must hold, in order, each comparison's
verdict, "beyond seed noise" or "no difference detected", and after each "no difference detected" a "detectable X"
within :data:`DETECTABLE_TOLERANCE` of the computed minimum detectable difference (:func:`verdict_errors`).
"""
from __future__ import annotations

import glob
import itertools
import json
import os
import re
from dataclasses import dataclass

import pytest

from torchrl_csirl.analysis.verdicts import BEYOND_NOISE, NO_DIFFERENCE, SeedComparison, compare_family

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: the pages whose verdict words follow the rule
PAGES = ("README.md", "docs/benchmark.md", *sorted(os.path.relpath(p, ROOT) for p in glob.glob(
    os.path.join(ROOT, "docs", "studies", "*.md"))), "docs/own-task.md")
#: how far after a marker its verdict may stand
REACH = 400
#: how far a printed detectable difference may lie from the computed one (two decimals, rounded; a return printed
#: in whole units may lie half a unit off)
DETECTABLE_TOLERANCE = 0.006
MARKER = re.compile(r"<!--\s*verdict(-family)?\s+(.*?)-->", re.S)
VERDICT = re.compile(r"(?:not\s+)?beyond\s+seed\s+noise|no\s+difference\s+detected", re.I)
NUMBER = re.compile(r"[−-]?(?:\d{1,3}(?: \d{3})+|\d+)(?:\.\d+)?")  # "0.22", "23 472"
DETECTABLE = re.compile(r"detectable(\s+[−-]?(?:\d{1,3}(?: \d{3})+|\d+)(?:\.\d+)?"
                        r"(?:(?:,|\s+and|,\s+and)\s+[−-]?(?:\d{1,3}(?: \d{3})+|\d+\.\d+))*)")
FENCE = re.compile(r"^(```|~~~).*?^\1", re.S | re.M)

#: words that are no verdict of the rule, where they would pass for one between two seed sets
FORBIDDEN = {
    "level with": re.compile(r"\blevel with\b", re.I),
    "X's level": re.compile(r"'s level\b", re.I),
    "is / are level": re.compile(r"\b(?:is|are|was|were|stays?|remains?|be|sits?|stand) (?:\w+ )?level\b", re.I),
    "no effect": re.compile(r"\bno effect\b", re.I),
    "explained": re.compile(r"\bexplained\b", re.I),
    "within (seed) noise": re.compile(r"\bwithin (?:the )?(?:seed )?noise\b", re.I),
    "does nothing measurable": re.compile(r"\b(?:does|adds) nothing measurable\b", re.I),
    "moves no score": re.compile(r"\bmoves? no score\b", re.I),
    "level": re.compile(r"(?<![-\w])level\b", re.I),
}
FORBIDDEN = {name: re.compile(p.pattern.replace(" ", r"\s+"), re.I) for name, p in FORBIDDEN.items()}  # across lines
#: "level" that is no verdict: a function's place in a module, a test's significance level
NOT_A_VERDICT_LEVEL = re.compile(r"top-level|(?:two-sided|strictest|significance|%)\s+level|level of|level,? 0\.05", re.I)
#: descriptions, not verdicts: a return a policy reached, the expert's or a flipped cheetah's
ALLOWED = re.compile(r"\b(?:the expert's|a flipped cheetah's)\s+level\b", re.I)


@dataclass(frozen=True)
class Marker:
    page: str
    section: str
    checked: bool
    comparisons: tuple[tuple[str, str], ...]  # (a glob, b glob) each
    metric: str
    text: str  # what follows the marker, to the next one or REACH characters

    def __str__(self) -> str:
        return f"{self.page} [{self.section}] {self.comparisons[0][0]} - {self.comparisons[0][1]} ({self.metric})"


def prose(text: str) -> str:
    """The page without its fenced code blocks (blanked, so that offsets keep)."""
    return FENCE.sub(lambda m: re.sub(r"[^\n]", " ", m.group()), text)


def parse_fields(body: str) -> tuple[dict[str, str], list[tuple[str, list[str]]]]:
    fields: dict[str, str] = {}
    each: list[tuple[str, list[str]]] = []
    for token in body.split():
        key, sep, value = token.partition("=")
        assert sep and value, f"marker field without a value: {token!r} in {body!r}"
        if key == "each":
            name, _, values = value.partition(":")
            each.append((name, values.split(",")))
        else:
            assert key not in fields, f"marker field twice: {key} in {body!r}"
            fields[key] = value
    assert {"section", "a", "b", "metric"} <= set(fields) <= {"section", "a", "b", "metric"}, body
    return fields, each


def markers(page: str) -> list[Marker]:
    with open(os.path.join(ROOT, page)) as f:
        text = prose(f.read())
    found = list(MARKER.finditer(text))
    out = []
    for i, match in enumerate(found):
        fields, each = parse_fields(match.group(2))
        end = found[i + 1].start() if i + 1 < len(found) else len(text)
        pairs = []
        for values in itertools.product(*(v for _, v in each)):
            names = {name: value for (name, _), value in zip(each, values)}
            pairs.append((fields["a"].format(**names), fields["b"].format(**names)))
        out.append(Marker(page, fields["section"], match.group(1) is None, tuple(pairs), fields["metric"],
                          text[match.end():min(end, match.end() + REACH)]))
    return out


def records(pattern: str) -> list[str]:
    """The records a side names: one glob, or several joined by ``|`` (each record once)."""
    return sorted({p for part in pattern.split("|") for p in glob.glob(os.path.join(ROOT, part))})


def _scores(paths: tuple[str, ...], metric: str) -> list[float]:
    values = []
    for path in paths:
        with open(path) as f:
            value = json.load(f).get(metric)
        assert value is not None, f"{path}: no {metric}"
        values.append(float(value))
    return values


def families(page: str) -> list[tuple[Marker, list[SeedComparison | None]]]:
    """``(marker, its comparisons)`` of every marker on the page, each section's family under Holm's correction."""
    found = markers(page)
    results: dict[int, list[SeedComparison | None]] = {}
    for section in dict.fromkeys(m.section for m in found):
        members = [(i, m) for i, m in enumerate(found) if m.section == section]
        # one comparison counts once in its family, however many markers name it (a table's cell and its prose)
        keys = {i: [(tuple(records(a)), tuple(records(b)), m.metric) for a, b in m.comparisons] for i, m in members}
        unique = list(dict.fromkeys(k for i, _ in members for k in keys[i]))
        tested = dict(zip(unique, compare_family([(_scores(a, metric), _scores(b, metric)) for a, b, metric in unique])))
        for i, _ in members:
            results[i] = [tested[k] for k in keys[i]]
    return [(m, results[i]) for i, m in enumerate(found)]


def detectable_values(text: str) -> list[tuple[int, float, int]]:
    """``(position, value, decimals)`` of every printed detectable difference: "detectable 0.22", "detectable 0.22, 0.20 and 0.51"."""
    out = []
    for match in DETECTABLE.finditer(text):
        for number in NUMBER.finditer(match.group(1)):
            token = number.group().replace("−", "-").replace(" ", "")
            out.append((match.start(1) + number.start(), float(token), len(token.partition(".")[2])))
    return out


def words(match: re.Match) -> str:
    """The verdict words matched, on one line and in lower case ("not beyond seed noise" is "no difference detected")."""
    found = " ".join(match.group().split()).lower()
    return BEYOND_NOISE if found == BEYOND_NOISE else NO_DIFFERENCE


def verdict_errors(marker: Marker, comparisons: list[SeedComparison | None]) -> list[str]:
    """What the text after a checked marker gets wrong against its comparisons (empty: nothing).

    Each comparison, in order, takes the next verdict words ("beyond seed noise"), or, for "no difference detected",
    the next printed detectable difference, whose verdict words are the last ones before it. Consecutive comparisons
    may share their words: "beyond seed noise on both mazes", "no difference detected on any of the four
    (detectable 0.22, 0.20, 0.51 and 0.22)".
    """
    errors, position = [], 0
    verdicts = list(VERDICT.finditer(marker.text))
    detectables = detectable_values(marker.text)
    for (a, b), c in zip(marker.comparisons, comparisons):
        name = f"{a} - {b}"
        if c is None:
            errors.append(f"{name}: fewer than two seeds a side")
            continue
        numbers = f"{c.difference:+.3f}, t {c.t:.2f}, p {c.p:.3g}, Holm {c.p_holm:.3g} of {c.comparisons}"
        if c.verdict == BEYOND_NOISE:
            found = next((v for v in verdicts if v.start() >= position), None)
            if found is None or words(found) != BEYOND_NOISE:
                errors.append(f"{name}: {found and found.group()!r} where the rule says {BEYOND_NOISE!r} ({numbers})")
                break
            position = found.start()  # the next comparisons may share the words: "beyond seed noise on both"
            continue
        shown = next((d for d in detectables if d[0] >= position), None)
        if shown is None:
            errors.append(f"{name}: no 'detectable {c.detectable:.2f}' after the marker ({NO_DIFFERENCE}: {numbers})")
            break
        before = [v for v in verdicts if v.start() < shown[0]]
        if not before or words(before[-1]) == BEYOND_NOISE:
            errors.append(f"{name}: {words(before[-1]) if before else None!r} before 'detectable {shown[1]}' where the "
                          f"rule says {NO_DIFFERENCE!r} ({numbers})")
        if abs(shown[1] - c.detectable) > max(DETECTABLE_TOLERANCE, 0.5 * 10.0**-shown[2] + 1e-9):  # "5 585": 0.5
            errors.append(f"{name}: detectable {shown[1]} printed, {c.detectable:.3f} computed ({numbers})")
        position = shown[0] + 1
    return errors


ALL_MARKERS = [m for page in PAGES for m in markers(page)]


def test_the_pages_have_markers():
    assert {m.page for m in ALL_MARKERS} >= {"docs/benchmark.md", "docs/studies/outside-driving.md"}


@pytest.mark.parametrize("marker", ALL_MARKERS, ids=str)
def test_every_marker_names_two_seed_sets(marker):
    for a, b in marker.comparisons:
        assert len(records(a)) >= 2 and len(records(b)) >= 2, (a, len(records(a)), b, len(records(b)))
        assert set(records(a)).isdisjoint(records(b)), (a, b)


@pytest.mark.parametrize("page", PAGES)
def test_verdict_words_are_the_rules_recomputed_from_the_records(page):
    errors = [f"{m}: {e}" for m, tested in families(page) if m.checked for e in verdict_errors(m, tested)]
    assert not errors, "\n".join(errors)


@pytest.mark.parametrize("page", PAGES)
def test_no_verdict_words_outside_the_rule(page):
    with open(os.path.join(ROOT, page)) as f:
        text = prose(f.read())
    text = MARKER.sub(lambda m: " " * len(m.group()), text)
    found, flagged = [], set()
    for name, pattern in FORBIDDEN.items():
        for match in pattern.finditer(text):
            around = text[max(0, match.start() - 20):match.end() + 5]
            if ALLOWED.search(around) or (name == "level" and NOT_A_VERDICT_LEVEL.search(around)):
                continue
            if any(start <= match.start() < end for start, end in flagged):
                continue  # "level" inside a "level with" already found
            flagged.add(match.span())
            line = text.count("\n", 0, match.start()) + 1
            found.append(f"{page}:{line}: {name}: ...{text[max(0, match.start() - 40):match.end() + 20]!r}")
    assert not found, "\n".join(found)
