"""``tetc warmup``: compile every kernel once, ahead of the first real run."""

from __future__ import annotations

import click

from .options import logger, quiet_option, status


@click.command("warmup")
@quiet_option
def warmup(quiet):
    """Compile tetc's numba kernels for this machine into numba's cache, once per install.

    Without it, the first run of each command compiles what it needs (and says so): up to two
    minutes for a first compress. Run it after installing (make install does); it takes a minute
    or two on two cores, and seconds once the kernels are cached. The cache lives beside the
    installed package (or in NUMBA_CACHE_DIR when that is set: set it the same way for the
    commands).
    """
    from gatun_py.warmup import warm_up

    seconds = warm_up(log=logger(quiet))
    status(f"kernels compiled and cached in {seconds:.0f} s", quiet)
