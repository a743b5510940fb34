"""The request records (View, Detail, ReadOptions, ForestOptions): checked once, used by the verbs,
the command line and the viewer; and the shape they keep the verbs in."""

from __future__ import annotations

import dataclasses
import inspect

import click
import pytest

import gatun_py
from gatun_py import api
from gatun_py.errors import OptionError
from gatun_py.pipeline.requests import Cluster, Detail, ForestOptions, ReadOptions, View, split_options

# records: a verb's keyword that takes one counts as one grouped argument, not as its fields
GROUPED = {"view", "detail", "read", "forest", "cluster"}
MAX_LOOSE = 12
RENDER_MAX_LINES = 60


def _verbs():
    names = set(gatun_py.__all__) | set(api.__all__)
    for name in sorted(names):
        obj = getattr(gatun_py, name, None) or getattr(api, name)
        fn = getattr(obj, "_target", obj)
        if callable(fn) and not inspect.isclass(fn):
            yield name, fn


def _commands():
    from gatun_py.cli.main import tetc

    def walk(group, prefix=""):
        for name, cmd in group.commands.items():
            if isinstance(cmd, click.Group):
                yield from walk(cmd, prefix + name + " ")
            else:
                yield prefix + name, cmd
    yield from walk(tetc)


def _loose_keywords(fn, positional=()) -> list[str]:
    return [p.name for p in inspect.signature(fn).parameters.values()
            if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD) and p.name not in GROUPED
            and p.name not in positional and p.default is not inspect.Parameter.empty]


@pytest.mark.parametrize("name, fn", list(_verbs()), ids=lambda x: x if isinstance(x, str) else "")
def test_no_verb_takes_more_than_twelve_loose_keywords(name, fn):
    loose = _loose_keywords(fn)
    assert len(loose) <= MAX_LOOSE, (name, loose)


@pytest.mark.parametrize("name, cmd", list(_commands()), ids=lambda x: x if isinstance(x, str) else "")
def test_no_command_takes_more_than_twelve_loose_options(name, cmd):
    arguments = {p.name for p in cmd.params if isinstance(p, click.Argument)}
    loose = [p for p in inspect.signature(cmd.callback).parameters if p not in GROUPED and p not in arguments]
    assert len(loose) <= MAX_LOOSE, (name, loose)


def test_render_is_a_few_dozen_lines():
    lines, _ = inspect.getsourcelines(api.render)
    assert len(lines) <= RENDER_MAX_LINES, len(lines)


def test_one_frame_and_one_encoder():
    from gatun_py.viewer import session

    assert api.Frame is gatun_py.Frame is session.Frame
    assert not hasattr(session, "encode_image")


# -- the records' checks -----------------------------------------------------------------------------

@pytest.mark.parametrize("make, message", [
    (lambda: View(size=0), "image size"),
    (lambda: View(size=(10, 10**6)), "image size"),
    (lambda: View(zoom=0), "zoom"),
    (lambda: View(azimuth=float("inf")), "azimuth"),
    (lambda: View(step=-1), "step"),
    (lambda: View(mode="x-ray"), "mode"),
    (lambda: View(scalar_range=(2, 1)), "MIN must be below MAX"),
    (lambda: View(background="nope"), "colour"),
    (lambda: View(tf="no-such-preset"), "no-such-preset"),
    (lambda: Detail(ratio=1.5), "ratio"),
    (lambda: Detail(budget=0), "budget"),
    (lambda: Detail(ratio=0.5, level=1), "at most one"),
    (lambda: Detail(tets=5), "selective"),
    (lambda: Detail(tets=0, selective=True), "tets"),
    (lambda: Detail(selective=True, level=1), "stored level"),
    (lambda: ReadOptions(time_step=1.5), "time_step"),
    (lambda: ForestOptions(levels=-1), "levels"),
    (lambda: ForestOptions(w_sample=float("nan")), "w_sample"),
    (lambda: Cluster(workers=2, scheduler="tcp://h:1"), "either"),
    (lambda: Cluster(workers=0), "workers"),
])
def test_records_refuse_with_one_message(make, message):
    with pytest.raises(OptionError, match=message):
        make()


def test_records_are_frozen_and_normalised():
    v = View(size=64, background="white", scalar_range=(0, 1), tf="post")
    assert v.size == (64, 64) and v.background == (1.0, 1.0, 1.0) and v.scalar_range == (0.0, 1.0)
    assert v.tf.__class__.__name__ == "TransferFunction"
    with pytest.raises(dataclasses.FrozenInstanceError):
        v.zoom = 2.0
    # replacing a field checks again, and keeps the loaded transfer function
    assert v.replace(azimuth=30).tf is v.tf
    with pytest.raises(OptionError):
        v.replace(zoom=-1)


def test_shorthand_changes_the_record_given():
    base = View(size=32, azimuth=10)
    v, d, r = split_options("render", {"azimuth": 30, "ratio": 0.5, "scalar": "rho"}, view=base, detail=None, read=None)
    assert (v.size, v.azimuth, d.ratio, r.scalar) == ((32, 32), 30.0, 0.5, "rho")
    with pytest.raises(TypeError, match="unexpected keyword argument 'colour'"):
        split_options("render", {"colour": "red"}, view=None)
    with pytest.raises(OptionError, match="View"):
        split_options("render", {}, view=Detail())


def test_render_with_records_equals_the_shorthand():
    from gatun_py.warmup import tiny_mesh

    mesh = tiny_mesh()
    a = gatun_py.render(mesh, view=View(size=(24, 20), azimuth=30, elevation=10, tf="post"))
    b = gatun_py.render(mesh, size=(24, 20), azimuth=30, elevation=10, tf="post")
    assert (a.rgb == b.rgb).all() and (a.image == b.image).all()


def test_cli_names_its_options_in_the_records_refusals(tmp_path):
    from click.testing import CliRunner

    from gatun_py.cli.main import tetc

    mesh = tmp_path / "m.vtu"
    gatun_py.write_mesh(__import__("gatun_py.warmup", fromlist=["tiny_mesh"]).tiny_mesh(), mesh)
    res = CliRunner().invoke(tetc, ["render", str(mesh), "-o", str(tmp_path / "x.png"), "--ratio", "0.5",
                                    "--level", "1"])
    assert res.exit_code == 2 and "--ratio" in res.output and "--level" in res.output, res.output
    res = CliRunner().invoke(tetc, ["render", str(mesh), "-o", str(tmp_path / "x.png"), "--tf", "no-such-preset"])
    assert res.exit_code == 1 and "no-such-preset" in res.output, res.output
