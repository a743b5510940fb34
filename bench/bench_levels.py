"""What a file's levels cost over its level 0 (issue 12: all levels <= 2.0 x level 0).

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

from common import SAMPLE_FILES, WORK, code_state, table, write_section  # noqa: E402

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
        "## Levels against level 0 (issue 12: all levels ≤ 2.0 × level 0)", "",
        f"Command: `python bench/bench_levels.py` ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; "
        f"{code_state()}). " + __doc__.split("\n\n")[2].replace("\n", " "), "",
        table(["sample", "levels", "format", "file bytes, with levels", "file bytes, level 0 and its forest",
               "all / level 0 (parts)", "file / level-0 file", "≤ 2.0 (parts)"], rows), "",
        "Format 7 (session 15, the same samples): all / level 0 2.529 (Blunt-fin), 2.359 (Combustion), "
        "2.555 (LOX post), 2.160 (Room fire). Format 8 chains each level's value tables to the next coarser "
        "level's (geometry coding 4, `docs/format.md`), so a value is sent once for the levels that share it; Room fire's u, v and w are stored once, as copies of uvw's components (format 8's array copies: its file 664,928 -> 422,802 bytes with levels). "
        "Levels of fewer than 128 points are not stored (`MIN_LEVEL_POINTS`: the level before them decodes in a "
        "fraction of a millisecond and keeps the remaining merges); with every level down to a few points "
        "(session 16, same code otherwise) the files were Blunt-fin 337,292 bytes (2.007), Combustion 933,696 "
        "(2.292), LOX post 36,068 (1.891), Room fire 422,802 (2.176). Format 9 (geometry coding 5: rank steps "
        "on the table-mode channels) against format 8 with the same levels (session 18): files with levels "
        "Blunt-fin 332,139 -> 327,389 bytes (2.000 -> 1.992), LOX post 31,079 -> 30,724, Room fire 412,352 -> "
        "406,097 (2.149 either way: the steps shrink level 0 and the levels alike); Combustion has no tables "
        "(+1 header byte a level).", ""])
    write_section("levels", text)


if __name__ == "__main__":
    main()
