"""The cells a mesh file gave, beside the tets the pipeline works on.

A volume cell (tetra, hexahedron, wedge, pyramid and their quadratic forms) is split into tets by
:mod:`.split`; its corners are the vertices of its tets, and its higher-order nodes (mid-edge,
mid-face, centre) are points no tet refers to. :class:`Cells` keeps every block as given (type,
order, each cell's vertex order), which tet came from which cell, and what rides on the cells:
cell arrays, field data, point and cell sets. The codec (:mod:`gatun_py.codec.cells`) stores the
cells against the decoded tets, so what it needs from here is this relation, not a second copy of
the connectivity.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import MeshError, OptionError
from .model import TetMesh, scalar_of

try:  # meshio's table of cell dimensions, which CellBlock consults (see _register_with_meshio)
    from meshio._mesh import topological_dimension as _MESHIO_DIMENSION
except ImportError:
    _MESHIO_DIMENSION = None

# meshio volume cell type -> (linear type, corners)
VOLUME_CELLS = {
    "tetra": ("tetra", 4), "tetra10": ("tetra", 4), "tetra20": ("tetra", 4),
    "hexahedron": ("hexahedron", 8), "hexahedron20": ("hexahedron", 8), "hexahedron24": ("hexahedron", 8),
    "hexahedron27": ("hexahedron", 8),
    "wedge": ("wedge", 6), "wedge12": ("wedge", 6), "wedge15": ("wedge", 6), "wedge18": ("wedge", 6),
    "pyramid": ("pyramid", 5), "pyramid13": ("pyramid", 5), "pyramid14": ("pyramid", 5),
}

# meshio's fixed-size cell types below three dimensions (stored as given, beside the volume cells)
OTHER_CELLS = {
    "vertex": 1, "line": 2, "line3": 3, "line4": 4, "triangle": 3, "triangle6": 6, "triangle7": 7,
    "triangle10": 10, "quad": 4, "quad8": 8, "quad9": 9,
}

_TET_EDGES = [(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)]
_HEX_EDGES = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)]
_HEX_FACES = [(0, 3, 7, 4), (1, 2, 6, 5), (0, 1, 5, 4), (3, 2, 6, 7), (0, 1, 2, 3), (4, 5, 6, 7)]
_WEDGE_EDGES = [(0, 1), (1, 2), (2, 0), (3, 4), (4, 5), (5, 3), (0, 3), (1, 4), (2, 5)]
_PYRAMID_EDGES = [(0, 1), (1, 2), (2, 3), (3, 0), (0, 4), (1, 4), (2, 4), (3, 4)]

# The corners each higher-order node of a type sits on (VTK's node order, which meshio uses): a
# node is predicted as the one a face-neighbouring cell already put on the same edge or face.
# Only a prediction: a table that does not match a file costs bytes, never exactness.
NODE_SUPPORTS = {
    "tetra10": _TET_EDGES,
    "hexahedron20": _HEX_EDGES,
    "hexahedron27": _HEX_EDGES + _HEX_FACES + [tuple(range(8))],
    "wedge15": _WEDGE_EDGES,
    "wedge18": _WEDGE_EDGES + [(0, 1, 4, 3), (1, 2, 5, 4), (2, 0, 3, 5)],
    "pyramid13": _PYRAMID_EDGES,
    "pyramid14": _PYRAMID_EDGES + [(0, 1, 2, 3)],
}


def _register_with_meshio() -> None:
    """meshio's readers produce some volume types (VTK's wedge15, pyramid13, ...) that its
    ``CellBlock`` then cannot hold (no dimension listed for them): list them."""
    if _MESHIO_DIMENSION is None:  # another meshio layout: nothing to add
        return
    for t in VOLUME_CELLS:
        _MESHIO_DIMENSION.setdefault(t, 3)


_register_with_meshio()


def cell_size(cell_type: str) -> int | None:
    """Vertices per cell of a meshio cell type, None for types of no fixed size."""
    if cell_type in OTHER_CELLS:
        return OTHER_CELLS[cell_type]
    digits = "".join(ch for ch in cell_type if ch.isdigit())
    if cell_type in VOLUME_CELLS:
        return int(digits) if digits else {"tetra": 4, "hexahedron": 8, "wedge": 6, "pyramid": 5}[cell_type]
    return None


def check_cell_type(cell_type: str, source: str = "mesh") -> None:
    """MeshError naming a cell type that cannot be stored (polyhedra, polygons, unknown types)."""
    if cell_type in VOLUME_CELLS or cell_type in OTHER_CELLS:
        return
    if cell_type.startswith("polyhedron"):
        raise MeshError(f"{source}: cell type {cell_type!r} (polyhedra of any number of faces) cannot be stored: "
                        "split them into tets, hexahedra, wedges or pyramids first")
    if cell_type.startswith("polygon"):
        raise MeshError(f"{source}: cell type {cell_type!r} (polygons) cannot be stored: triangulate them first")
    raise MeshError(f"{source}: cell type {cell_type!r} is not supported (volume cells: "
                    f"{', '.join(VOLUME_CELLS)}; others: {', '.join(OTHER_CELLS)})")


@dataclass(eq=False)
class Cells:
    """The cell blocks of a mesh as given, and how its tets relate to them.

    Attributes
    ----------
    blocks : list of (str, (n, k) int64 array)
        Every block in file order: meshio type and vertex ids (the mesh's point ids).
    tet_cell : (m,) int64
        For each tet of the mesh (in the mesh's tet order), its cell: the index among the volume
        cells of every volume block, in block order.
    cell_data : dict
        ``name -> [one array per block]``, each (n,) or (n, c), in its dtype (bool included).
    field_data, point_sets, cell_sets : dict
        As meshio holds them (sets: point ids; per block cell ids).
    """

    blocks: list
    tet_cell: np.ndarray
    cell_data: dict = field(default_factory=dict)
    field_data: dict = field(default_factory=dict)
    point_sets: dict = field(default_factory=dict)
    cell_sets: dict = field(default_factory=dict)
    keep_order: bool = False  # store the point order, the cell order and every tet's vertex order too
    # decoded with keep_order: (original id of every decoded point, {block: original index of every
    # cell in the block's decoded order})
    order: tuple | None = None

    @property
    def volume(self) -> list[bool]:
        return [t in VOLUME_CELLS for t, _ in self.blocks]

    @property
    def n_volume_cells(self) -> int:
        return sum(len(d) for t, d in self.blocks if t in VOLUME_CELLS)

    def needed(self) -> bool:
        """Whether anything here is more than one block of linear tets, which the tets themselves
        give back (up to each tet's vertex order and the order of the tets)."""
        return (self.keep_order or len(self.blocks) != 1 or self.blocks[0][0] != "tetra" or bool(self.cell_data)
                or bool(self.field_data) or bool(self.point_sets) or bool(self.cell_sets))


def is_raw_set(name: str) -> bool:
    """meshio's gmsh reader keeps entity tags, not cell ids, under ``gmsh:...`` cell sets (such as
    ``gmsh:bounding_entities``): those are stored as given, not as cells."""
    return str(name).startswith("gmsh:")


def check_cells(cells: Cells, n_points: int, source: str = "mesh") -> None:
    """MeshError on what cannot be stored: unknown types, ids out of range, cell arrays whose length
    does not match their block, sets that name missing points or cells."""
    for t, d in cells.blocks:
        check_cell_type(t, source)
        if d.ndim != 2 or d.shape[1] != cell_size(t):
            raise MeshError(f"{source}: a {t} block has shape {d.shape}, expected (n, {cell_size(t)})")
        if d.size and (int(d.min()) < 0 or int(d.max()) >= n_points):
            raise MeshError(f"{source}: a {t} cell refers to a point outside 0..{n_points - 1}")
    for name, arrays in cells.cell_data.items():
        if len(arrays) != len(cells.blocks):
            raise MeshError(f"{source}: cell array {name!r} has {len(arrays)} blocks, the mesh {len(cells.blocks)}")
        for (t, d), a in zip(cells.blocks, arrays):
            a = np.asarray(a)
            if a.ndim == 0 or a.shape[0] != len(d):
                raise MeshError(f"{source}: cell array {name!r} has {a.shape[0] if a.ndim else 0} values for "
                                f"{len(d)} {t} cells")
            if a.dtype.kind not in "fiub" or a.dtype.itemsize > 8:
                raise MeshError(f"{source}: cell array {name!r} has dtype {a.dtype} (floats, integers and "
                                "booleans only)")
    for name, ids in cells.point_sets.items():
        ids = np.asarray(ids)
        if ids.size and (ids.dtype.kind not in "iu" or int(ids.min()) < 0 or int(ids.max()) >= n_points):
            raise MeshError(f"{source}: point set {name!r} names a point outside 0..{n_points - 1}")
    for name, per_block in cells.cell_sets.items():
        if is_raw_set(name):
            continue
        if len(per_block) != len(cells.blocks):
            raise MeshError(f"{source}: cell set {name!r} has {len(per_block)} blocks, the mesh {len(cells.blocks)}")
        for (t, d), ids in zip(cells.blocks, per_block):
            ids = np.asarray([] if ids is None else ids)
            if ids.size and (ids.dtype.kind not in "iu" or int(ids.min()) < 0 or int(ids.max()) >= len(d)):
                raise MeshError(f"{source}: cell set {name!r} names a cell outside the {len(d)} {t} cells")


def tet_values(cells: Cells, name: str, component=None) -> np.ndarray:
    """One float64 value per tet from the cell array ``name``: the value of the tet's cell (a
    vector's ``component``, or its ``"magnitude"``).

    Raises
    ------
    OptionError
        No such cell array, or a component that does not fit it.
    """
    if name not in cells.cell_data:
        raise OptionError(f"no cell array named {name!r}; cell arrays: "
                          f"{', '.join(map(repr, cells.cell_data)) or 'none'}")
    per_block = [np.asarray(a) for (t, _), a in zip(cells.blocks, cells.cell_data[name]) if t in VOLUME_CELLS]
    widths = {a.reshape(len(a), -1).shape[1] for a in per_block}
    if len(widths) > 1:
        raise OptionError(f"cell array {name!r} has a different number of components per block")
    flat = np.concatenate([a.reshape(len(a), -1) for a in per_block]) if per_block else np.zeros((0, 1))
    try:
        per_cell = scalar_of({name: flat[:, 0] if flat.shape[1] == 1 else flat}, name, component)
    except ValueError as e:
        raise OptionError(str(e)) from None
    return per_cell[cells.tet_cell]


def constant_per_cell(mesh: TetMesh, values: np.ndarray, name: str) -> TetMesh:
    """``mesh`` with ``values`` (one per tet) as its scalar, constant inside every tet.

    A point scalar is interpolated inside each tet, so a value per tet is rendered as a point scalar
    on points that are not shared across a change of value: every point gets one copy per distinct
    value among its tets (the value rounded to float32, as a rendered scalar is). Tets of equal value
    keep sharing their faces, so a cell array that is constant over large regions (material ids,
    tags) adds few points; where the value changes, the two tets no longer share the face, and
    rays cross from one to the other as between two touching parts of a mesh.
    """
    v32 = np.asarray(values, dtype=np.float32).reshape(-1)
    if len(v32) != mesh.n_tets:
        raise OptionError(f"{len(v32)} values for {mesh.n_tets} tets")
    tets = np.asarray(mesh.tets, np.int64)
    bits = np.repeat(v32.view(np.uint32).astype(np.int64), 4)
    key = tets.reshape(-1) * (1 << 32) + bits
    uniq, inverse = np.unique(key, return_inverse=True)
    vertex = uniq >> 32
    density = (uniq & 0xFFFFFFFF).astype(np.uint32).view(np.float32)
    return TetMesh(np.asarray(mesh.points)[vertex], density, inverse.reshape(-1, 4).astype(np.int32), name)
