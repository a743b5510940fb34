"""`tetc view` of a time series: a frame of any step, without decoding the mesh again.

Oracles: a full-quality frame of step k is the image of `render_tetc` on that step's reader (what
`tetc render --time-step k` draws) with the session's scalar range; changing step decodes no
connectivity once the level is cached; the server answers a step, refuses a bad one with a 400 (or
a websocket error) and keeps serving. Real solver output: tests/data/series_heat.npz.
"""

import asyncio
import json
import sys
from pathlib import Path

import numpy as np
import pytest

aiohttp = pytest.importorskip("aiohttp", reason="the viewer's server needs aiohttp (pip install 'gatun_py[view]')")
from aiohttp.test_utils import TestClient, TestServer  # noqa: E402

from gatun_py.codec.stepreader import StepDecoder  # noqa: E402
from gatun_py.codec.tetcfile import TetcReader  # noqa: E402
from gatun_py.errors import OptionError  # noqa: E402
from gatun_py.mesh.validate import validate_tets  # noqa: E402
from gatun_py.pipeline.budget import Costs  # noqa: E402
from gatun_py.pipeline.series import write_series  # noqa: E402
from gatun_py.pipeline.stream import View, render_tetc  # noqa: E402
from gatun_py.raycast.camera import Camera  # noqa: E402
from gatun_py.raycast.image import to_rgb8  # noqa: E402
from gatun_py.raycast.transfer import load_transfer_function  # noqa: E402
from gatun_py.viewer import ViewerSession, parse_request  # noqa: E402
from gatun_py.viewer.server import SERVICE, make_app  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))
from series_data import load  # noqa: E402

DATA = Path(__file__).parent / "data"
TOKEN = "seriestoken1234567890"
N_STEPS = 10
CAM = {"width": 40, "height": 32, "azimuth": 25.0, "elevation": 15.0}


@pytest.fixture(scope="module", params=[False, True], ids=["static", "deforming"])
def series(request, tmp_path_factory):
    run = load(DATA / "series_heat.npz")
    meshes = [validate_tets(run["moved"][k] if request.param else run["points"], None, run["tets"],
                            scalar_name="temperature", point_data={"temperature": run["temperature"][k]})[0]
              for k in range(N_STEPS)]
    path = tmp_path_factory.mktemp("viewer_series") / "run.tetc"
    write_series(path, meshes, list(run["times"][:N_STEPS]), levels=2, keyframe_interval=4)
    return path, request.param


def _still(session, step, tf="default"):
    req = parse_request({"camera": CAM, "tf": tf, "budget": None, "format": "png", "step": step})
    return session.render(req)


def test_request_takes_a_step():
    assert parse_request({"step": 7}).time_step == 7
    assert parse_request({}).time_step == 0
    for bad in (1.5, "3", True, None):
        with pytest.raises(OptionError, match="'step'"):
            parse_request({"step": bad})


def test_a_step_renders_as_tetc_render_of_that_step(series):
    path, moving = series
    session = ViewerSession(path, costs=Costs())
    reader = StepDecoder(TetcReader(path)).reader(7)
    camera = Camera(CAM["width"], CAM["height"], CAM["azimuth"], CAM["elevation"])
    tf = load_transfer_function("default")
    # the session keeps step 0's range and framing, so that playing does not flicker
    view = View(camera, tf, scalar_range=tuple(session.scalar_range))
    frame = _still(session, 7)
    assert frame.stats["time_step"] == 7 and frame.stats["time"] == session.series.steps.times[7]
    if not moving:  # a moving mesh's own reader frames its own bounding box
        assert np.array_equal(frame.rgb8, to_rgb8(render_tetc(reader, view).image))
    assert np.abs(frame.rgb8.astype(int) - _still(session, 0).rgb8).max() > 10
    assert np.array_equal(_still(session, -3).rgb8, _still(session, N_STEPS - 3).rgb8)


