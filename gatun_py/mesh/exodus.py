"""Exodus II files (``.e``, ``.exo``, ``.ex2``) with a choice of time step.

Exodus is netCDF; reading it needs the optional ``netCDF4`` package (``pip install
'gatun_py[exodus]'``). meshio's own Exodus reader keeps only the first time step, so this one reads
the nodal variables of the step asked for (default: the last, the converged or final state) and
hands a ``meshio.Mesh`` to the common conversion.
"""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np

from ..errors import OptionError, ReadError

EXODUS_SUFFIXES = (".e", ".exo", ".ex2")
INSTALL_HINT = "reading Exodus files needs netCDF4: pip install netCDF4 (or the extra: pip install 'gatun_py[exodus]')"

# Exodus element type (upper case, digits stripped of the node count where it is the linear one)
# -> meshio cell type; only volume cells matter here, the rest are reported as ignored
ELEMENT_TYPES = {
    "TETRA": "tetra", "TETRA4": "tetra", "TET4": "tetra", "TET": "tetra", "TETRA10": "tetra10", "TET10": "tetra10",
    "HEX": "hexahedron", "HEX8": "hexahedron", "HEXAHEDRON": "hexahedron", "HEX20": "hexahedron20",
    "HEX27": "hexahedron27", "WEDGE": "wedge", "WEDGE6": "wedge", "WEDGE15": "wedge15",
    "PYRAMID": "pyramid", "PYRAMID5": "pyramid", "PYRAMID13": "pyramid13",
    "TRI": "triangle", "TRI3": "triangle", "TRIANGLE": "triangle", "QUAD": "quad", "QUAD4": "quad",
    "SHELL": "quad", "SHELL4": "quad", "BAR2": "line", "BEAM": "line",
}


def _text(rows) -> list[str]:
    return [b"".join(r).decode("utf-8", "replace").strip("\x00 ") for r in np.asarray(rows)]


def read_exodus(path, *, time_step: int | None = None) -> tuple[meshio.Mesh, list[str]]:
    """The mesh and the nodal variables of one time step (index, negative from the end; default last).

    Returns
    -------
    (meshio.Mesh, notes)
    """
    path = Path(path)
    nc = _open(path)
    notes = []
    with nc:
        nc.set_auto_mask(False)
        v = nc.variables
        if "num_nodes" not in nc.dimensions:
            raise ReadError(f"{path}: not an Exodus mesh (no num_nodes dimension)")
        n = len(nc.dimensions["num_nodes"])
        if "coord" in v:
            points = np.asarray(v["coord"][:]).T
        else:
            axes = [np.asarray(v[f"coord{a}"][:]) if f"coord{a}" in v else np.zeros(n) for a in "xyz"]
            points = np.stack(axes, axis=1)
        cells, block_ids = [], []
        for key in sorted((k for k in v if k.startswith("connect")), key=lambda k: int(k[7:] or 0)):
            etype = str(getattr(v[key], "elem_type", "")).upper()
            if etype not in ELEMENT_TYPES:
                notes.append(f"element block {key} of type {etype or '?'} ignored")
                continue
            cells.append((ELEMENT_TYPES[etype], np.asarray(v[key][:], np.int64) - 1))
            block_ids.append(key[7:])
        point_sets = {}
        set_names = _text(v["ns_names"][:]) if "ns_names" in v else []
        for k in range(1, 1 + sum(1 for x in v if x.startswith("node_ns"))):
            if f"node_ns{k}" in v:
                name = set_names[k - 1] if k - 1 < len(set_names) and set_names[k - 1] else f"node_set_{k}"
                point_sets[name] = np.asarray(v[f"node_ns{k}"][:], np.int64) - 1
        names = _text(v["name_nod_var"][:]) if "name_nod_var" in v else []
        n_steps = len(nc.dimensions["time_step"]) if "time_step" in nc.dimensions else 0
        point_data = {}
        if names and n_steps:
            t = n_steps - 1 if time_step is None else int(time_step)
            if not -n_steps <= t < n_steps:
                raise OptionError(f"{path}: time step {time_step} does not exist (the file has {n_steps}: "
                                  f"0..{n_steps - 1}, or -1 for the last)")
            t %= n_steps
            times = np.asarray(v["time_whole"][:]) if "time_whole" in v else None
            when = f" (time {float(times[t]):g})" if times is not None and len(times) > t else ""
            if n_steps > 1:
                notes.append(f"nodal variables of time step {t} of 0..{n_steps - 1}{when}")
            for k, name in enumerate(names):
                if f"vals_nod_var{k + 1}" in v:
                    point_data[name] = np.asarray(v[f"vals_nod_var{k + 1}"][t])
                elif "vals_nod_var" in v:  # the older layout: one (time, variable, node) array
                    point_data[name] = np.asarray(v["vals_nod_var"][t, k])
        elif time_step not in (None, 0, -1):
            raise OptionError(f"{path}: the file has no time steps of nodal variables")
        cell_data = {}
        enames = _text(v["name_elem_var"][:]) if "name_elem_var" in v else []
        if enames and n_steps:
            t = (n_steps - 1 if time_step is None else int(time_step)) % n_steps
            for k, name in enumerate(enames):
                per = [v.get(f"vals_elem_var{k + 1}eb{b}") for b in block_ids]
                if all(x is not None for x in per):
                    cell_data[name] = [np.asarray(x[t]) for x in per]
                else:  # a variable some blocks do not have: no value to give their cells
                    notes.append(f"element variable {name!r} skipped: not defined on every element block")
    return meshio.Mesh(points, cells, point_data=point_data, cell_data=cell_data, point_sets=point_sets), notes


def _open(path):
    """The Exodus file as a netCDF4 dataset (ReadError when netCDF4 is missing or cannot read it)."""
    try:
        import netCDF4  # optional dependency
    except ImportError:
        raise ReadError(f"{path}: {INSTALL_HINT}") from None
    try:
        return netCDF4.Dataset(str(path))
    except OSError as e:
        raise ReadError(f"cannot read {path} as Exodus: {e}") from None


def exodus_times(path) -> list[float]:
    """The time of every step of an Exodus file (``time_whole``; 0, 1, ... when it has none)."""
    path = Path(path)
    nc = _open(path)
    with nc:
        nc.set_auto_mask(False)
        n = len(nc.dimensions["time_step"]) if "time_step" in nc.dimensions else 0
        if "time_whole" in nc.variables:
            t = np.asarray(nc.variables["time_whole"][:], np.float64).reshape(-1)
            if len(t) == n:
                return [float(x) for x in t]
        return [float(k) for k in range(n)]
