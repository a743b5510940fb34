"""Stage 3: offline Van Gelder decimation (merge forest, pre-simplified levels) and the run-time filter."""

from .decimation import DEFAULT_W_DENSITY, DEFAULT_W_GEOMETRY, decimate
from .forest import ROOT_RANK, MergeForest, ancestors, check_forest, forest_prefix, mesh_from_ancestors, simplified_mesh
from .levels import (MAX_LEVEL, MIN_LEVEL_POINTS, LevelMesh, Target, available_levels, build_levels, forest_merges, level_forest,
                     level_merges, level_payloads, next_level, read_simplified, resolve_target, storage_forests,
                     stored_levels, target_ancestors)

__all__ = ["decimate", "DEFAULT_W_DENSITY", "DEFAULT_W_GEOMETRY", "ROOT_RANK", "MergeForest", "ancestors",
           "check_forest", "simplified_mesh", "mesh_from_ancestors", "MAX_LEVEL", "MIN_LEVEL_POINTS",
           "LevelMesh", "available_levels", "build_levels", "level_forest", "level_merges", "next_level", "read_simplified",
           "forest_merges", "storage_forests", "level_payloads", "forest_prefix", "Target", "resolve_target",
           "stored_levels",
           "target_ancestors"]
