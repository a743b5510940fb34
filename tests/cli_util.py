"""Shared helpers for the CLI tests: run `tetc` in-process and check the one-line error contract."""

from __future__ import annotations

from click.testing import CliRunner

from gatun_py.cli.main import tetc


def run(*args):
    """Invoke ``tetc`` with string-converted arguments (exceptions propagate: a traceback is a bug)."""
    return CliRunner().invoke(tetc, [str(a) for a in args], catch_exceptions=False)


def assert_usage_error(res, *fragments):
    """Exit code 2 (click's usage error), naming every fragment, no traceback."""
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and "Error:" in res.output
    for f in fragments:
        assert f in res.output, (f, res.output)


def assert_error(res, *fragments):
    """Exit code 1, exactly one non-empty line starting ``tetc: error:``, containing every fragment."""
    assert res.exit_code == 1, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("tetc: error: "), res.output
    assert "Traceback" not in res.output
    for f in fragments:
        assert f in lines[0], (f, lines[0])
