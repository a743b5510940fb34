"""``tetc``: compress, simplify and volume-render tetrahedral meshes.

Exit codes: 0 success, 1 error (one line on stderr), 2 usage error. Every command parses its
options, calls one verb of :mod:`gatun_py.api` and prints.
"""

from __future__ import annotations

import sys

import click

from gatun_py import __version__
from gatun_py.errors import OutputExistsError, TetcError

from .codec_commands import append, compress, convert, decompress, info
from .compare import compare_command
from .isosurface_commands import isosurface
from .paraview_commands import paraview_plugin
from .render_commands import render
from .view_commands import view
from .warmup_command import warmup


class TetcGroup(click.Group):
    """A click group that turns library errors into one line and exit code 1."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except OutputExistsError as e:
            click.echo(f"tetc: error: {e} (add --force to overwrite it)", err=True)
            ctx.exit(1)
        except TetcError as e:
            click.echo(f"tetc: error: {e}", err=True)
            ctx.exit(1)
        except MemoryError:
            click.echo("tetc: error: out of memory", err=True)
            ctx.exit(1)
        except KeyboardInterrupt:
            click.echo("tetc: interrupted", err=True)
            ctx.exit(130)


@click.group(cls=TetcGroup, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="tetc")
def tetc():
    """Compress tetrahedral volume meshes losslessly, simplify them on the fly and volume-render
    them in one streaming pass.

    \b
    Typical use:
      tetc compress mesh.vtu -o mesh.tetc        lossless, with pre-simplified levels
      tetc render mesh.tetc -o image.png         streaming decode + render
      tetc render mesh.tetc -o f.png --budget 0.1   fit a frame-time budget
      tetc info mesh.tetc --json                 sizes, levels, bits per tet
      tetc warmup                                compile the kernels once, after installing
    """


for _command in (info, convert, compress, decompress, append, render, isosurface, view, compare_command,
                 paraview_plugin, warmup):
    tetc.add_command(_command)


class _UnbreakableStream:
    """A text stream whose writes never raise: once the reader of a pipe has gone (``tetc compress
    ... 2>&1 | head -1``) progress and notes are dropped, and the work goes on to its output."""

    def __init__(self, stream):
        self._stream = stream
        self._broken = stream is None

    def write(self, text):
        if not self._broken:
            try:
                return self._stream.write(text)
            except (OSError, ValueError):  # EPIPE, or a closed file
                self._broken = True
        return len(text)

    def flush(self):
        if not self._broken:
            try:
                self._stream.flush()
            except (OSError, ValueError):
                self._broken = True

    def isatty(self):
        return not self._broken and self._stream.isatty()

    def __getattr__(self, name):
        return getattr(self._stream, name)


def main(argv=None):
    sys.stdout = _UnbreakableStream(sys.stdout)
    sys.stderr = _UnbreakableStream(sys.stderr)
    return tetc.main(args=argv, prog_name="tetc")


if __name__ == "__main__":
    sys.exit(main())
