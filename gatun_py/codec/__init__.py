"""Stage 2 (storage): lossless cut-border compression, the streaming decoder, the ``.tetc`` container.

Public API: :func:`write_tetc` / :func:`encode_tetc` (levels of :class:`LevelPayload`),
:class:`TetcReader` (``.meta``, ``.levels``, ``.read_section``, ``.iter_decode``, ``.decode_mesh``),
:func:`iter_decode`, :func:`decode_mesh` and :class:`DecodeBatch`.
"""

from .tetcfile import DecodeBatch, LevelPayload, TetcReader, decode_mesh, encode_tetc, iter_decode, write_tetc

__all__ = ["DecodeBatch", "LevelPayload", "TetcReader", "decode_mesh", "encode_tetc", "iter_decode", "write_tetc"]
