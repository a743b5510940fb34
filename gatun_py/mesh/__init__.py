"""Stage 1 of the pipeline: the mesh model, input formats, cell splitting and validation."""

from .io import read_mesh, write_mesh
from .model import TetMesh, boundary_faces, signed_volumes
from .validate import MeshReport, validate_tets

__all__ = ["TetMesh", "MeshReport", "read_mesh", "write_mesh", "validate_tets", "boundary_faces", "signed_volumes"]
