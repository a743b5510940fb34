"""``tetc compare A.png B.png`` and the stand-alone ``tetc-compare`` script: RMSE (0-255) over the
pixels where either image has a ray contribution, PSNR and SSIM."""

from __future__ import annotations

import math
import sys

import click

from gatun_py.errors import TetcError

from .options import echo_json, json_option


def _compare(a, b, as_json):
    from gatun_py.pipeline.quality import compare_files  # start-up time of every other command

    d = compare_files(a, b)
    if as_json:
        out = d.as_dict()
        out["psnr"] = out["psnr"] if math.isfinite(out["psnr"]) else None  # JSON has no infinity
        echo_json(out)
    else:
        click.echo(f"rmse {d.rmse:.4f}  psnr {d.psnr:.2f} dB  ssim {d.ssim:.4f}  pixels {d.pixels}")


@click.command("compare")
@click.argument("a", type=click.Path(dir_okay=False))
@click.argument("b", type=click.Path(dir_okay=False))
@json_option
def compare_command(a, b, as_json):
    """Image difference between renders A and B: RMSE on a 0-255 scale over the pixels where either
    image is not black (the paper's measure), PSNR from that RMSE, and SSIM over the whole image.
    With --json: keys rmse, psnr (null when identical), ssim, pixels."""
    _compare(a, b, as_json)


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("a", type=click.Path(dir_okay=False))
@click.argument("b", type=click.Path(dir_okay=False))
@json_option
def compare_script(a, b, as_json):
    """RMSE (0-255, non-black pixels), PSNR and SSIM between two images."""
    try:
        _compare(a, b, as_json)
    except TetcError as e:
        click.echo(f"tetc-compare: error: {e}", err=True)
        sys.exit(1)


def main(argv=None):
    return compare_script.main(args=argv, prog_name="tetc-compare")


if __name__ == "__main__":
    sys.exit(main())
