"""`tetc view` without a browser: the frame session, the server's routes and the command.

Oracles: a still frame is byte-for-byte the image of `render_tetc` (what `tetc render` writes) of
the same view and transfer function; a cached level renders exactly as a freshly decoded one.
The server is driven in-process (aiohttp's test server on a free loopback port).
"""

import asyncio
import io
import json
import shutil

import numpy as np
import pytest

aiohttp = pytest.importorskip("aiohttp", reason="the viewer's server needs aiohttp (pip install 'gatun_py[view]')")
from aiohttp.test_utils import TestClient, TestServer  # noqa: E402
from click.testing import CliRunner  # noqa: E402
from PIL import Image  # noqa: E402

from gatun_py.cli.main import tetc  # noqa: E402
from gatun_py.errors import OptionError, TetcError  # noqa: E402
from gatun_py.pipeline.budget import Costs  # noqa: E402
from gatun_py.pipeline.stream import View, render_tetc  # noqa: E402
from gatun_py.raycast.camera import Camera  # noqa: E402
from gatun_py.raycast.image import to_rgb8  # noqa: E402
from gatun_py.raycast.transfer import load_transfer_function  # noqa: E402
from gatun_py.viewer import ViewerSession, parse_request  # noqa: E402
from gatun_py.viewer.server import SERVICE, make_app  # noqa: E402

TOKEN = "testtoken1234567890"


@pytest.fixture
def own_copy(post_tetc, tmp_path):
    """A copy the test may delete or damage."""
    p = tmp_path / "mine.tetc"
    shutil.copy(post_tetc, p)
    return p


