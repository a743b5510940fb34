"""`tetc compare` and the quality measures against a plain computation."""

import json

import numpy as np
import pytest
from click.testing import CliRunner
from skimage import io

from gatun_py.cli.compare import compare_script
from gatun_py.cli.main import tetc
from gatun_py.errors import OptionError
from gatun_py.pipeline.quality import compare_images


def _pair(seed=0, shape=(32, 40, 3)):
    rng = np.random.default_rng(seed)
    a = np.zeros(shape, np.uint8)
    a[5:25, 8:30] = rng.integers(0, 256, (20, 22, 3))
    b = a.copy()
    b[10:12, 10:20] = rng.integers(0, 256, (2, 10, 3))
    b[0, 0] = 7  # a pixel only b has: counted
    return a, b


def test_rmse_over_non_black_pixels():
    a, b = _pair()
    d = compare_images(a, b)
    mask = (a.max(2) > 0) | (b.max(2) > 0)
    diff = a[mask].astype(float) - b[mask].astype(float)
    assert d.pixels == int(mask.sum())
    assert d.rmse == pytest.approx(np.sqrt((diff ** 2).mean()))
    assert d.psnr == pytest.approx(20 * np.log10(255 / d.rmse))
    assert 0 < d.ssim < 1


def test_identical_and_black():
    a, _ = _pair()
    d = compare_images(a, a)
    assert d.rmse == 0 and d.psnr == float("inf") and d.ssim == pytest.approx(1.0)
    z = np.zeros((16, 16, 3), np.uint8)
    assert compare_images(z, z).pixels == 0


def test_size_mismatch():
    with pytest.raises(OptionError, match="differ in size"):
        compare_images(np.zeros((8, 8, 3), np.uint8), np.zeros((8, 9, 3), np.uint8))


def test_cli_and_script(tmp_path):
    a, b = _pair(1)
    io.imsave(tmp_path / "a.png", a, check_contrast=False)
    io.imsave(tmp_path / "b.png", b, check_contrast=False)
    for cmd, args in ((tetc, ["compare"]), (compare_script, [])):
        res = CliRunner().invoke(cmd, args + [str(tmp_path / "a.png"), str(tmp_path / "b.png"), "--json"])
        assert res.exit_code == 0, res.output
        out = json.loads(res.output)
        assert set(out) == {"rmse", "psnr", "ssim", "pixels"}
        assert out["rmse"] == pytest.approx(compare_images(a, b).rmse)
    io.imsave(tmp_path / "c.png", np.zeros((5, 5, 3), np.uint8), check_contrast=False)
    res = CliRunner().invoke(tetc, ["compare", str(tmp_path / "a.png"), str(tmp_path / "c.png")])
    assert res.exit_code == 1 and "differ in size" in res.output
    (tmp_path / "bad.png").write_bytes(b"nope")
    res = CliRunner().invoke(compare_script, [str(tmp_path / "a.png"), str(tmp_path / "bad.png")])
    assert res.exit_code == 1 and "cannot read image" in res.output
    res = CliRunner().invoke(tetc, ["compare", str(tmp_path / "a.png"), str(tmp_path / "none.png")])
    assert res.exit_code == 1 and "no such file" in res.output
