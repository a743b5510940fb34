"""The library, the CLI and the bench scripts state techniques, not their history: no issue or session
numbers and no machine paths in their sources (figures and the story of how they were reached live
in ``bench/sections/*.md``)."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PATTERN = re.compile(r"issue \d+|session \d+|/work/|/root/", re.IGNORECASE)


def _sources():
    files = []
    for tree in ("gatun_py", "cli"):
        files += sorted((ROOT / tree).rglob("*.py"))
    files += sorted((ROOT / "bench").glob("*.py"))
    return files


def test_sources_are_found():
    names = {p.name for p in _sources()}
    assert {"api.py", "common.py", "caster.py"} <= names


def test_no_issue_session_or_machine_path():
    hits = [f"{path.relative_to(ROOT)}:{i}: {line.strip()}" for path in _sources()
            for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1) if PATTERN.search(line)]
    assert not hits, "lab notebook in the sources (move it to bench/sections/*.md):\n" + "\n".join(hits)


def test_pattern_catches_what_it_should():
    for bad in ("(issue 12)", "Session 14:", "/work/main", "/root/.cache"):
        assert PATTERN.search(bad)
    assert not PATTERN.search("an issue with the border")