def _decode(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


def _reference(path, cam: dict, tf="post") -> np.ndarray:
    camera = Camera(cam["width"], cam["height"], cam.get("azimuth", 0.0), cam.get("elevation", 0.0),
                    cam.get("zoom", 1.0), pan_x=cam.get("pan_x", 0.0), pan_y=cam.get("pan_y", 0.0))
    return to_rgb8(render_tetc(path, View(camera, load_transfer_function(tf))).image)


CAM = {"width": 48, "height": 40, "azimuth": 30.0, "elevation": 20.0, "zoom": 1.2}


# -- requests ------------------------------------------------------------------------------------

def test_request_defaults_and_round_trip():
    r = parse_request({})
    assert (r.camera.width, r.camera.height, r.budget_s, r.fmt, r.mode) == (512, 512, 0.1, "jpeg", "volume")
    r = parse_request({"camera": CAM, "tf": "post", "budget": None, "format": "png"})
    assert r.budget_s is None and r.camera.zoom == 1.2 and r.fmt == "png"


@pytest.mark.parametrize("bad, key", [
    ([], "JSON object"), ({"camera": 3}, "camera"), ({"camera": {"width": 0}}, "width"),
    ({"camera": {"width": 10.5}}, "width"), ({"camera": {"azimuth": "x"}}, "azimuth"),
    ({"camera": {"zoom": float("nan")}}, "zoom"), ({"camera": {"pan_x": True}}, "pan_x"),
    ({"budget": -1}, "budget"), ({"budget": "fast"}, "budget"), ({"format": "gif"}, "format"),
    ({"mode": "iso"}, "mode"), ({"level": -2}, "level"), ({"tf": 7}, "tf"),
    ({"tf": {"color": "nope"}}, "color"), ({"quality": 0}, "quality"),
])
def test_malformed_requests_name_the_key(bad, key):
    with pytest.raises(OptionError, match=key):
        parse_request(bad)


def test_transfer_function_strings_are_presets_never_paths(tmp_path):
    tf = tmp_path / "x.json"
    tf.write_text(json.dumps({"color": [{"x": 0, "rgb": [1, 1, 1]}], "opacity": [{"x": 0, "a": 1}]}))
    with pytest.raises(OptionError, match="preset"):
        parse_request({"tf": str(tf)})
    with pytest.raises(OptionError, match="preset"):
        parse_request({"tf": "/etc/passwd"})


# -- the session -----------------------------------------------------------------------------------

def test_still_frame_equals_render_tetc(post_tetc):
    s = ViewerSession(post_tetc, costs=Costs())
    for cam in (CAM, {**CAM, "pan_x": 0.2, "pan_y": -0.1}):
        f = s.render(parse_request({"camera": cam, "tf": "post", "budget": None, "format": "png"}))
        ref = _reference(post_tetc, cam)
        assert np.array_equal(f.rgb8, ref) and np.array_equal(_decode(f.data), ref)
        assert f.stats["full_quality"] and f.stats["level"] == 0 and f.stats["merges"] == 0


def test_pan_moves_the_image(post_tetc):
    a = _reference(post_tetc, CAM)
    b = _reference(post_tetc, {**CAM, "pan_x": 0.3})
    assert not np.array_equal(a, b)
    # Panning right moves the focal point right: the mesh moves left on screen.
    cols = lambda img: np.flatnonzero(img.max(axis=(0, 2)) > 0)  # noqa: E731
    assert cols(b).mean() < cols(a).mean()


def test_cached_levels_render_as_decoded_ones(post_tetc):
    s = ViewerSession(post_tetc, costs=Costs())
    req = parse_request({"camera": CAM, "tf": "post", "level": 2, "format": "png"})
    first = s.render(req)
    assert s.reader.is_decoded(2) and first.stats["tets_decoded"] > 0
    again = s.render(req)
    assert again.stats["tets_decoded"] == 0  # served from memory
    assert np.array_equal(first.rgb8, again.rgb8)
    ref = to_rgb8(render_tetc(post_tetc, View(Camera(48, 40, 30, 20, 1.2), load_transfer_function("post")),
                              level=2).image)
    assert np.array_equal(again.rgb8, ref)


def test_budget_frames_report_every_stage_and_learn(post_tetc):
    s = ViewerSession(post_tetc, costs=Costs())
    stats = [s.render(parse_request({"camera": {**CAM, "azimuth": 30.0 + i}, "tf": "post", "budget": 0.05})).stats
             for i in range(3)]
    for st in stats:
        for key in ("decode_s", "filter_s", "render_s", "encode_s", "server_s", "predicted_s", "level", "merges",
                    "tets_rendered", "scale", "step_factor"):
            assert key in st
        assert st["width"] == round(48 * st["scale"]) and st["format"] == "jpeg"
    assert s.model.frames == 3


def test_a_vanished_or_corrupt_file_raises_and_recovers(own_copy, tmp_path):
    s = ViewerSession(own_copy, costs=Costs())
    req = parse_request({"camera": CAM, "tf": "post", "budget": None, "format": "png"})
    good = s.render(req)
    backup = tmp_path / "backup.tetc"
    shutil.move(own_copy, backup)
    with pytest.raises(TetcError, match="gone"):
        s.render(req)
    own_copy.write_bytes(b"not a tetc file at all")
    for _ in range(2):  # and it stays an error: never the old image
        with pytest.raises(TetcError):
            s.render(req)
    shutil.copy(backup, own_copy)
    assert np.array_equal(s.render(req).rgb8, good.rgb8)


# -- the server ------------------------------------------------------------------------------------

def _serve(path, coro, **session_attrs):
    """Run ``coro(client, app)`` against an in-process server of ``path``."""

    async def main():
        session = ViewerSession(path, costs=Costs())
        for k, v in session_attrs.items():
            setattr(session, k, v)
        app = make_app(session, TOKEN)
        async with TestClient(TestServer(app, host="127.0.0.1")) as client:
            return await coro(client, app)

    return asyncio.run(main())


def test_every_route_needs_the_token(post_tetc):
    async def check(client, app):
        for method, url in [("GET", "/"), ("GET", "/static/viewer.js"), ("GET", "/api/info"),
                            ("POST", "/api/frame"), ("GET", "/ws")]:
            for q in ("", "?token=wrong", f"?token={TOKEN[:-1]}"):
                r = await client.request(method, url + q, data=json.dumps({"camera": CAM}))
                assert r.status == 403, (method, url, q)
                assert "token" in (await r.json())["error"]
        assert app[SERVICE].frames == 0  # nothing rendered
        r = await client.get(f"/?token={TOKEN}")
        assert r.status == 200 and TOKEN in await r.text()
        r = await client.get("/api/info", headers={"Authorization": f"token {TOKEN}"})
        assert r.status == 200 and (await r.json())["tets"] > 0
        r = await client.get(f"/static/viewer.js?token={TOKEN}")
        assert r.status == 200 and "tetcStats" in await r.text()
        assert (await client.get(f"/static/../server.py?token={TOKEN}")).status == 404

    _serve(post_tetc, check)


def test_frame_service_answers_and_survives_bad_requests(post_tetc):
    async def check(client, app):
        url = f"/api/frame?token={TOKEN}"
        for body in ("not json", "[1, 2]", json.dumps({"camera": {"width": -1}}), json.dumps({"tf": "../x"})):
            r = await client.post(url, data=body)
            assert r.status == 400 and (await r.json())["error"]
        r = await client.post(url, data=json.dumps({"camera": CAM, "tf": "post", "budget": None, "format": "png"}))
        assert r.status == 200 and r.headers["Content-Type"] == "image/png"
        stats = json.loads(r.headers["X-Tetc-Stats"])
        assert stats["full_quality"] and stats["tets_rendered"] > 0
        assert np.array_equal(_decode(await r.read()), _reference(post_tetc, CAM))
        r = await client.post(url, data=json.dumps({"camera": CAM, "tf": "post", "budget": 0.1}))
        assert r.status == 200 and r.headers["Content-Type"] == "image/jpeg"

    _serve(post_tetc, check)


def test_vanished_file_is_an_error_not_a_crash(own_copy, tmp_path):
    async def check(client, app):
        url = f"/api/frame?token={TOKEN}"
        body = json.dumps({"camera": CAM, "tf": "post", "budget": None, "format": "png"})
        shutil.move(own_copy, tmp_path / "away.tetc")
        r = await client.post(url, data=body)
        assert r.status == 500 and "gone" in (await r.json())["error"]
        ws = await client.ws_connect(f"/ws?token={TOKEN}")
        await ws.send_str(json.dumps({"type": "frame", "id": 1, **json.loads(body)}))
        msg = json.loads((await ws.receive(timeout=60)).data)
        assert msg["type"] == "error" and "gone" in msg["message"]
        shutil.move(tmp_path / "away.tetc", own_copy)
        r = await client.post(url, data=body)
        assert r.status == 200
        await ws.close()

    _serve(own_copy, check)


async def _frames(ws, n_final=1, timeout=120):
    """Receive (header, image) pairs until ``n_final`` frames (neither preview nor partial) arrived."""
    out, header = [], None
    while sum(1 for h, _ in out if not (h.get("preview") or h.get("partial"))) < n_final:
        msg = await ws.receive(timeout=timeout)
        if msg.type == aiohttp.WSMsgType.TEXT:
            header = json.loads(msg.data)
            assert header["type"] == "frame", header
        else:
            out.append((header, msg.data))
    return out


def test_websocket_keeps_only_the_newest_request(post_tetc):
    async def check(client, app):
        ws = await client.ws_connect(f"/ws?token={TOKEN}")
        await ws.send_str("{broken")
        assert json.loads((await ws.receive(timeout=30)).data)["type"] == "error"
        await ws.send_str(json.dumps({"type": "frame", "id": 0, "camera": {"width": 0}}))
        err = json.loads((await ws.receive(timeout=30)).data)
        assert err["type"] == "error" and err["id"] == 0 and "width" in err["message"]
        n = 12
        for i in range(1, n + 1):  # a burst, faster than frames render
            await ws.send_str(json.dumps({"type": "frame", "id": i, "interacting": True, "tf": "post",
                                          "camera": {**CAM, "azimuth": 30.0 + i}, "budget": 0.05}))
        got = []
        while not got or got[-1][0]["id"] != n:
            got += await _frames(ws)
        ids = [h["id"] for h, _ in got]
        assert ids == sorted(ids) and len(ids) < n  # stale views were dropped, none out of order
        assert app[SERVICE].frames == len(ids)
        # At rest: the still request gives the full-quality PNG, equal to tetc render's image.
        await ws.send_str(json.dumps({"type": "frame", "id": n + 1, "still": True, "tf": "post", "camera": CAM}))
        (head, data), = [f for f in await _frames(ws) if not (f[0].get("preview") or f[0].get("partial"))]
        assert head["final"] and head["mime"] == "image/png"
        assert np.array_equal(_decode(data), _reference(post_tetc, CAM))
        await ws.close()

    _serve(post_tetc, check)


def test_a_still_frame_fills_in_before_it_is_final(post_tetc):
    """While the still frame streams, images of it filling in arrive first: opaque exactly where
    the pixel is final (and then equal to the final image), transparent elsewhere."""
    async def check(client, app):
        ws = await client.ws_connect(f"/ws?token={TOKEN}")
        cam = {**CAM, "width": 64, "height": 48}
        await ws.send_str(json.dumps({"type": "frame", "id": 1, "still": True, "tf": "post", "camera": cam}))
        got = await _frames(ws)
        partials = [(h, d) for h, d in got if h.get("partial")]
        assert partials and not partials[-1][0]["final"] and got[-1][0]["final"]
        final = _decode(got[-1][1])
        assert np.array_equal(final, _reference(post_tetc, cam))
        for head, data in partials:
            rgba = np.asarray(Image.open(io.BytesIO(data)).convert("RGBA"))
            done = rgba[..., 3] == 255
            assert set(np.unique(rgba[..., 3])) <= {0, 255}
            assert abs(done.mean() - head["stats"]["finished_share"]) < 1e-9
            # lossy WebP: the finished pixels are the final ones up to the codec's error
            assert np.abs(rgba[..., :3][done].astype(int) - final[done]).mean() < 6
        await ws.close()

    _serve(post_tetc, check, partial_every_s=0.0)


def test_two_clients_are_both_served(post_tetc):
    async def check(client, app):
        a = await client.ws_connect(f"/ws?token={TOKEN}")
        b = await client.ws_connect(f"/ws?token={TOKEN}")
        for ws, az in ((a, 10.0), (b, 50.0)):
            await ws.send_str(json.dumps({"type": "frame", "id": 7, "tf": "post", "budget": None, "format": "png",
                                          "camera": {**CAM, "azimuth": az}}))
        (ha, da), = await _frames(a)
        (hb, db), = await _frames(b)
        assert np.array_equal(_decode(da), _reference(post_tetc, {**CAM, "azimuth": 10.0}))
        assert np.array_equal(_decode(db), _reference(post_tetc, {**CAM, "azimuth": 50.0}))
        await a.close()
        await b.close()

    _serve(post_tetc, check)


# -- the command -------------------------------------------------------------------------------------

@pytest.fixture
def fake_serve(monkeypatch):
    """Replace the blocking server loop: record its arguments and print the URL as it would."""
    calls = []

    def serve(session, *, host, port, token, on_ready):
        calls.append({"session": session, "host": host, "port": port, "token": token})
        on_ready(f"http://{host}:{port or 12345}/?token={token or 'generated'}")

    monkeypatch.setattr("gatun_py.viewer.server.serve", serve)
    return calls


def test_view_command_defaults_to_loopback(post_tetc, fake_serve):
    r = CliRunner().invoke(tetc, ["view", str(post_tetc), "--no-browser", "-q"])
    assert r.exit_code == 0, r.output
    assert fake_serve[0]["host"] == "127.0.0.1" and fake_serve[0]["token"] is None
    assert "http://127.0.0.1:" in r.output and "warning" not in r.output


def test_view_command_warns_when_opened_up(post_tetc, fake_serve):
    r = CliRunner().invoke(tetc, ["view", str(post_tetc), "--no-browser", "--host", "0.0.0.0", "-q"])
    assert r.exit_code == 0 and "warning: listening on 0.0.0.0" in r.output


@pytest.mark.parametrize("args, message", [
    (["view", "sample_meshes/lox_post_tets/post.vtk", "--no-browser"], "needs a .tetc file"),
    (["view", "missing.tetc", "--no-browser"], "no such file"),
])
def test_view_command_bad_input(args, message, fake_serve):
    r = CliRunner().invoke(tetc, args)
    assert r.exit_code == 1 and message in r.output and not fake_serve


def test_view_command_rejects_a_weak_token(post_tetc, fake_serve):
    r = CliRunner().invoke(tetc, ["view", str(post_tetc), "--token", "abc"])
    assert r.exit_code == 1 and "--token" in r.output and not fake_serve


def test_missing_web_package_is_a_clear_error(monkeypatch):
    import sys

    from gatun_py import viewer

    monkeypatch.setitem(sys.modules, "aiohttp", None)
    monkeypatch.delitem(sys.modules, "gatun_py.viewer.server", raising=False)
    monkeypatch.delattr(viewer, "server", raising=False)
    with pytest.raises(OptionError, match=r"pip install 'gatun_py\[view\]'"):
        viewer.require_web()


def test_view_command_on_a_damaged_file_fails_before_it_is_ready(own_copy, fake_serve):
    """A byte flipped inside a section: one line, exit 1, and the server never starts (no "ready")."""
    data = bytearray(own_copy.read_bytes())
    data[len(data) // 2] ^= 0xFF
    own_copy.write_bytes(bytes(data))
    r = CliRunner().invoke(tetc, ["view", str(own_copy), "--no-browser"])
    assert r.exit_code == 1 and not fake_serve, r.output
    assert "ready" not in r.output and "checksum mismatch" in r.output
    assert [ln for ln in r.output.splitlines() if ln.startswith("tetc: error:")] == [
        ln for ln in r.output.splitlines() if "error" in ln]
