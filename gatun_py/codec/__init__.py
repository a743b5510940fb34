"""Stage 2 (storage): lossless cut-border compression, the streaming decoder, the ``.tetc`` container.

Public API: :func:`write_tetc` / :func:`encode_tetc` (levels of :class:`LevelPayload`),
:class:`TetcReader` (``.meta``, ``.levels`` as :class:`LevelMeta` records, ``.read_section``, ``.read_forest``, ``.iter_decode``,
``.decode_mesh``), :func:`iter_decode` and :func:`decode_mesh`; the forest's bytes in :mod:`.forest`.
Streams are of :class:`gatun_py.mesh.TetBatch`.
"""

from .levelmeta import LevelMeta
from .tetcfile import LevelPayload, TetcReader, decode_mesh, encode_tetc, iter_decode, write_tetc

__all__ = ["LevelMeta", "LevelPayload", "TetcReader", "decode_mesh", "encode_tetc", "iter_decode", "write_tetc"]
