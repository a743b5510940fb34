"""The CLI's option types: bounds agree with the library's, usage errors come before any heavy import."""

from __future__ import annotations

import subprocess
import sys

from gatun_py.render.camera import MAX_ZOOM


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
