"""Stage 1 of the pipeline: the mesh model, input formats, cell splitting, validation, the tet stream."""

from .io import mesh_from_meshio, read_mesh, write_mesh
from .model import TET_FACES, TetMesh, boundary_faces, default_step, signed_volumes
from .stream import TetBatch, mesh_batches
from .partition import Brick, partition_tets, split_bricks
from .validate import MeshReport, validate_tets

__all__ = ["TetMesh", "MeshReport", "TetBatch", "TET_FACES", "read_mesh", "write_mesh", "mesh_from_meshio", "validate_tets",
           "boundary_faces", "signed_volumes", "default_step", "mesh_batches", "Brick", "partition_tets",
           "split_bricks"]
