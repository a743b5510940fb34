"""``tetc info`` for ``.tetc`` files: sizes, counts and the codec's figures."""

from __future__ import annotations

import re

from .geometry import MAX_HEADER_SIZE, geometry_stream_sizes
from .tetcfile import TetcReader

_BRICK = re.compile(r"^B\d+/")


def tetc_info(source) -> dict:
    """Describe a ``.tetc`` file without decoding it.

    Parameters
    ----------
    source : path-like, bytes or TetcReader

    Returns
    -------
    dict
        ``points``, ``tets``, ``boundary_faces``, ``bbox``, ``scalar``, ``scalar_range``,
        ``source``, ``bytes_total``, ``bits_per_tet_connectivity`` (boundary and tet sections of
        level 0 over its tets), ``bits_per_vertex_geometry`` (geometry section of level 0 over its
        points), ``sections`` (name -> bytes), ``levels`` (one dict per stored level) and
        ``forest`` (``merges``, ``max_ratio``, ``bytes`` of all stored forests), ``format_version``,
        ``points_dtype`` and ``arrays`` (``name``, ``dtype``, ``components``, ``bytes`` in level 0
        -- for the float32 default scalar, its share is inside the geometry section; ``copies``,
        when some components are stored as references to another array's: ``"uvw[0] = u, ..."``), and ``parts``:
        what the bytes are, summed over levels and bricks, largest first (``part``, ``bytes``,
        ``level0_bytes``, ``share`` of the sections' total). ``level0_bytes`` are the bytes a
        decode of level 0 reads: its sections, and in format 8 the value tables of the coarser
        levels its geometry is chained to (part ``geometry value tables``: the table streams of
        the geometry sections, :mod:`gatun_py.codec.geometry`, apart from the rest of them).
    """
    r = source if isinstance(source, TetcReader) else TetcReader(source)
    c = r.container
    sizes = {name: c.section_size(name) for name in c.section_names()}
    # a bricked file's figures are its bricks' together (sections named B{k}/L{i}/...)
    plain = {}
    for name, v in sizes.items():
        key = _BRICK.sub("", name)
        plain[key] = plain.get(key, 0) + v
    lv0 = r.levels[0]
    i0 = lv0.level
    conn = plain.get(f"L{i0}/boundary", 0) + plain.get(f"L{i0}/tets", 0)
    geo = plain.get(f"L{i0}/geometry", 0)
    levels = []
    for lv in r.levels:
        i = lv.level
        levels.append({
            "level": i,
            "ratio": lv.ratio,
            "points": lv.points,
            "tets": lv.tets,
            "bytes": sum(v for k, v in plain.items() if k.startswith(f"L{i}/")),
        })
    return {
        "points": r.meta.get("points"),
        "tets": r.meta.get("tets"),
        "boundary_faces": r.meta.get("boundary_faces"),
        "bbox": r.meta.get("bbox"),
        "scalar": r.meta.get("scalar") if r.has_scalar else None,
        "scalar_range": r.meta.get("scalar_range") if r.has_scalar else None,
        "source": r.meta.get("source"),
        "bytes_total": c.size,
        "bits_per_tet_connectivity": round(8.0 * conn / lv0.tets, 4) if lv0.tets else 0.0,
        "bits_per_vertex_geometry": round(8.0 * geo / lv0.points, 4) if lv0.points else 0.0,
        "sections": sizes,
        "format_version": c.major,
        "points_dtype": r.points_dtype.name,
        "arrays": [dict({"name": name, "dtype": dt.name, "components": k, "bytes": plain.get(f"L{i0}/array/{j}", 0)},
                        **({"copies": _copies_text(r, j)} if j in r.copies else {}))
                   for j, (name, dt, k) in enumerate(r.arrays) if name],
        "levels": levels,
        "parts": _parts(r, plain, i0, _table_streams(r, sizes)),
        "forest": _forest_info(r, sizes),
        **_cells_info(r, sizes),
        "bricks": _bricks_info(r, sizes),
    }


def _bricks_info(reader, sizes) -> list:
    """Per brick (none for a one-brick file): bounds, points, tets, cut vertices, bytes."""
    if reader.n_bricks == 1:
        return []
    out = []
    for k in range(reader.n_bricks):
        m = reader.brick(k).meta
        out.append({"brick": k, "bounds": m["brick_bounds"], "points": m["points"], "tets": m["tets"],
                    "cut_points": m["brick_cut_points"],
                    "bytes": sum(v for name, v in sizes.items() if name.startswith(f"B{k}/"))})
    return out


def _forest_info(reader, sizes) -> dict:
    """``merges``, ``max_ratio`` and ``bytes`` of the stored merge forest (all zero without one)."""
    merges = reader.forest_merges()
    n0 = reader.levels[0].points
    return {"merges": merges, "max_ratio": merges / n0 if n0 else 0.0,
            "bytes": sum(v for k, v in sizes.items() if k.endswith("/forest"))}


