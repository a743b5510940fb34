"""Typed errors raised by the library.

Every failure a user can cause (bad input file, corrupt ``.tetc``, impossible option) raises a
subclass of :class:`TetcError`, which is also a ``ValueError`` (bad values, damaged data) or an
``OSError`` (files that cannot be read or written), so generic handlers catch them too. The
command-line front end turns these into one line on stderr and
exit code 1; anything else is a bug.
"""


class TetcError(Exception):
    """Base class of every error the library raises on purpose."""


class ReadError(TetcError, OSError):
    """An input file is missing, unreadable, or not in a format we understand."""


class MeshError(TetcError, ValueError):
    """A mesh violates a validity rule (NaNs, bad ids, non-conforming faces, ...)."""


class CorruptFileError(TetcError, ValueError):
    """A ``.tetc`` file is truncated, damaged, or otherwise inconsistent."""


class FormatVersionError(CorruptFileError):
    """A ``.tetc`` file was written by a newer, unknown format version."""


class OptionError(TetcError, ValueError):
    """An option value is impossible for this input (ratio out of range, unknown level, ...)."""


class OutputError(TetcError, OSError):
    """An output file cannot be written (unwritable directory, unknown format, ...)."""


class OutputExistsError(OutputError):
    """The output file exists and overwriting was not asked for (``force=True``)."""
