"""Frozen codings of earlier format versions: what files of those versions hold, decoded exactly as
they were written (``tests/data/post_v*.tetc``). Nothing here writes today's files;
:mod:`gatun_py.codec.formats` says which format version uses which coding, ``docs/format.md`` has
the history. A module is imported only when a file of its version is read, so that today's
format never compiles these kernels.
"""
