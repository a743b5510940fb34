"""``tetc view``: explore a .tetc file interactively in the browser (served locally)."""

from __future__ import annotations

import ipaddress
import time

import click

from gatun_py.errors import OptionError, TetcError

from .options import quiet_option, require_file, status

LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")


def _is_loopback(host: str) -> bool:
    if host in LOCAL_HOSTS:
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@click.command("view")
@click.argument("input", type=click.Path(dir_okay=False))
@click.option("--port", type=click.IntRange(0, 65535), default=0, show_default=True,
              help="TCP port to listen on (0: any free port).")
@click.option("--host", default="127.0.0.1", show_default=True,
              help="Address to listen on. Anything but the loopback lets other machines reach the viewer "
                   "(they still need the URL's token).")
@click.option("--no-browser", is_flag=True, help="Print the URL but do not open a browser.")
@click.option("--token", default=None, metavar="TEXT",
              help="Access token of the URL [default: a new random one]; scripts may fix it.")
@quiet_option
def view(input, port, host, no_browser, token, quiet):
    """Open INPUT (a .tetc file) in the browser: drag to rotate, shift-drag to pan, wheel to zoom.

    While you drag, every frame is planned to fit the frame budget (0.1 s by default) by choosing a
    pre-simplified level and simplifying on the fly; once you stop, the full-quality image follows
    after the still delay. The page has a transfer-function editor and shows the level in use, the
    tets rendered, frames per second and where each frame's time went.

    The server listens on 127.0.0.1 unless --host says otherwise, and the page, its websocket and
    its frame requests need the random token in the printed URL. Scripts can ask for frames
    without a browser:
    POST /api/frame?token=... with a JSON request (camera, tf, budget) returns the image and its
    stats (header X-Tetc-Stats); see the module gatun_py.viewer.server.
    """
    from gatun_py._runtime import announce, is_tetc

    if token is not None and (len(token) < 8 or not token.isalnum()):
        raise OptionError("--token must be at least 8 letters or digits")
    require_file(input)
    if not is_tetc(input):
        raise OptionError(f"{input}: tetc view needs a .tetc file (make one with: tetc compress {input} -o FILE.tetc)")
    # the kernels are loaded (or compiled) before the file is checked: say so first, before the
    # viewer's imports load numba
    compiling = announce(["decoder", "forest decoder", "filter", "renderer"], quiet=quiet)
    from gatun_py.viewer import ViewerSession, require_web

    server = require_web()
    if not _is_loopback(host):
        status(f"warning: listening on {host}: other machines that can reach it may connect (with the token); "
               "use the default 127.0.0.1 unless you mean it", False)
    from gatun_py.pipeline.budget import load_costs, machine_costs
    from gatun_py._runtime import load_render_kernels

    t0 = time.perf_counter()
    if not compiling:
        status("loading the decoder and renderer...", quiet)
    load_render_kernels()
    if load_costs() is None:
        status("measuring this machine's rendering costs (once, under a second)...", quiet)
    costs, _ = machine_costs()
    session = ViewerSession(input, costs=costs)

    def ready(url):
        status(f"ready in {time.perf_counter() - t0:.1f} s; press Ctrl-C to stop", quiet)
        click.echo(url)
        if not no_browser:
            import webbrowser  # here, not at the top: only needed when a browser is opened

            webbrowser.open(url)

    try:
        server.serve(session, host=host, port=port, token=token, on_ready=ready)
    except OSError as e:
        raise TetcError(f"cannot listen on {host}:{port}: {e.strerror or e}") from None