def test_changing_step_decodes_no_mesh_and_the_cache_is_bounded(series, monkeypatch):
    path, _ = series
    session = ViewerSession(path, costs=Costs())
    reader = session.reader
    calls = []
    for name in ("_connectivity_decoder", "_geometry_decoder", "read_forest"):
        orig = getattr(reader, name)
        monkeypatch.setattr(reader, name, lambda *a, _o=orig, _n=name, **k: (calls.append(_n), _o(*a, **k))[1])
    for level in (0, 1):
        session.render(parse_request({"camera": CAM, "level": level, "format": "png", "step": 1}))
    before = list(calls)
    session.series.steps.cache_steps = 3
    for k in list(range(N_STEPS)) + [5, 2, 9]:
        for level in (0, 1):
            st = session.render(parse_request({"camera": CAM, "level": level, "format": "png", "step": k})).stats
            assert st["tets_decoded"] == 0 and st["time_step"] == k
    assert calls == before  # the mesh, the geometry and the forest were decoded for the first frames only
    cache = session.series.steps._cache
    assert 0 in cache and len(cache) <= 3 + 8  # the bound, plus the steps a prediction needs


def test_budget_frames_plan_around_the_step_decode(series):
    path, _ = series
    session = ViewerSession(path, costs=Costs())
    stats = [session.render(parse_request({"camera": CAM, "budget": 0.2, "step": k})).stats for k in range(N_STEPS)]
    assert all(s["step_decode_s"] > 0 for s in stats[1:])  # every step decoded once, in order
    assert any(s["step_predicted_s"] > 0 for s in stats[2:])  # and the model predicted it
    again = session.render(parse_request({"camera": CAM, "budget": 0.2, "step": N_STEPS - 1})).stats
    assert again["step_decode_s"] < stats[-1]["step_decode_s"] and again["step_predicted_s"] == 0
    assert ViewerSession.series_budget(0.1, 0.5) == pytest.approx(0.02)
    assert ViewerSession.series_budget(0.1, 0.03) == pytest.approx(0.07)


def _serve(path, coro):
    async def main():
        app = make_app(ViewerSession(path, costs=Costs()), TOKEN)
        async with TestClient(TestServer(app, host="127.0.0.1")) as client:
            return await coro(client, app)

    return asyncio.run(main())


def test_server_answers_a_step_refuses_a_bad_one_and_keeps_serving(series):
    path, _ = series

    async def check(client, app):
        url = f"/api/frame?token={TOKEN}"
        info = await (await client.get(f"/api/info?token={TOKEN}")).json()
        assert info["steps"]["n_steps"] == N_STEPS and len(info["steps"]["times"]) == N_STEPS
        body = {"camera": CAM, "budget": None, "format": "png"}
        r = await client.post("/api/frame?token=wrong", data=json.dumps({**body, "step": 3}))
        assert r.status == 403 and app[SERVICE].frames == 0
        r = await client.post(url, data=json.dumps({**body, "step": 3}))
        assert r.status == 200
        st = json.loads(r.headers["X-Tetc-Stats"])
        assert st["time_step"] == 3 and st["time"] == info["steps"]["times"][3]
        for bad, what in ((N_STEPS, "does not exist"), (-N_STEPS - 1, "does not exist"), ("2", "'step'"),
                          (2.5, "'step'")):
            r = await client.post(url, data=json.dumps({**body, "step": bad}))
            assert r.status == 400 and what in (await r.json())["error"], bad
        r = await client.post(url, data=json.dumps({**body, "step": N_STEPS - 1}))
        assert r.status == 200 and json.loads(r.headers["X-Tetc-Stats"])["time_step"] == N_STEPS - 1
        ws = await client.ws_connect(f"/ws?token={TOKEN}")
        await ws.send_str(json.dumps({"type": "frame", "id": 1, "camera": CAM, "step": 99}))
        msg = json.loads((await ws.receive(timeout=60)).data)
        assert msg["type"] == "error" and msg["id"] == 1 and "step 99 does not exist" in msg["message"]
        await ws.send_str(json.dumps({"type": "frame", "id": 2, "camera": CAM, "step": 4, "budget": 0.5}))
        msg = json.loads((await ws.receive(timeout=60)).data)
        assert msg["type"] == "frame" and msg["id"] == 2 and msg["stats"]["time_step"] == 4
        assert (await ws.receive(timeout=60)).type == aiohttp.WSMsgType.BINARY
        await ws.close()

    _serve(path, check)
