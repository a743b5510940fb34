"""The viewer's local web server (aiohttp): the page, its websocket and a scriptable frame service.

Routes (every one needs ``?token=...`` or an ``Authorization: token ...`` header, else 403):

``GET /``                the page (``static/index.html``)
``GET /static/{name}``   its script and style sheet
``GET /api/info``        the file: levels, scalar range and histogram, presets, colormaps (JSON)
``POST /api/frame``      body: a frame request (JSON, :func:`gatun_py.viewer.session.parse_request`);
                         answer: the image (``Content-Type`` image/jpeg, png or webp) with its stats
                         as JSON in the ``X-Tetc-Stats`` header; 400 with ``{"error": ...}`` for a
                         malformed request, 500 when the file vanished or is corrupt
``GET /ws``              websocket: the page sends ``{"type": "frame", "id": n, "still": bool, ...request}``;
                         the server answers ``{"type": "frame", "id", "final", "mime", "stats"}`` followed
                         by one binary message with the image, or ``{"type": "error", "id", "message"}``

One render runs at a time, whoever asks (a single worker thread behind a lock); each websocket
keeps only its newest request, so a client that sends faster than frames come back never queues
old views. A still request (``"still": true``) is rendered at full quality as a PNG (lossless: it equals
``tetc render`` of the same view), preceded by a quick
preview when the full frame is predicted to take long and by JPEG images of it filling in while it
streams (``"partial": true``, at most four a second), and abandoned between batches as soon as a
newer request of the same client arrives; a drag frame is abandoned likewise when a still request
follows it (its image would be replaced at once).
"""

from __future__ import annotations

import asyncio
import hmac
import json
import secrets
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from importlib import resources

from aiohttp import WSMsgType, web

from ..errors import OptionError, TetcError
from .session import FrameCancelled, ViewerSession, parse_request

STATIC_FILES = {"viewer.js": "text/javascript", "viewer.css": "text/css"}
PREVIEW_ABOVE_S = 1.5  # a still frame predicted to take longer than this gets a quick preview first
PREVIEW_SHARE = 0.08  # the preview's budget, as a share of the full frame's predicted time


def new_token() -> str:
    return secrets.token_hex(24)


class FrameService:
    """Renders the frames of one :class:`ViewerSession`, one at a time, off the event loop."""

    def __init__(self, session: ViewerSession):
        self.session = session
        self.executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="tetc-render")
        self.lock = asyncio.Lock()
        self.frames = 0

    async def render(self, req, cancelled=None, partial=None):
        """Render ``req`` on the render thread; ``partial`` (a coroutine function taking ``data, mime,
        stats``) is scheduled on the event loop for every image of the frame filling in."""
        async with self.lock:
            loop = asyncio.get_running_loop()
            on_partial = None
            if partial is not None:
                def on_partial(data, mime, stats):
                    asyncio.run_coroutine_threadsafe(partial(data, mime, stats), loop)
            frame = await loop.run_in_executor(
                self.executor, lambda: self.session.render(req, cancelled=cancelled, partial=on_partial))
            self.frames += 1
            return frame

    async def predict_full(self, req) -> float:
        """Predicted seconds of the full-quality frame of ``req`` (on the render thread: it reads the
        model that renders update)."""
        return await asyncio.get_running_loop().run_in_executor(self.executor, lambda: self._predict_full(req))

    def _predict_full(self, req) -> float:
        s = self.session
        planner = s.planner(req.mode)
        fitted = req.camera.fit(s.bbox_lo, s.bbox_hi)
        lv = planner.levels[0]
        return planner.model.predict(planner.estimate(lv.level, lv.merges, fitted.width * fitted.height,
                                                      planner.estimator.coverage(fitted)), key=lv.level)

    def close(self):
        self.executor.shutdown(wait=False, cancel_futures=True)


SERVICE = web.AppKey("service", FrameService)  # the app's FrameService, for tests and scripts


def _error(status: int, message: str) -> web.Response:
    return web.json_response({"error": message}, status=status)


def _token_ok(request: web.Request, token: str) -> bool:
    given = request.query.get("token", "")
    auth = request.headers.get("Authorization", "")
    if not given and auth.lower().startswith("token "):
        given = auth[6:].strip()
    return hmac.compare_digest(given.encode(), token.encode())


def make_app(session: ViewerSession, token: str) -> web.Application:
    """The aiohttp application serving ``session`` to whoever holds ``token``."""
    service = FrameService(session)

    @web.middleware
    async def require_token(request, handler):
        if not _token_ok(request, token):
            return _error(403, "invalid or missing token: open the URL that `tetc view` printed")
        return await handler(request)

    async def index(request):
        html = resources.files(__package__).joinpath("static/index.html").read_text()
        return web.Response(text=html.replace("{{TOKEN}}", token), content_type="text/html",
                            headers={"Cache-Control": "no-store"})

    async def static(request):
        name = request.match_info["name"]
        if name not in STATIC_FILES:
            raise web.HTTPNotFound()
        text = resources.files(__package__).joinpath(f"static/{name}").read_text()
        return web.Response(text=text, content_type=STATIC_FILES[name])

    async def info(request):
        try:
            session.check_file()
            return web.json_response(session.info())
        except TetcError as e:
            return _error(500, str(e))

    async def frame(request):
        try:
            body = await request.json()
        except (ValueError, UnicodeDecodeError):
            return _error(400, "the body must be a JSON frame request")
        try:
            req = parse_request(body)
            f = await service.render(req)
        except OptionError as e:
            return _error(400, str(e))
        except TetcError as e:
            return _error(500, str(e))
        return web.Response(body=f.data, content_type=f.mime, headers={"X-Tetc-Stats": json.dumps(f.stats)})

    async def websocket(request):
        ws = web.WebSocketResponse(heartbeat=30, max_msg_size=1 << 20)
        await ws.prepare(request)
        client = _Client(ws, service)
        worker = asyncio.create_task(client.run())
        try:
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    await client.receive(msg.data)
                elif msg.type == WSMsgType.ERROR:
                    break
        finally:
            worker.cancel()
        return ws

    app = web.Application(middlewares=[require_token], client_max_size=1 << 20)
    app.router.add_get("/", index)
    app.router.add_get("/static/{name}", static)
    app.router.add_get("/api/info", info)
    app.router.add_post("/api/frame", frame)
    app.router.add_get("/ws", websocket)
    app[SERVICE] = service

    async def shutdown(app):
        service.close()

    app.on_cleanup.append(shutdown)
    return app


