"""``tetc paraview-plugin``."""

from __future__ import annotations

import sys

import click

from gatun_py.paraview import plugin_path


@click.command("paraview-plugin")
def paraview_plugin():
    """Print the path of the ParaView reader plugin for .tetc files (one line).

    Load it in ParaView with Tools > Manage Plugins > Load New, or LoadPlugin(path, ns=globals())
    in pvbatch. The plugin decodes with this Python (recorded beside the plugin where the install
    is writable; otherwise set TETC_PYTHON to it, or put `tetc` on ParaView's PATH), so gatun_py
    need not be importable in ParaView's own Python.
    """
    click.echo(str(plugin_path(record_python=sys.executable)))
