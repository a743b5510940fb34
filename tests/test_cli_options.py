"""The CLI's option types: bounds agree with the library's, usage errors come before any heavy import."""

from __future__ import annotations

import io
import subprocess
import sys

from gatun_py.cli.options import progress_reporter, status
from gatun_py.raycast.camera import MAX_ZOOM


def test_zoom_bound_matches_the_camera():
    from gatun_py.cli.options import MAX_ZOOM as CLI_MAX_ZOOM

    assert CLI_MAX_ZOOM == MAX_ZOOM


def test_a_usage_error_does_not_load_numba():
    code = ("import sys\nfrom gatun_py.cli.main import tetc\n"
            "try:\n    tetc.main(['render', 'x.tetc', '-o', 'x.png', '--size', '0'], standalone_mode=False)\n"
            "except Exception as e:\n    print(type(e).__name__)\n"
            "print('numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.stdout.split() == ["BadParameter", "False"], out


class _Terminal(io.StringIO):
    """stderr as a terminal, so that click draws its bars."""

    def isatty(self) -> bool:
        return True


def test_a_finished_bar_ends_its_line_before_the_next_status(monkeypatch):
    err = _Terminal()
    monkeypatch.setattr(sys, "stderr", err)
    with progress_reporter("decimating", False, min_total=1) as progress:
        progress(40, 100)
        progress(100, 100)
        status("merge forest: 99 merges", False)
        progress(100, 100)  # after the end: ignored, no second bar
    out = err.getvalue()
    assert "100%" in out and out.count("decimating") >= 1
    before = out[:out.index("merge forest")]
    assert before.endswith("\n"), repr(out[-200:])
    assert "decimating" not in out[out.index("merge forest"):]


def test_quiet_draws_nothing(monkeypatch):
    err = _Terminal()
    monkeypatch.setattr(sys, "stderr", err)
    with progress_reporter("decimating", True, min_total=1) as progress:
        progress(100, 100)
    assert err.getvalue() == ""
