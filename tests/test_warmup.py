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
