// tetc view: the page. Sends frame requests over a websocket, draws the frames that come back.
// While the user drags, every move asks for a frame within the budget (the server keeps only the
// newest); once they stop, after the still delay, a full-quality frame is asked for and blended in.
// window.tetcStats holds the last frame's stats for scripts and tests.
"use strict";

(function () {
  const token = window.TETC_TOKEN;
  const $ = (id) => document.getElementById(id);
  const view = $("view"), ctx = view.getContext("2d");
  const tfCanvas = $("tf-editor"), tfCtx = tfCanvas.getContext("2d");
  const DEFAULT_CAMERA = { azimuth: 0, elevation: 0, zoom: 1, pan_x: 0, pan_y: 0 };

  const state = {
    info: null,
    camera: { ...DEFAULT_CAMERA },
    color: [], // [{x in 0..1 of the range, rgb}]
    opacity: [], // [{x in 0..1 of the range, a}]
    unitDistance: 1,
    range: [0, 1],
    nextId: 1,
    sent: new Map(), // id -> send time (ms)
    shownId: 0, // id of the frame on screen (older frames are dropped)
    pending: null, // a frame header waiting for its image
    stillTimer: null,
    interacting: false,
    received: [], // receive times of the last second's frames (fps)
    frames: 0,
    step: 0, // the time step shown (series files)
    playing: false, // while playing, each frame that arrives asks for the next step
  };
  window.tetcStats = null;

  // -- the websocket -------------------------------------------------------------------------------
  let ws = null;
  function connect() {
    const proto = location.protocol === "https:" ? "wss" : "ws";
    ws = new WebSocket(`${proto}://${location.host}/ws?token=${encodeURIComponent(token)}`);
    ws.binaryType = "blob";
    // A quick frame within the budget first, then the full-quality one after the still delay.
    ws.onopen = () => { hideError(); send(false); scheduleStill(); };
    ws.onmessage = onMessage;
    ws.onclose = () => { showError("connection to the tetc server lost; retrying..."); setTimeout(connect, 1000); };
  }

  function cameraRequest() {
    const size = parseInt($("size").value, 10);
    return { width: size, height: size, ...state.camera };
  }

  function transferFunction() {
    const [lo, hi] = state.range, span = hi - lo;
    const sorted = (pts) => [...pts].sort((a, b) => a.x - b.x);
    return {
      absolute: true,
      unit_distance: state.unitDistance,
      color: sorted(state.color).map((p) => ({ x: lo + p.x * span, rgb: p.rgb })),
      opacity: sorted(state.opacity).map((p) => ({ x: lo + p.x * span, a: p.a })),
    };
  }

  function send(still) {
    if (!ws || ws.readyState !== WebSocket.OPEN) return;
    const id = state.nextId++;
    const msg = { type: "frame", id, still, camera: cameraRequest(), tf: transferFunction(),
                  budget: parseFloat($("budget").value) || 0.1, interacting: !still,
                  format: still ? "png" : $("format").value, step: state.step };
    state.sent.set(id, performance.now());
    ws.send(JSON.stringify(msg));
  }

  let framePending = false;
  function requestFrame(interacting) {
    // Coalesce the moves of one animation frame into one request.
    state.interacting = interacting;
    if (framePending) return;
    framePending = true;
    requestAnimationFrame(() => { framePending = false; send(false); });
  }

  function scheduleStill(delayS) {
    clearTimeout(state.stillTimer);
    const d = delayS !== undefined ? delayS : Math.max(parseFloat($("still-delay").value) || 0, 0);
    state.stillTimer = setTimeout(() => send(true), d * 1000);
  }

  function interact() { clearTimeout(state.stillTimer); requestFrame(true); }
  function endInteraction() { state.interacting = false; if (!state.playing) scheduleStill(); }

  async function onMessage(ev) {
    if (typeof ev.data === "string") {
      const msg = JSON.parse(ev.data);
      if (msg.type === "error") { showError(msg.message); if (state.playing) setPlaying(false); return; }
      state.pending = msg;
      return;
    }
    const head = state.pending;
    state.pending = null;
    if (!head) return;
    const now = performance.now();
    const sentAt = state.sent.get(head.id);
    for (const id of state.sent.keys()) if (id < head.id) state.sent.delete(id);
    if (head.id < state.shownId) return; // an older view than the one on screen: never snap back
    if (head.partial && state.finalId === head.id) return; // the full frame is already on screen
    const bitmap = await createImageBitmap(ev.data);
    if (head.partial) {
      // the still frame filling in: its finished pixels are opaque, the rest transparent, so the
      // preview underneath shows until the full-quality pixels arrive
      if (blendAnim) { cancelAnimationFrame(blendAnim); blendAnim = null; }
      ctx.globalAlpha = 1;
      ctx.drawImage(bitmap, 0, 0, view.width, view.height);
      // the last frame's figures stay; only the progress of the fill changes
      window.tetcStats = { ...(window.tetcStats || {}), partial: true, finished_share: head.stats.finished_share,
                           partial_s: head.stats.server_s };
      showStats(window.tetcStats);
      return;
    } else {
      draw(bitmap, head.final || head.preview);
    }
    if (head.final) state.finalId = head.id;
    state.shownId = head.id;
    hideError();
    state.frames += 1;
    state.received.push(now);
    while (state.received.length && state.received[0] < now - 1000) state.received.shift();
    const latency = sentAt !== undefined ? (now - sentAt) / 1000 : null;
    const s = head.stats;
    window.tetcStats = {
      ...s, id: head.id, final: !!head.final, preview: !!head.preview, partial: false,
      latency_s: latency, transfer_s: latency !== null ? Math.max(latency - s.server_s, 0) : null,
      fps: state.received.length, frames: state.frames,
      camera: { ...state.camera }, received_at: now,
    };
    showStats(window.tetcStats);
    if (state.playing && !head.final && !head.preview) nextStep();
  }

  // -- time steps: a slider and play/pause ------------------------------------------------------
  // Playing asks for the next step as soon as a frame arrives (never more than one in flight): each
  // frame is planned to the budget by the server, so the frame rate follows the budget.
  function stepLabel() {
    const steps = state.info.steps;
    $("step-label").textContent = `${state.step} / ${steps.n_steps - 1} · t = ${+steps.times[state.step].toPrecision(6)}`;
  }
  function showStep(k) {
    state.step = k;
    $("step").value = String(k);
    stepLabel();
  }
  function nextStep() {
    const n = state.info.steps.n_steps;
    if (state.step + 1 >= n && !$("loop").checked) { setPlaying(false); return; }
    showStep((state.step + 1) % n);
    send(false);
  }
  function setPlaying(on) {
    state.playing = on;
    $("play").textContent = on ? "pause" : "play";
    if (on) { clearTimeout(state.stillTimer); nextStep(); } else scheduleStill();
  }
  $("step").addEventListener("input", () => { showStep(parseInt($("step").value, 10)); interact(); });
  $("step").addEventListener("change", () => { if (!state.playing) endInteraction(); });
  $("play").addEventListener("click", () => setPlaying(!state.playing));

  // -- drawing, blending the still frame in ----------------------------------------------------
  let blendAnim = null;
  function draw(bitmap, blend) {
    if (blendAnim) { cancelAnimationFrame(blendAnim); blendAnim = null; }
    ctx.imageSmoothingEnabled = true;
    if (!blend) { ctx.globalAlpha = 1; ctx.drawImage(bitmap, 0, 0, view.width, view.height); return; }
    const before = document.createElement("canvas");
    before.width = view.width; before.height = view.height;
    before.getContext("2d").drawImage(view, 0, 0);
    const t0 = performance.now(), duration = 180;
    const step = () => {
      const f = Math.min((performance.now() - t0) / duration, 1);
      ctx.globalAlpha = 1; ctx.drawImage(before, 0, 0);
      ctx.globalAlpha = f; ctx.drawImage(bitmap, 0, 0, view.width, view.height);
      ctx.globalAlpha = 1;
      blendAnim = f < 1 ? requestAnimationFrame(step) : null;
    };
    step();
  }

  function fmtMs(s) { return s === null || s === undefined ? "–" : (1000 * s).toFixed(1) + " ms"; }
  function showStats(s) {
    const rows = [
      ["quality", s.partial ? `filling in ${Math.round(100 * (s.finished_share || 0))} %`
        : s.final ? "full" : s.preview ? "preview" : "interactive"],
      ["level / cut", `level ${s.level}, ${s.merges} merges (ratio ${s.ratio.toFixed(4)}), ${s.cut}`],
      ["tets rendered", s.tets_rendered.toLocaleString()],
      ["image", `${s.width}×${s.height}` + (s.step_factor !== 1 ? `, step ×${s.step_factor}` : "")],
      ["frames / s", s.fps],
      ["budget / predicted", `${s.budget_s === null ? "–" : fmtMs(s.budget_s)} / ${fmtMs(s.predicted_s)}`],
      ["decode", fmtMs(s.decode_s)], ["filter", fmtMs(s.filter_s)], ["render", fmtMs(s.render_s)],
      ["encode", fmtMs(s.encode_s)], ["server total", fmtMs(s.server_s)], ["transfer", fmtMs(s.transfer_s)],
      ["latency", fmtMs(s.latency_s)],
    ];
    $("stats").tBodies[0].innerHTML = rows.map(([k, v]) => `<tr><td>${k}</td><td>${v}</td></tr>`).join("");
  }

  function showError(text) { const e = $("error"); e.textContent = text; e.hidden = false; }
  function hideError() { $("error").hidden = true; }

  // -- camera interaction (VTK's trackball: azimuth / elevation about the focal point) ---------
  let drag = null;
  view.addEventListener("pointerdown", (ev) => {
    drag = { x: ev.clientX, y: ev.clientY, pan: ev.shiftKey };
    view.setPointerCapture(ev.pointerId);
    view.classList.add("dragging");
  });
  view.addEventListener("pointermove", (ev) => {
    if (!drag) return;
    const dx = ev.clientX - drag.x, dy = ev.clientY - drag.y;
    drag.x = ev.clientX; drag.y = ev.clientY;
    const c = state.camera;
    if (drag.pan || ev.shiftKey) {
      // pan in radii of the bounding sphere: the view's half-height at the focal point is 1/cos(15°) radii
      const k = 2 / (Math.cos(Math.PI / 12) * view.height * c.zoom);
      c.pan_x -= dx * k; c.pan_y += dy * k;
    } else {
      c.azimuth -= dx * 0.5;
      c.elevation = Math.max(-89.9, Math.min(89.9, c.elevation + dy * 0.5));
    }
    interact();
  });
  const release = (ev) => {
    if (!drag) return;
    drag = null;
    view.classList.remove("dragging");
    endInteraction();
  };
  view.addEventListener("pointerup", release);
  view.addEventListener("pointercancel", release);
  let wheelTimer = null;
  view.addEventListener("wheel", (ev) => {
    ev.preventDefault();
    const c = state.camera;
    c.zoom = Math.max(1e-3, Math.min(1e3, c.zoom * Math.exp(-ev.deltaY * 0.001)));
    interact();
    clearTimeout(wheelTimer);
    wheelTimer = setTimeout(endInteraction, 120);
  }, { passive: false });
  $("reset").addEventListener("click", () => { state.camera = { ...DEFAULT_CAMERA }; interact(); endInteraction(); });

  // -- the transfer-function editor --------------------------------------------------------------
  function colorAt(x) {
    const pts = [...state.color].sort((a, b) => a.x - b.x);
    if (!pts.length) return [1, 1, 1];
    if (x <= pts[0].x) return pts[0].rgb;
    for (let i = 1; i < pts.length; i++) {
      if (x <= pts[i].x) {
        const f = (x - pts[i - 1].x) / Math.max(pts[i].x - pts[i - 1].x, 1e-12);
        return pts[i].rgb.map((v, c) => pts[i - 1].rgb[c] + f * (v - pts[i - 1].rgb[c]));
      }
    }
    return pts[pts.length - 1].rgb;
  }

  const TF_BAR = 12;
  function drawEditor() {
    const w = tfCanvas.width, h = tfCanvas.height - TF_BAR;
    tfCtx.clearRect(0, 0, w, tfCanvas.height);
    const info = state.info;
    if (info) { // the histogram spans the file's scalar range; map it into the edited range
      const hist = info.histogram, [flo, fhi] = info.scalar_range, [lo, hi] = state.range;
      const maxLog = Math.log1p(Math.max(...hist, 1));
      tfCtx.fillStyle = "#3a3a3a";
      hist.forEach((c, i) => {
        const a = flo + (i / hist.length) * (fhi - flo), b = flo + ((i + 1) / hist.length) * (fhi - flo);
        const x0 = ((a - lo) / (hi - lo)) * w, x1 = ((b - lo) / (hi - lo)) * w;
        const bh = (Math.log1p(c) / maxLog) * h;
        tfCtx.fillRect(x0, h - bh, Math.max(x1 - x0, 1), bh);
      });
    }
    for (let i = 0; i < w; i++) {
      const [r, g, b] = colorAt(i / (w - 1));
      tfCtx.fillStyle = `rgb(${255 * r},${255 * g},${255 * b})`;
      tfCtx.fillRect(i, h, 1, TF_BAR);
    }
    const pts = [...state.opacity].sort((a, b) => a.x - b.x);
    tfCtx.strokeStyle = "#eee"; tfCtx.lineWidth = 1.5; tfCtx.beginPath();
    pts.forEach((p, i) => { const X = p.x * w, Y = (1 - p.a) * h; i ? tfCtx.lineTo(X, Y) : tfCtx.moveTo(X, Y); });
    tfCtx.stroke();
    pts.forEach((p) => {
      const [r, g, b] = colorAt(p.x);
      tfCtx.fillStyle = `rgb(${255 * r},${255 * g},${255 * b})`;
      tfCtx.beginPath(); tfCtx.arc(p.x * w, (1 - p.a) * h, 5, 0, 2 * Math.PI); tfCtx.fill(); tfCtx.stroke();
    });
  }

  function editorPoint(ev) {
    const r = tfCanvas.getBoundingClientRect();
    const h = tfCanvas.height - TF_BAR;
    const x = ((ev.clientX - r.left) / r.width), y = ((ev.clientY - r.top) / r.height) * tfCanvas.height;
    return { x: Math.min(Math.max(x, 0), 1), a: Math.min(Math.max(1 - y / h, 0), 1) };
  }
  function nearest(p) {
    const w = tfCanvas.width, h = tfCanvas.height - TF_BAR;
    let best = null, bestD = 8;
    state.opacity.forEach((q) => {
      const d = Math.hypot((q.x - p.x) * w, (q.a - p.a) * h);
      if (d < bestD) { best = q; bestD = d; }
    });
    return best;
  }
  let tfDrag = null;
  tfCanvas.addEventListener("pointerdown", (ev) => {
    const p = editorPoint(ev);
    tfDrag = nearest(p);
    if (!tfDrag) { tfDrag = p; state.opacity.push(p); }
    tfCanvas.setPointerCapture(ev.pointerId);
    drawEditor(); interact();
  });
  tfCanvas.addEventListener("pointermove", (ev) => {
    if (!tfDrag) return;
    const p = editorPoint(ev);
    tfDrag.x = p.x; tfDrag.a = p.a;
    drawEditor(); interact();
  });
  tfCanvas.addEventListener("pointerup", () => { if (tfDrag) { tfDrag = null; endInteraction(); } });
  tfCanvas.addEventListener("dblclick", (ev) => {
    const q = nearest(editorPoint(ev));
    if (q && state.opacity.length > 2) state.opacity.splice(state.opacity.indexOf(q), 1);
    drawEditor(); interact(); endInteraction();
  });

  function loadPreset(name) {
    const tf = state.info.presets[name];
    const [lo, hi] = state.info.scalar_range, span = hi - lo || 1;
    const norm = (x) => (tf.absolute ? (x - lo) / span : x);
    state.color = tf.color.map((p) => ({ x: norm(p.x), rgb: p.rgb }));
    state.opacity = tf.opacity.map((p) => ({ x: norm(p.x), a: p.a }));
    state.unitDistance = tf.unit_distance;
    state.range = [lo, hi];
    $("unit-distance").value = tf.unit_distance;
    $("range-lo").value = +lo.toPrecision(6); $("range-hi").value = +hi.toPrecision(6); // shown rounded, kept exact
    $("colormap").value = "";
  }

  function onTfControl() { drawEditor(); interact(); endInteraction(); }
  $("preset").addEventListener("change", () => { loadPreset($("preset").value); onTfControl(); });
  $("colormap").addEventListener("change", () => {
    const name = $("colormap").value;
    if (name) state.color = state.info.colormaps[name].map((p) => ({ x: p.x, rgb: p.rgb }));
    else loadPreset($("preset").value);
    onTfControl();
  });
  for (const id of ["range-lo", "range-hi"]) {
    $(id).addEventListener("change", () => {
      const lo = parseFloat($("range-lo").value), hi = parseFloat($("range-hi").value);
      if (Number.isFinite(lo) && Number.isFinite(hi) && hi > lo) { state.range = [lo, hi]; onTfControl(); }
      else showError("the range needs two numbers, the first below the second");
    });
  }
  $("unit-distance").addEventListener("change", () => {
    const u = parseFloat($("unit-distance").value);
    if (u > 0) { state.unitDistance = u; onTfControl(); } else showError("the unit distance must be positive");
  });
  for (const id of ["size", "budget", "still-delay", "format"]) {
    $(id).addEventListener("change", () => {
      const size = parseInt($("size").value, 10);
      view.width = size; view.height = size;
      interact(); endInteraction();
    });
  }

  // -- start -------------------------------------------------------------------------------------
  async function start() {
    const res = await fetch(`api/info?token=${encodeURIComponent(token)}`);
    const info = await res.json();
    if (!res.ok) { showError(info.error || `cannot load the file (${res.status})`); return; }
    state.info = info;
    $("title").textContent = `${info.file} · ${info.tets.toLocaleString()} tets · ${info.levels.length} levels`;
    $("budget").value = info.default_budget;
    const names = Object.keys(info.presets);
    $("preset").innerHTML = names.map((n) => `<option>${n}</option>`).join("");
    const initial = names.includes("default") ? "default" : names[0];
    $("preset").value = initial;
    $("colormap").innerHTML += Object.keys(info.colormaps).map((n) => `<option>${n}</option>`).join("");
    if (initial) loadPreset(initial);
    if (info.steps && info.steps.n_steps > 1) {
      $("steps").hidden = false;
      $("step").max = String(info.steps.n_steps - 1);
      showStep(0);
    }
    drawEditor();
    connect();
  }
  window.tetcViewer = { state, requestFrame: interact, endInteraction, transferFunction, setPlaying };
  start().catch((e) => showError(String(e)));
})();