_PART_OF_KIND = {"boundary": "connectivity", "tets": "connectivity", "geometry": "geometry",
                 "points64": "float64 coordinates", "forest": "merge forests", "cut": "brick cut vertices",
                 "deps": "merge dependencies"}


_TABLES = "geometry value tables"


def _table_streams(reader, sizes) -> tuple[dict, int]:
    """({plain section name: bytes of its geometry table stream}, the table-stream bytes of the
    coarser levels a decode of level 0 reads), summed over bricks; empty before format 8."""
    if reader.container.major < 8:
        return {}, 0
    c = reader.container
    order = [lv.level for lv in reader.levels]
    own, chained0 = {}, 0
    prefixes = sorted({m.group(0) for m in map(_BRICK.match, sizes) if m}) or [""]
    for prefix in prefixes:
        heads = {}
        for i in order:
            name = f"{prefix}L{i}/geometry"
            if name in sizes:
                heads[i] = geometry_stream_sizes(c.read_section_head(name, MAX_HEADER_SIZE))
                own[f"L{i}/geometry"] = own.get(f"L{i}/geometry", 0) + heads[i].get("tables", 0)
        # level 0 (the first level) reads the table streams of its chained channels in the levels
        # their chains reach
        need = [ch for ch in ("x", "y", "z", "density") if order[0] in heads and heads[order[0]][ch + "_mode"] == "chained"]
        at = 0
        while need and at + 1 < len(order) and order[at + 1] in heads:
            at += 1
            chained0 += sum(heads[order[at]].get(ch + "_table", 0) for ch in need)  # none before coding 4
            need = [ch for ch in need if heads[order[at]][ch + "_mode"] == "chained"]
    return own, chained0


def _copies_text(reader, j: int) -> str:
    """Array j's components stored as references, e.g. ``uvw[0] = u, uvw[2] = density``."""
    def label(k, c):
        name, _, n = reader.arrays[k]
        return name if n == 1 else f"{name}[{c}]"
    return ", ".join(f"{label(j, c)} = {label(k, kc)}" for c, k, kc in reader.copies[j])


def _parts(reader, plain: dict, i0: int, tables: tuple = ({}, 0)) -> list:
    """Section bytes by what they hold (see :func:`tetc_info`'s ``parts``); ``tables`` from
    :func:`_table_streams`."""
    names = [name for name, _, _ in reader.arrays]
    total = max(sum(plain.values()), 1)
    parts = {}
    own_tables, chained0 = tables
    if own_tables:
        plain = dict(plain)
        for key, v in own_tables.items():
            plain[key] -= v
        row = parts.setdefault(_TABLES, [0, chained0])
        for key, v in own_tables.items():
            row[0] += v
            if key.startswith(f"L{i0}/"):
                row[1] += v
    for key, v in plain.items():
        level, _, kind = key.partition("/")
        if not level.startswith("L"):
            level, kind = "", key
        if kind.startswith("array/"):
            j = kind.split("/", 1)[1]
            name = names[int(j)] if j.isdigit() and int(j) < len(names) else j
            part = f"array {name!r}"
        else:
            part = _PART_OF_KIND.get(kind, kind)
        row = parts.setdefault(part, [0, 0])
        row[0] += v
        if level == f"L{i0}":
            row[1] += v
    return [{"part": part, "bytes": b, "level0_bytes": b0, "share": round(b / total, 4)}
            for part, (b, b0) in sorted(parts.items(), key=lambda kv: -kv[1][0])]


def _cells_info(r, sizes: dict) -> dict:
    """``cells`` (blocks, cell arrays, bytes of the cell sections) and ``keep_order`` (bytes of the
    stored numbering, in bits per point and per cell) of a file that stores its cells as given."""
    meta = r.meta.get("cells")
    if not isinstance(meta, dict):
        return {}
    blocks = [b for b in meta.get("blocks", []) if isinstance(b, dict)]
    n_cells = sum(int(b.get("cells", 0)) for b in blocks)
    out = {"cells": {
        "blocks": [f"{b.get('type')} {b.get('cells')}" for b in blocks],
        "cell_arrays": [{"name": e.get("name"), "dtype": (e.get("blocks") or [{}])[0].get("dtype"),
                         "shape": (e.get("blocks") or [{}])[0].get("shape"),
                         "bytes": sum(v for k, v in sizes.items() if k.startswith(f"C/data/{j}/"))}
                        for j, e in enumerate(meta.get("cell_data", [])) if isinstance(e, dict)],
        "bytes": sum(v for k, v in sizes.items() if k.startswith("C/") and not k.startswith("C/order")),
    }}
    if meta.get("keep_order"):
        b = sum(v for k, v in sizes.items() if k.startswith("C/order"))
        pts = max(int(r.meta.get("points", 0)), 1)
        out["keep_order"] = {"bytes": b, "bits_per_point": round(8.0 * sizes.get("C/order/points", 0) / pts, 3),
                             "bits_per_cell": round(8.0 * (b - sizes.get("C/order/points", 0)) / max(n_cells, 1), 3)}
    return out
