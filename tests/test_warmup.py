"""The kernel warm-up: its shipped sample file stays current."""

from __future__ import annotations

from gatun_py.codec import TetcReader
from gatun_py.warmup import SHIPPED_TETC, tiny_mesh, tiny_tetc_bytes


def test_shipped_tetc_is_the_tiny_mesh_encoded_today():
    # regenerate with: python -c "from gatun_py.warmup import *; SHIPPED_TETC.write_bytes(tiny_tetc_bytes())"
    assert SHIPPED_TETC.read_bytes() == tiny_tetc_bytes()
    mesh = TetcReader(SHIPPED_TETC).decode_mesh(0)
    ref = tiny_mesh()
    assert mesh.n_tets == ref.n_tets and mesh.n_points == ref.n_points


def test_forest_section_of_the_cold_start_is_what_the_encoder_writes_today():
    import numpy as np

    from gatun_py.codec.forest import decode_forest_on_mesh, encode_forest_on_mesh
    from gatun_py.warmup import FOREST_PARENT_RANK, FOREST_SECTION, FOREST_TETS

    parent, rank = (np.array(a) for a in FOREST_PARENT_RANK)
    assert encode_forest_on_mesh(parent, rank, FOREST_TETS, boundary=np.ones(5, bool)) == FOREST_SECTION
    p, r = decode_forest_on_mesh(FOREST_SECTION, FOREST_TETS, 5, boundary=np.ones(5, bool))
    assert np.array_equal(p, parent) and np.array_equal(r, rank)
