"""``tetc view``: interactive exploration of a ``.tetc`` file in the browser.

* :mod:`gatun_py.viewer.session`  frame requests -> planned, rendered, encoded frames (no web code);
* :mod:`gatun_py.viewer.server`   the local web server: the page, its websocket, ``POST /api/frame``
  (needs aiohttp, part of the core install);
* ``static/``                     the page (HTML, script, style), package data.

A script can drive the frame service without a browser; see :mod:`gatun_py.viewer.server` for the
routes and :func:`gatun_py.viewer.session.parse_request` for the request.
"""

from ..errors import OptionError
from .session import Frame, FrameRequest, ViewerSession, parse_request

WEB_EXTRA_MESSAGE = ("tetc view needs the web server package aiohttp, which this install lacks: "
                     "pip install aiohttp (or pip install 'gatun_py[view]'; in a checkout: pip install '.[view]')")


def require_web():
    """Import the server module, or raise OptionError saying how to install what it needs."""
    try:  # optional dependency: only the viewer's server needs aiohttp
        from . import server
    except ImportError as e:
        if getattr(e, "name", "") and not str(e.name).startswith("aiohttp"):
            raise
        raise OptionError(WEB_EXTRA_MESSAGE) from None
    return server


__all__ = ["ViewerSession", "FrameRequest", "Frame", "parse_request", "require_web"]