class _Client:
    """One websocket: keeps only the newest request and renders it when the service is free."""

    def __init__(self, ws, service: FrameService):
        self.ws = ws
        self.service = service
        self.latest = None  # (id, request, still)
        self.wake = asyncio.Event()
        self.send_lock = asyncio.Lock()

    async def send(self, header: dict, data: bytes | None = None):
        async with self.send_lock:  # a header and its image go out together
            if self.ws.closed:
                return
            await self.ws.send_str(json.dumps(header))
            if data is not None:
                await self.ws.send_bytes(data)

    async def receive(self, text: str):
        try:
            obj = json.loads(text)
            if not isinstance(obj, dict):
                raise ValueError
        except ValueError:
            await self.send({"type": "error", "id": None, "message": "messages must be JSON objects"})
            return
        rid = obj.get("id")
        if obj.get("type", "frame") != "frame":
            await self.send({"type": "error", "id": rid, "message": f"unknown message type {obj.get('type')!r}"})
            return
        try:
            still = bool(obj.get("still", False))
            req = parse_request({**{k: v for k, v in obj.items() if k not in ("type", "id", "still")},
                                 **({"budget": None, "format": "png"} if still else {})})
        except OptionError as e:
            await self.send({"type": "error", "id": rid, "message": str(e)})
            return
        self.latest = (rid, req, still)  # replaces any older request not started yet: stale views are dropped
        self.wake.set()

    def superseded(self) -> bool:
        return self.latest is not None

    def still_waiting(self) -> bool:
        """A still request arrived: the drag frame being drawn would be replaced at once."""
        return self.latest is not None and self.latest[2]

    async def run(self):
        while True:
            await self.wake.wait()
            self.wake.clear()
            job, self.latest = self.latest, None
            if job is None:
                continue
            rid, req, still = job
            try:
                if still:
                    await self._still(rid, req)
                else:
                    f = await self.service.render(req, cancelled=self.still_waiting)
                    await self.send({"type": "frame", "id": rid, "final": False, "mime": f.mime, "stats": f.stats},
                                    f.data)
            except FrameCancelled:
                continue
            except (OptionError, TetcError) as e:
                await self.send({"type": "error", "id": rid, "message": str(e)})
            except Exception as e:  # the server keeps serving whatever one frame did
                print(f"tetc view: frame {rid} failed: {type(e).__name__}: {e}", file=sys.stderr)
                await self.send({"type": "error", "id": rid, "message": f"internal error: {type(e).__name__}: {e}"})

    async def _still(self, rid, req):
        """Progressive refinement at rest: a quick preview if the full frame is slow, then full quality."""
        t0 = time.perf_counter()
        full_s = await self.service.predict_full(req)
        if full_s > PREVIEW_ABOVE_S:
            preview = replace(req, budget_s=max(PREVIEW_SHARE * full_s, 0.05), fmt="jpeg")
            f = await self.service.render(preview, cancelled=self.superseded)
            await self.send({"type": "frame", "id": rid, "final": False, "preview": True, "mime": f.mime,
                             "stats": f.stats}, f.data)
            if self.superseded():
                return
        async def show_partial(data, mime, stats):
            if not self.superseded():
                await self.send({"type": "frame", "id": rid, "final": False, "partial": True, "mime": mime,
                                 "stats": stats}, data)

        f = await self.service.render(req, cancelled=self.superseded, partial=show_partial)
        f.stats["still_s"] = time.perf_counter() - t0
        await self.send({"type": "frame", "id": rid, "final": True, "mime": f.mime, "stats": f.stats}, f.data)


def serve(session: ViewerSession, *, host: str = "127.0.0.1", port: int = 0, token: str | None = None,
          on_ready=None) -> None:
    """Run the server until interrupted; ``on_ready(url)`` is called once it listens."""
    token = token or new_token()
    app = make_app(session, token)

    async def main():
        runner = web.AppRunner(app, access_log=None)
        await runner.setup()
        site = web.TCPSite(runner, host, port)
        await site.start()
        bound = runner.addresses[0][1]
        shown = f"[{host}]" if ":" in host else host
        if on_ready is not None:
            on_ready(f"http://{shown}:{bound}/?token={token}")
        try:
            await asyncio.Event().wait()
        finally:
            await runner.cleanup()

    try:
        asyncio.run(main())
    except KeyboardInterrupt:
        pass


__all__ = ["make_app", "serve", "new_token", "FrameService"]
