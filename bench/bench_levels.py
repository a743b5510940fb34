"""What a file's levels cost over its level 0 (all levels <= 2.0 x level 0).

Run: ``python bench/bench_levels.py`` (writes ``bench/sections/levels.md``).

Each sample is compressed twice by ``gatun_py.compress`` as ``tetc compress`` does: with its
default levels, and with ``levels=0`` (level 0 alone, with its whole merge forest: what on-the-fly
simplification needs without stored levels). *All / level 0 (parts)* is the sum of the file's sections over
level 0's as ``tetc info`` counts them (level 0's bytes include the coarser levels' value tables its
decode reads, format 8); *file / level-0 file* divides the whole file by the file holding level 0
and its forest alone, the ratio a user sees on disk. Bytes are deterministic: no timing here.
"""

from __future__ import annotations

import sys
import time

from common import SAMPLE_FILES, WORK, code_state, note, table, write_section  # noqa: E402

import gatun_py
from gatun_py.codec.info import tetc_info

NAMES = ["bluntfin", "combustion", "post", "fire"]


def measure(name: str) -> list:
    path, kw, _ = SAMPLE_FILES[name]
    out = WORK / "levels"
    out.mkdir(parents=True, exist_ok=True)
    with_levels, level0 = out / f"{name}_levels.tetc", out / f"{name}_level0.tetc"
    gatun_py.compress(path, with_levels, force=True, **kw)
    gatun_py.compress(path, level0, levels=0, force=True, **kw)
    info = tetc_info(with_levels)
    total = sum(p["bytes"] for p in info["parts"])
    total0 = sum(p["level0_bytes"] for p in info["parts"])
    size, size0 = with_levels.stat().st_size, level0.stat().st_size
    print(name, size, size0, total / total0, flush=True)
    return [name, len(info["levels"]), info["format_version"], f"{size:,}", f"{size0:,}", f"{total / total0:.3f}",
            f"{size / size0:.3f}", "met" if total / total0 <= 2.0 else "missed"]


def main() -> None:
    rows = [measure(n) for n in (NAMES[:1] if "--quick" in sys.argv else NAMES)]
    text = "\n".join([
        "## Levels against level 0 (all levels ≤ 2.0 × level 0)", "",
        f"Command: `python bench/bench_levels.py` ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; "
        f"{code_state()}). " + __doc__.split("\n\n")[2].replace("\n", " "), "",
        table(["sample", "levels", "format", "file bytes, with levels", "file bytes, level 0 and its forest",
               "all / level 0 (parts)", "file / level-0 file", "≤ 2.0 (parts)"], rows), "",
        note("levels_history"), ""])
    write_section("levels", text)


if __name__ == "__main__":
    main()
