"""Where the bytes of a pieced (or bricked) ``.tetc`` file go, against the same mesh as one piece.

A per-section size table: every section's payload summed over the bricks by its name without the
brick prefix (``B3/L0/points`` counts as ``L0/points``), the cut lists, the record heads (name and
length of every section), the metadata split into its section index, its brick index and the rest.
Sizes are exact bytes (independent of the machine's load)::

    python bench/pieces_sizes.py pieces.tetc whole.tetc           # prints the table
    python bench/pieces_sizes.py pieces.tetc whole.tetc --write   # also bench/sections/pieces_sizes.md
"""

from __future__ import annotations

import json
import re
import sys
import zlib
from collections import defaultdict
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from common import code_state, table, write_section  # noqa: E402


def breakdown(path) -> dict:
    """``{row name: bytes}`` of one file; the rows add up to the file size."""
    from gatun_py.codec.container import PREAMBLE_SIZE, Container

    c = Container(Path(path).read_bytes())
    rows = defaultdict(int)
    n_records = 0
    for name in c.section_names():
        plain = re.sub(r"^B\d+/", "", name)
        kind = re.sub(r"^L\d+/", "L*/", plain) if not plain.startswith("L0/") else plain
        rows[kind] += c.section_size(name)
        rows["record heads"] += 2 + len(name.encode("utf-8")) + 12
        n_records += 1
    meta = dict(c.meta)
    dumps = lambda v: len(json.dumps(v, separators=(",", ":")).encode("utf-8"))  # noqa: E731
    total_meta = dumps(meta)
    rows["meta: section index"] = dumps(meta.pop("sections", []))
    rows["meta: brick index"] = dumps(meta.pop("bricks", [])) if "bricks" in meta else 0
    rows["meta: pieces"] = dumps(meta.pop("pieces", [])) if "pieces" in meta else 0
    rows["meta: rest"] = total_meta - rows["meta: section index"] - rows["meta: brick index"] - rows["meta: pieces"]
    rows["preamble"] = PREAMBLE_SIZE
    rows["(records)"] = n_records
    # what the metadata would take compressed (not in the file: an estimate of that cut)
    rows["(meta zlib -9)"] = len(zlib.compress(json.dumps(c.meta, separators=(",", ":")).encode("utf-8"), 9))
    return dict(rows)


def compare(a, b) -> str:
    ra, rb = breakdown(a), breakdown(b)
    size_a, size_b = Path(a).stat().st_size, Path(b).stat().st_size
    keys = sorted(set(ra) | set(rb), key=lambda k: (k.startswith("("), k.startswith("meta") or k in (
        "record heads", "preamble"), not k.startswith("L0/"), k))
    rows = [[k, ra.get(k, 0), rb.get(k, 0), ra.get(k, 0) - rb.get(k, 0),
             f"{100.0 * (ra.get(k, 0) - rb.get(k, 0)) / size_b:+.3f} %"] for k in keys]
    rows.append(["file", size_a, size_b, size_a - size_b, f"{100.0 * (size_a - size_b) / size_b:+.3f} %"])
    return table(["section", Path(a).name, Path(b).name, "difference", "of the second file"], rows)


def counts(path) -> str:
    """Points, shared points, the points the bricks hold (a shared point in every brick holding it)
    and levels per brick of a pieced file, or the levels of a plain file."""
    from gatun_py.codec.container import Container

    m = Container(Path(path).read_bytes()).meta
    if "bricks" not in m:
        return f"`{Path(path).name}`: {m['points']:,} points, {len(m['levels'])} levels"
    held = sum(b["points"] for b in m["bricks"])
    return (f"`{Path(path).name}`: {m['points']:,} points, {m['cut_points']:,} shared; the bricks hold {held:,} "
            f"({100.0 * (held / m['points'] - 1):+.2f} %); boundary faces of the bricks "
            f"{sum(b['boundary_faces'] for b in m['bricks']):,} against {m['boundary_faces']:,} of the mesh; "
            f"levels per brick {sorted({len(b['levels']) for b in m['bricks']})}")


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if a != "--write"]
    if len(args) != 2:
        raise SystemExit(__doc__.split("::")[-1])
    text = compare(*args)
    print(text)
    if "--write" in sys.argv:
        write_section("pieces_sizes", f"""## Pieces: where the bytes of a pieced file go

`python bench/pieces_sizes.py {Path(args[0]).name} {Path(args[1]).name} --write` ({code_state()}; exact bytes,
independent of the load). Each row sums a section kind over the bricks; `L*` are the levels above 0.
The files: `tetc compress --jobs 1` of `bench/pieces_data.py`'s pieces (the `.pvtu`) and of the same mesh
as one file (`whole.vtu`, `--whole`).

{text}

{counts(args[0])}.
{counts(args[1])}.
""")
