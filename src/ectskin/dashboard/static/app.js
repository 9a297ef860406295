// ectskin live dashboard. Plain JS, no dependencies (the page must work offline).
// Messages on /ws: one "meta", one "history", then "status" (the engine running, ended, failed:
// again whenever it changes) and "frame"s (see ectskin/dashboard/app.py). A frame's "contact"
// (the contact model's reading) and "ect" (the ECT image, quantised, and its peak) are drawn in
// the Contact panel, shown when the meta says the engine has either head or the physical
// inversion, whose "inversion" (the fitted fingers and their standard errors) inversion.js draws.
(function () {
  "use strict";

  const WINDOW_S = 10;            // strip chart: seconds shown
  const CHART_COLS = 7;           // strip chart: small multiples per row
  const GAP_MS = 500;             // strip chart: a longer pause in the stream breaks the line
  const TICK_S = 5;               // strip chart: a time label every 5 s (seconds before now)
  const GRID_S = 2.5;             // strip chart: a grid line every 2.5 s
  // Each pair's vertical scale spans at least this much, so that readout noise (~1 fF) is drawn
  // as the flicker it is, not stretched to full height: 20 fF raw, 2 % calibrated.
  const MIN_SPAN_RAW_PF = 0.02;
  const MIN_SPAN_CALIBRATED = 0.02;
  const STALE_MS = 2000;          // badge: no frame for this long while running = "stale"
  const SURFACE_ORDER = ["front", "back", "right", "left"];
  const SVG_NS = "http://www.w3.org/2000/svg";
  const FINGER_SLOTS = 2;         // contact: fingers drawn at most (the model's slots)
  const FORCE_FULL_N = 2;         // contact: a force bar's full width, N (grows past it)
  const DOT_MM = 2.2;             // contact: finger dot radius on the face drawing, mm
  const HOVER_AT = 0.5;           // contact: "hovering" at p_hover >= this without contact
  const HEAT_DECAY_S = 5;         // ECT: the colour scale follows the largest value, decaying
                                  // with this time constant (rest noise stays faint after a touch)

  const state = {
    meta: null,
    frames: [],                   // [{w, raw, calibrated}] for the chart, oldest first
                                  // (w: page clock, ms; a source's t may restart per trial)
    mode: "raw",
    chartDirty: true,
    lastFrame: null,
    lastFrameWall: 0,
    frameCount: 0,                // frames received by this page
    ref: { state: "unknown", requestedAt: 0, sawNotReady: false, requests: 0 },
    views: {},                    // marker views by svg id
    refKey: null,                 // identity of the reference pose the views were scaled for
    ws: null,
    wsOpen: false,
    retryMs: 500,
    engine: "waiting",            // the engine's state from "status" messages
    chartSpans: [],               // per pair, the vertical span drawn last (tests read it)
    chartBoundaries: [],          // trial names whose boundary is drawn in the window
    trial: null,
    contact: null,                // the last contact reading drawn
    ect: null,                    // the last ECT frame drawn: {seq, face, u_mm, v_mm, scale, drawn}
  };

  const $ = (id) => document.getElementById(id);
  function svgEl(tag, attrs, parent) {
    const el = document.createElementNS(SVG_NS, tag);
    for (const k in attrs) el.setAttribute(k, attrs[k]);
    if (parent) parent.appendChild(el);
    return el;
  }
  const isNum = (v) => typeof v === "number" && isFinite(v);
  function fmt(v, digits) { return isNum(v) ? v.toFixed(digits) : "—"; }
  function setText(id, text) { const el = $(id); if (el.textContent !== text) el.textContent = text; }

  // ------------------------------------------------------------------ connection
  function connect() {
    const proto = location.protocol === "https:" ? "wss" : "ws";
    const ws = new WebSocket(proto + "://" + location.host + "/ws");
    state.ws = ws;
    setConnection("connecting", "connecting…");
    ws.onopen = () => { state.retryMs = 500; state.wsOpen = true; updateBadge(); };
    ws.onmessage = (ev) => {
      let msg;
      try { msg = JSON.parse(ev.data); } catch (e) { console.error("bad message", e); return; }
      if (msg.type === "meta") onMeta(msg);
      else if (msg.type === "history") onHistory(msg);
      else if (msg.type === "status") onStatus(msg);
      else if (msg.type === "frame") onFrame(msg);
    };
    ws.onclose = () => {
      state.wsOpen = false;
      updateBadge();
      setTimeout(connect, state.retryMs);
      state.retryMs = Math.min(state.retryMs * 2, 5000);
    };
  }
  function onStatus(msg) {
    state.engine = msg.engine || "waiting";
    const errEl = $("engine-error");
    errEl.hidden = !msg.error;
    errEl.textContent = msg.error ? "engine: " + msg.error : "";
    updateBadge();
  }
  // The badge says "live" only while the engine runs and frames keep coming: [data-state, text]
  // from the websocket being open, the engine's state and the age of the last frame (ms, null
  // before the first).
  function badge(wsOpen, engine, ageMs) {
    if (!wsOpen) {
      return engine === "ended" ? ["ended", "ended (server gone)"]
                                : ["closed", "disconnected, retrying…"];
    }
    if (engine === "ended") return ["ended", "ended: the source stopped; last frame shown"];
    if (engine === "error") return ["error", "stopped by an error"];
    if (ageMs !== null && ageMs > STALE_MS) {
      return ["stale", "stale: no frame for " + (ageMs / 1000).toFixed(0) + " s"];
    }
    if (ageMs === null) return ["waiting", "waiting for frames"];
    return ["open", "live"];
  }
  function updateBadge() {
    const age = state.lastFrameWall ? performance.now() - state.lastFrameWall : null;
    const [st, text] = badge(state.wsOpen, state.engine, age);
    setConnection(st, text);
  }
  function setConnection(s, text) {
    const el = $("connection-status");
    el.dataset.state = s;
    el.textContent = text;
  }

  // ------------------------------------------------------------------ meta: build the drawings
  function onMeta(meta) {
    state.meta = meta;
    state.frames = [];
    state.refKey = null;
    setText("layout-name", meta.layout_name || "");
    buildFaces(meta);
    buildProbs(meta);
    for (const id of ["markers-yz", "markers-xz"]) buildView(id, meta);
    buildMarkerBars(meta);
    buildContact(meta);
    resizeChart();
  }

  function surfacesOf(meta) {
    const present = new Set();
    meta.skins.forEach((s) => present.add(s.surface));
    meta.regions.forEach((r) => present.add(r.surface));
    return SURFACE_ORDER.filter((s) => present.has(s));
  }

  function buildFaces(meta) {
    const host = $("faces");
    host.innerHTML = "";
    const skinSurface = {};
    meta.skins.forEach((s) => { skinSurface[s.name] = s.surface; });
    for (const surface of surfacesOf(meta)) {
      const rects = meta.skins.filter((s) => s.surface === surface)
        .concat(meta.regions.filter((r) => r.surface === surface));
      let u0 = Infinity, u1 = -Infinity, v0 = Infinity, v1 = -Infinity;
      for (const r of rects) {
        u0 = Math.min(u0, r.u_mm[0]); u1 = Math.max(u1, r.u_mm[1]);
        v0 = Math.min(v0, r.v_mm[0]); v1 = Math.max(v1, r.v_mm[1]);
      }
      const m = 3;
      const div = document.createElement("div");
      div.className = "face";
      div.dataset.surface = surface;
      // Surface coordinates (u, v) in mm; v (towards the tip) points up: SVG y = -v.
      const svg = svgEl("svg", {
        id: "face-" + surface, class: "face-svg",
        viewBox: [u0 - m, -(v1 + m), u1 - u0 + 2 * m, v1 - v0 + 2 * m].join(" "),
      }, div);
      for (const s of meta.skins.filter((s) => s.surface === surface)) {
        svgEl("rect", {
          class: "skin", "data-skin": s.name, x: s.u_mm[0], y: -s.v_mm[1],
          width: s.u_mm[1] - s.u_mm[0], height: s.v_mm[1] - s.v_mm[0], rx: 1.5,
        }, svg);
      }
      // Regions under the wires (a lit region shows which wires cover it), labels on top.
      const regions = meta.regions.filter((r) => r.surface === surface);
      for (const r of regions) {
        svgEl("rect", {
          class: "region", "data-region": r.id, "data-surface": r.surface,
          x: r.u_mm[0], y: -r.v_mm[1], width: r.u_mm[1] - r.u_mm[0], height: r.v_mm[1] - r.v_mm[0],
        }, svg);
      }
      for (const e of meta.electrodes.filter((e) => e.surface === surface)) {
        const g = svgEl("g", { class: "electrode", "data-electrode": e.name }, svg);
        const pc = e.pad.centre_mm, ps = e.pad.size_mm;
        svgEl("rect", { class: "pad", x: pc[0] - ps[0] / 2, y: -(pc[1] + ps[1] / 2),
          width: ps[0], height: ps[1], rx: 0.6 }, g);
        svgEl("polyline", {
          class: "wire", "stroke-width": e.width_mm,
          points: e.polyline_mm.map((p) => p[0] + "," + (-p[1])).join(" "),
        }, g);
        const tip = e.polyline_mm[e.polyline_mm.length - 1];
        const lab = svgEl("text", { class: "electrode-label", x: tip[0], y: -(tip[1] + 1.5) }, g);
        lab.textContent = e.name;
      }
      for (const r of regions) {
        const t = svgEl("text", { class: "region-label", "data-region-label": r.id,
          x: (r.u_mm[0] + r.u_mm[1]) / 2, y: -(r.v_mm[0] + r.v_mm[1]) / 2 }, svg);
        t.textContent = r.id;
      }
      const title = document.createElement("div");
      title.className = "title";
      title.textContent = surface + (surface === "back" ? " (x to the right, as the front)" : "");
      div.appendChild(title);
      host.appendChild(div);
    }
  }

  function className(meta, k) {
    if (k === 0) return "0 none";
    const r = meta.regions.find((r) => r.id === k);
    return r ? k + " " + r.surface : String(k);
  }

  function buildProbs(meta) {
    const host = $("probs");
    host.innerHTML = "";
    for (let k = 0; k < meta.n_classes; k++) {
      const row = document.createElement("div");
      row.className = "prob-row";
      row.dataset.class = k;
      row.innerHTML = '<span class="name"></span><span class="track"><span class="bar"></span></span>' +
        '<span class="p">0.00</span>';
      row.querySelector(".name").textContent = className(meta, k);
      host.appendChild(row);
    }
  }

  // ------------------------------------------------------------------ frames
  function onHistory(msg) {
    const now = performance.now();
    for (const f of msg.frames || []) pushChart(f, now - 1000 * (f.age_s || 0));
    state.chartDirty = true;
  }

  // The trial being played and its inflation (replay, sim); nothing when the source does not say.
  function updateTrial(f) {
    const parts = [];
    if (typeof f.trial === "string") parts.push("trial " + f.trial);
    if (Array.isArray(f.inflation)) {
      const infl = f.inflation.map((v) => (isNum(v) ? +v.toFixed(1) : "?"));
      const inflated = f.inflation.some((v) => isNum(v) && v !== 0);
      parts.push((inflated ? "inflated " : "uninflated ") + infl.join("/") + " ml");
    }
    const el = $("trial-info");
    el.dataset.trial = typeof f.trial === "string" ? f.trial : "";
    setText("trial-info", parts.join(" · "));
  }

  function onFrame(f) {
    state.lastFrame = f;
    state.lastFrameWall = performance.now();
    state.frameCount += 1;
    document.body.dataset.framesReceived = state.frameCount;
    pushChart(f, state.lastFrameWall);
    state.chartDirty = true;
    if (f.stats) updateStats(f.stats);
    setText("frame-seq", String(f.seq));
    updateTrial(f);
    updateTouch(f.touch, f.label);
    updateMarkers(f.markers);
    updateContact(f.contact);
    if (f.ect) updateEct(f.ect, f.seq);
    window.ectskinInversion.update(f);
    updateBadge();
  }

  function pushChart(f, wallMs) {
    if (!Array.isArray(f.raw)) return;
    const fr = state.frames;
    fr.push({ w: wallMs, raw: f.raw, calibrated: f.calibrated,
              trial: typeof f.trial === "string" ? f.trial : null });
    const cutoff = wallMs - 1000 * WINDOW_S;
    let drop = 0;
    while (drop < fr.length && fr[drop].w < cutoff) drop++;
    if (drop) fr.splice(0, drop);
  }

  function updateStats(s) {
    setText("frames-count", String(s.frames ?? "—"));
    setText("processed-count", String(s.processed ?? "—"));
    setText("dropped-count", String(s.dropped ?? "—"));
    setText("malformed-count", String(s.malformed ?? "—"));
    setText("reconnects-count", String(s.reconnects ?? "—"));
    $("dropped-count").classList.toggle("warn", s.dropped > 0);
    $("malformed-count").classList.toggle("warn", s.malformed > 0);
    setText("latency-p50", fmt(s.latency_ms_p50, 2));
    setText("latency-p99", fmt(s.latency_ms_p99, 2));
    setText("fps", fmt(s.fps_in, 1) + " / " + fmt(s.fps_out, 1));
    setText("policy", s.policy || "—");
    if (s.reference && s.reference.touch) {
      showReference(s.reference.touch);
    } else if (typeof s.reference_ready === "boolean") {
      updateReference(s.reference_ready && !s.reference_capturing);
    }
  }

  // ------------------------------------------------------------------ reference
  // The engine's account of the touch reference: state, frames it came from, when, warnings,
  // and why the last window was refused (LiveEngine.reference_state()).
  function showReference(r) {
    const use = r.in_use;
    if (r.state === "retrying") {
      setReference("refused", r.last_refusal);
    } else {
      updateReference(r.state === "ready");
    }
    let detail = "";
    if (use && Array.isArray(use.frames)) {
      const when = typeof use.captured_utc === "string" ? use.captured_utc.replace("T", " ")
        .replace("+00:00", " UTC") : "";
      detail = "from frames " + use.frames[0] + ".." + use.frames[1] + (when ? ", " + when : "");
      if (r.refusals) detail += ", after " + r.refusals + " refused window(s)";
    }
    const d = $("reference-detail");
    d.dataset.frames = use && Array.isArray(use.frames) ? use.frames.join("..") : "";
    setText("reference-detail", detail);
    const warn = $("reference-warning");
    const warnings = use && Array.isArray(use.warnings) ? use.warnings : [];
    const text = r.state === "retrying" && r.last_refusal ? r.last_refusal
      : warnings.length ? "reference taken while: " + warnings.join("; ") +
        " (re-capture it with the skin untouched, uninflated and still)" : "";
    warn.hidden = !text;
    warn.dataset.kind = r.state === "retrying" ? "refused" : warnings.length ? "warning" : "";
    if (warn.textContent !== text) warn.textContent = text;
  }
  function updateReference(ready) {
    const ref = state.ref;
    let st;
    if (!ready) { st = "capturing"; ref.sawNotReady = true; }
    else if (ref.state === "requested" && !ref.sawNotReady &&
             performance.now() - ref.requestedAt < 1500) st = "requested";
    else st = "ready";
    setReference(st);
  }
  function setReference(st, detail) {
    const ref = state.ref;
    ref.state = st;
    const el = $("reference-status");
    el.dataset.state = st;
    el.dataset.requests = ref.requests;
    const text = {
      unknown: "reference: —",
      requested: "reference: re-capture requested…",
      capturing: "reference: capturing…",
      ready: "reference: ready" + (ref.requests ? " (re-captured ×" + ref.requests + ")" : ""),
      refused: "reference: refused, capturing again…",
      error: "reference: " + (detail || "request failed"),
    }[st];
    if (el.textContent !== text) el.textContent = text;
  }
  async function captureReference() {
    const btn = $("capture-reference");
    btn.disabled = true;
    try {
      const resp = await fetch("/api/reference", { method: "POST" });
      const body = await resp.json().catch(() => ({}));
      if (!resp.ok || !body.ok) {
        setReference("error", body.error || ("HTTP " + resp.status));
      } else {
        state.ref.requests = body.reference_requests || state.ref.requests + 1;
        state.ref.requestedAt = performance.now();
        state.ref.sawNotReady = false;
        setReference("requested");
      }
    } catch (e) {
      setReference("error", String(e));
    } finally {
      btn.disabled = false;
    }
  }

  // ------------------------------------------------------------------ touch
  function updateTouch(touch, label) {
    const meta = state.meta;
    if (!meta) return;
    const regions = document.querySelectorAll("#faces .region");
    const cls = touch && Number.isInteger(touch.cls) ? touch.cls : null;
    const probs = touch && Array.isArray(touch.probs) ? touch.probs : null;
    const pc = $("predicted-class");
    if (cls === null) {
      pc.textContent = "—"; pc.dataset.class = "";
      setText("predicted-label", touch ? "" : "no touch model");
    } else {
      if (pc.textContent !== String(cls)) pc.textContent = String(cls);
      pc.dataset.class = cls;
      setText("predicted-label", cls === 0 ? "no touch" : className(meta, cls).replace(/^\d+ /, "") +
        " region " + cls + (probs && isNum(probs[cls]) ? " (p = " + probs[cls].toFixed(2) + ")" : ""));
    }
    const truth = Number.isInteger(label) ? label : null;
    setText("true-class", truth === null ? "—" : String(truth));
    for (const el of regions) {
      const id = Number(el.dataset.region);
      const lit = cls !== null && id === cls;
      el.classList.toggle("lit", lit);
      el.classList.toggle("truth", truth !== null && id === truth);
      const lab = el.ownerSVGElement.querySelector('[data-region-label="' + id + '"]');
      if (lab) lab.classList.toggle("lit", lit);
      // Unlit regions are tinted by their probability.
      const p = probs && isNum(probs[id]) ? probs[id] : 0;
      el.style.fillOpacity = lit ? "" : String(Math.min(0.5, 0.5 * p));
    }
    const rows = $("probs").children;
    for (let k = 0; k < rows.length; k++) {
      const p = probs && isNum(probs[k]) ? probs[k] : 0;
      const row = rows[k];
      row.querySelector(".bar").style.width = (100 * Math.max(0, Math.min(1, p))).toFixed(1) + "%";
      row.querySelector(".p").textContent = probs ? p.toFixed(2) : "—";
      row.classList.toggle("top", k === cls);
      row.classList.toggle("truth", k === truth);
    }
  }

  // ------------------------------------------------------------------ markers
  const AXIS = { x: 0, y: 1, z: 2 };
  function validPoint(p) { return Array.isArray(p) && p.length === 3 && p.every(isNum); }
  function dist(a, b) { return Math.hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]); }

  function buildView(id, meta) {
    const svg = $(id);
    svg.innerHTML = "";
    const [h, v] = svg.dataset.axes.split(",");
    const n = meta.marker_names.length;
    const view = { svg, h: AXIS[h], v: AXIS[v], hName: h, vName: v, bounds: null,
                   static: svgEl("g", {}, svg), lines: {}, dots: {} };
    for (const kind of ["ref", "true", "pred"]) {
      view.lines[kind] = svgEl("polyline", { class: "l-" + kind, "data-kind": kind }, svg);
    }
    for (const kind of ["ref", "true", "pred"]) {
      view.dots[kind] = [];
      for (let j = 0; j < n; j++) {
        view.dots[kind].push(svgEl("circle", {
          class: "m-" + kind, r: kind === "ref" ? 5 : 4, "data-kind": kind,
          "data-marker": meta.marker_names[j], visibility: "hidden",
        }, svg));
      }
    }
    view.names = meta.marker_names.map((name) => {
      const t = svgEl("text", { class: "m-name", visibility: "hidden" }, svg);
      t.textContent = name;
      return t;
    });
    state.views[id] = view;
    if (validPoints(meta.reference_markers)) setBounds(view, meta.reference_markers);
  }
  function validPoints(ps) { return Array.isArray(ps) && ps.some(validPoint); }

  // Equal-aspect mm → px mapping around the reference pose; grows if points leave it.
  function setBounds(view, ref, extra) {
    const pts = ref.filter(validPoint).concat((extra || []).filter(validPoint));
    let h0 = Infinity, h1 = -Infinity, v0 = Infinity, v1 = -Infinity;
    for (const p of pts) {
      h0 = Math.min(h0, p[view.h]); h1 = Math.max(h1, p[view.h]);
      v0 = Math.min(v0, p[view.v]); v1 = Math.max(v1, p[view.v]);
    }
    if (view.v === 2) v0 = Math.min(v0, 0);          // keep the clamped base (z = 0) in view
    const hc = (h0 + h1) / 2, half = Math.max(35, (h1 - h0) / 2 + 15);
    view.bounds = { h0: hc - half, h1: hc + half, v0: v0 - 10, v1: v1 + 15 };
    drawAxes(view);
  }
  function mapper(view) {
    const W = view.svg.clientWidth || 300, H = view.svg.clientHeight || 360;
    const b = view.bounds, pad = 28;
    const s = Math.min((W - 2 * pad) / (b.h1 - b.h0), (H - 2 * pad) / (b.v1 - b.v0));
    const ox = W / 2 - s * (b.h0 + b.h1) / 2, oy = H / 2 + s * (b.v0 + b.v1) / 2;
    return { s, W, H, x: (a) => ox + s * a, y: (c) => oy - s * c,
             a: (px) => (px - ox) / s, c: (py) => (oy - py) / s };
  }
  function drawAxes(view) {
    const g = view.static;
    g.innerHTML = "";
    const m = mapper(view);
    view.map = m;
    const lo = { h: m.a(0), v: m.c(m.H) }, hi = { h: m.a(m.W), v: m.c(0) };
    const step = (hi.v - lo.v) > 200 ? 20 : 10;
    // Tick labels keep clear of the axis names (bottom right, top left).
    for (let a = Math.ceil(lo.h / step) * step; a <= hi.h; a += step) {
      svgEl("line", { class: "grid", x1: m.x(a), x2: m.x(a), y1: 0, y2: m.H }, g);
      if (a % (2 * step) === 0 && m.x(a) > 24 && m.x(a) < m.W - 70) {
        const t = svgEl("text", { class: "tick", x: m.x(a) + 2, y: m.H - 4 }, g);
        t.textContent = a;
      }
    }
    for (let c = Math.ceil(lo.v / step) * step; c <= hi.v; c += step) {
      svgEl("line", { class: "grid", x1: 0, x2: m.W, y1: m.y(c), y2: m.y(c) }, g);
      if (c % (2 * step) === 0 && m.y(c) > 28 && m.y(c) < m.H - 16) {
        const t = svgEl("text", { class: "tick", x: 3, y: m.y(c) - 2 }, g);
        t.textContent = c;
      }
    }
    if (view.v === 2) {  // the clamp at the base, z = 0
      svgEl("line", { class: "axis", x1: 0, x2: m.W, y1: m.y(0), y2: m.y(0),
                      "stroke-width": 3 }, g);
    }
    const lab = svgEl("text", { class: "tick axis-name", x: m.W - 4, y: m.H - 4,
                                "text-anchor": "end" }, g);
    lab.textContent = view.hName + " (mm) →";
    const lab2 = svgEl("text", { class: "tick axis-name", x: 3, y: 12 }, g);
    lab2.textContent = "↑ " + view.vName + " (mm)";
  }
  function outside(view, pts) {
    const b = view.bounds;
    return pts.some((p) => validPoint(p) &&
      (p[view.h] < b.h0 || p[view.h] > b.h1 || p[view.v] < b.v0 || p[view.v] > b.v1));
  }
  function drawPoints(view, kind, pts) {
    const dots = view.dots[kind], m = view.map, line = [];
    for (let j = 0; j < dots.length; j++) {
      const p = pts && pts[j];
      if (validPoint(p)) {
        const x = m.x(p[view.h]), y = m.y(p[view.v]);
        dots[j].setAttribute("cx", x.toFixed(1));
        dots[j].setAttribute("cy", y.toFixed(1));
        dots[j].setAttribute("visibility", "visible");
        line.push(x.toFixed(1) + "," + y.toFixed(1));
        if (kind === "ref") {
          view.names[j].setAttribute("x", (x + 8).toFixed(1));
          view.names[j].setAttribute("y", (y + 4).toFixed(1));
          view.names[j].setAttribute("visibility", "visible");
        }
      } else {
        dots[j].setAttribute("visibility", "hidden");
      }
    }
    view.lines[kind].setAttribute("points", line.join(" "));
  }

  // Predicted markers against the reference pose (and the true markers when the source has them).
  // Without a tracking model the true markers are still drawn. "moved" is the largest distance of
  // a marker from its reference position: predicted markers if any, else true ones
  // (data-source says which).
  function updateMarkers(mk) {
    if (!state.meta) return;
    const moved = $("markers-moved"), err = $("markers-error");
    const pred = mk && validPoints(mk.pred) ? mk.pred : null;
    const truth = mk && validPoints(mk.true) ? mk.true : null;
    let ref = mk && validPoints(mk.reference) ? mk.reference : null;
    if (!ref && validPoints(state.meta.reference_markers)) ref = state.meta.reference_markers;
    const shown = pred || truth;
    if (!shown) {
      moved.textContent = "—"; moved.dataset.value = ""; moved.dataset.source = "";
      err.textContent = "—"; err.dataset.value = "";
      return;
    }
    const key = ref ? JSON.stringify(ref) : "none";
    const all = (pred || []).concat(truth || []);
    for (const id in state.views) {
      const view = state.views[id];
      if (key !== state.refKey || !view.bounds) setBounds(view, ref || shown);
      if (outside(view, all)) setBounds(view, ref || shown, all);
      drawPoints(view, "ref", ref);
      drawPoints(view, "true", truth);
      drawPoints(view, "pred", pred);
    }
    state.refKey = key;
    let maxMove = null;
    if (ref) {
      for (let j = 0; j < shown.length; j++) {
        if (validPoint(shown[j]) && validPoint(ref[j])) {
          const d = dist(shown[j], ref[j]);
          maxMove = maxMove === null ? d : Math.max(maxMove, d);
        }
      }
    }
    moved.textContent = fmt(maxMove, 2);
    moved.dataset.value = maxMove === null ? "" : String(maxMove);
    moved.dataset.source = pred ? "pred" : "true";
    // Average distance of the predicted to the true markers (paper Eq. 3, for this frame).
    let sum = 0, n = 0;
    if (pred && truth) {
      for (let j = 0; j < pred.length; j++) {
        if (validPoint(pred[j]) && validPoint(truth[j])) { sum += dist(pred[j], truth[j]); n++; }
      }
    }
    err.textContent = n ? (sum / n).toFixed(2) : "—";
    err.dataset.value = n ? String(sum / n) : "";
    updateMarkerBars(pred || truth, pred ? truth : null, ref);
  }

  // Per marker: how far it moved from the reference pose, and the error of the estimate, as bars
  // on their own millimetre scale (a sub-millimetre error is invisible on the 140-mm views).
  function buildMarkerBars(meta) {
    const host = $("marker-errors");
    host.querySelectorAll(".mk-row").forEach((el) => el.remove());
    for (const name of meta.marker_names) {
      const row = document.createElement("div");
      row.className = "mk-row";
      row.dataset.marker = name;
      row.innerHTML = '<span class="name"></span><span class="bars">' +
        '<span class="track"><span class="bar moved"></span></span>' +
        '<span class="track"><span class="bar err"></span></span></span>' +
        '<span class="v">—</span>';
      row.querySelector(".name").textContent = name;
      host.appendChild(row);
    }
  }
  function niceCeil(v) {  // 1, 2, 5 × 10^k at or above v
    const p = Math.pow(10, Math.floor(Math.log10(v)));
    for (const m of [1, 2, 5, 10]) if (m * p >= v) return m * p;
    return 10 * p;
  }
  function updateMarkerBars(shown, truth, ref) {
    const rows = $("marker-errors").querySelectorAll(".mk-row");
    const moved = [], errs = [];
    for (let j = 0; j < rows.length; j++) {
      const p = shown && shown[j];
      moved.push(validPoint(p) && ref && validPoint(ref[j]) ? dist(p, ref[j]) : null);
      errs.push(validPoint(p) && truth && validPoint(truth[j]) ? dist(p, truth[j]) : null);
    }
    // Two scales: the error of a good estimate is far smaller than the motion it tracks, and
    // would vanish on the motion's scale. Each is at least 0.5 mm at full width.
    const scaleMoved = niceCeil(Math.max(0.5, ...moved.filter(isNum)));
    const scale = niceCeil(Math.max(0.5, ...errs.filter(isNum)));
    setText("marker-scale", "full bar: moved " + scaleMoved + " mm, error " + scale + " mm");
    $("marker-scale").dataset.scaleMoved = String(scaleMoved);
    $("marker-scale").dataset.scaleError = String(scale);
    rows.forEach((row, j) => {
      const m = moved[j], e = errs[j];
      row.dataset.moved = isNum(m) ? String(m) : "";
      row.dataset.error = isNum(e) ? String(e) : "";
      row.querySelector(".bar.moved").style.width =
        (isNum(m) ? 100 * m / scaleMoved : 0).toFixed(1) + "%";
      row.querySelector(".bar.err").style.width = (isNum(e) ? 100 * e / scale : 0).toFixed(1) + "%";
      row.querySelector(".v").textContent = (isNum(m) ? m.toFixed(2) : "—") + " / " +
        (isNum(e) ? e.toFixed(2) : "—") + " mm";
    });
  }

  // ------------------------------------------------------------------ contact and ECT image
  // Each face drawn in its own (u, v) mm: u across, v from the base (bottom) to the tip (top);
  // SVG y = -v. The ECT image is a canvas (one pixel per image pixel, scaled by the browser) in a
  // foreignObject over the imager's grid extent, under the fingers: a dot at (u, v), a dashed
  // circle of radius sigma_mm (one standard deviation) around it, and a cross at the ECT peak.
  const contactView = { faces: {}, forceScale: FORCE_FULL_N, heatScale: 0, heatT: 0 };

  function contactFaces(meta) {
    const names = [];
    for (const head of [meta.contact, meta.ect, meta.inversion]) {
      if (head && Array.isArray(head.faces)) head.faces.forEach((f) => names.push(f));
    }
    const known = SURFACE_ORDER.filter((s) => names.includes(s));
    return known.concat([...new Set(names)].filter((f) => !known.includes(f)));
  }

  // The face's drawing extent: its skins, the contact model's and the inversion's face extents,
  // the ECT grid.
  function faceBounds(meta, face) {
    const b = { u0: Infinity, u1: -Infinity, v0: Infinity, v1: -Infinity };
    const add = (u, v) => {
      b.u0 = Math.min(b.u0, u[0]); b.u1 = Math.max(b.u1, u[1]);
      b.v0 = Math.min(b.v0, v[0]); b.v1 = Math.max(b.v1, v[1]);
    };
    meta.skins.filter((s) => s.surface === face).forEach((s) => add(s.u_mm, s.v_mm));
    for (const ext of [meta.contact && meta.contact.face_extent[face],
                       meta.ect && meta.ect.grid_extent[face],
                       meta.inversion && meta.inversion.face_extent &&
                         meta.inversion.face_extent[face]]) {
      if (Array.isArray(ext)) add(ext[0], ext[1]);
    }
    if (!isFinite(b.u0)) Object.assign(b, { u0: -20, u1: 20, v0: 0, v1: 120 });
    return b;
  }

  function buildContact(meta) {
    const panel = $("contact-panel"), host = $("contact-faces");
    host.innerHTML = "";
    contactView.faces = {};
    contactView.forceScale = FORCE_FULL_N;
    contactView.heatScale = 0;
    state.contact = null;
    state.ect = null;
    $("contact-fingers").querySelectorAll(".cf-row").forEach((el) => el.remove());
    panel.hidden = !(meta.contact || meta.ect || meta.inversion);
    const svgs = {};
    if (panel.hidden) { window.ectskinInversion.build(meta, svgs); return; }
    for (const face of contactFaces(meta)) {
      const b = faceBounds(meta, face), m = 4;
      const div = document.createElement("div");
      div.className = "cface";
      div.dataset.face = face;
      const svg = svgEl("svg", {
        id: "cface-" + face, viewBox: [b.u0 - m, -(b.v1 + m), b.u1 - b.u0 + 2 * m,
                                       b.v1 - b.v0 + 2 * m].join(" "),
      }, div);
      for (const sk of meta.skins.filter((sk) => sk.surface === face)) {
        svgEl("rect", { class: "skin", x: sk.u_mm[0], y: -sk.v_mm[1], rx: 1.5,
          width: sk.u_mm[1] - sk.u_mm[0], height: sk.v_mm[1] - sk.v_mm[0] }, svg);
      }
      let canvas = null;
      const ext = meta.ect && meta.ect.grid_extent[face];
      if (Array.isArray(ext)) {
        const fo = svgEl("foreignObject", { x: ext[0][0], y: -ext[1][1],
          width: ext[0][1] - ext[0][0], height: ext[1][1] - ext[1][0] }, svg);
        canvas = document.createElement("canvas");  // an HTML element inside the SVG
        canvas.className = "heat";
        canvas.dataset.face = face;
        canvas.width = 1; canvas.height = 1;
        fo.appendChild(canvas);
      }
      for (const r of meta.regions.filter((r) => r.surface === face)) {
        svgEl("rect", { class: "region", x: r.u_mm[0], y: -r.v_mm[1],
          width: r.u_mm[1] - r.u_mm[0], height: r.v_mm[1] - r.v_mm[0] }, svg);
      }
      const peak = svgEl("path", { class: "ect-peak", d: "", visibility: "hidden" }, svg);
      const sigma = [], dots = [];
      for (let k = 0; k < FINGER_SLOTS; k++) {
        sigma.push(svgEl("circle", { class: "finger-sigma", "data-finger": k, r: 0,
                                     visibility: "hidden" }, svg));
      }
      for (let k = 0; k < FINGER_SLOTS; k++) {
        dots.push(svgEl("circle", { class: "finger-dot", "data-finger": k, r: DOT_MM,
                                    visibility: "hidden" }, svg));
      }
      const title = document.createElement("div");
      title.className = "title";
      title.textContent = face + " (u across, v up to the tip, mm)";
      div.appendChild(title);
      host.appendChild(div);
      contactView.faces[face] = { svg, canvas, peak, sigma, dots };
      svgs[face] = svg;
    }
    window.ectskinInversion.build(meta, svgs);  // over the contact model's fingers
    const list = $("contact-fingers");
    for (let k = 0; k < FINGER_SLOTS; k++) {
      const row = document.createElement("div");
      row.className = "cf-row absent";
      row.dataset.finger = k;
      row.innerHTML = '<span class="name"></span><span class="track"><span class="bar"></span>' +
        '<span class="fsig" hidden></span></span><span class="v">—</span>' +
        '<span class="where"></span>';
      row.querySelector(".name").textContent = "finger " + (k + 1);
      list.appendChild(row);
    }
    const notes = [];
    if (!meta.contact) notes.push("no contact model (ectskin live --contact-model RUN)");
    if (!meta.ect) notes.push("no ECT image (ectskin live --ect)");
    else notes.push("ECT image every " + meta.ect.every + " frame(s)");
    if (!meta.inversion) notes.push("no physical inversion (ectskin live --fields DIR)");
    else notes.push("inversion every " + meta.inversion.every + " frame(s)");
    setText("contact-note", notes.join("; "));
    updateForceScale();
  }

  function updateForceScale() {
    const el = $("force-scale");
    el.dataset.scale = String(contactView.forceScale);
    setText("force-scale", "full bar: " + contactView.forceScale + " N");
  }

  function updateContact(c) {
    const meta = state.meta;
    if (!meta || !meta.contact) return;
    state.contact = c || null;
    const fingers = c && Array.isArray(c.fingers) ? c.fingers.slice(0, FINGER_SLOTS) : [];
    const count = $("contact-count"), p = $("contact-p");
    count.dataset.count = c ? String(c.count) : "";
    setText("contact-count", c ? String(c.count) : "—");
    p.dataset.value = c && isNum(c.p_contact) ? String(c.p_contact) : "";
    setText("contact-p", c ? fmt(c.p_contact, 2) : "—");
    for (const face in contactView.faces) {
      const view = contactView.faces[face];
      for (let k = 0; k < FINGER_SLOTS; k++) {
        const f = fingers[k];
        const here = f && f.face === face && isNum(f.u_mm) && isNum(f.v_mm);
        const dot = view.dots[k], ring = view.sigma[k];
        dot.setAttribute("visibility", here ? "visible" : "hidden");
        ring.setAttribute("visibility", here ? "visible" : "hidden");
        if (!here) continue;
        for (const el of [dot, ring]) {
          el.setAttribute("cx", f.u_mm.toFixed(2));
          el.setAttribute("cy", (-f.v_mm).toFixed(2));
        }
        ring.setAttribute("r", (isNum(f.sigma_mm) ? Math.max(0, f.sigma_mm) : 0).toFixed(2));
      }
    }
    const maxF = Math.max(0, ...fingers.map((f) => (isNum(f.force_n) ? f.force_n : 0)));
    if (maxF > contactView.forceScale) {
      contactView.forceScale = niceCeil(maxF);
      updateForceScale();
    }
    // Each finger's force as a bar, and its standard deviation force_sigma_n (N, the model's
    // own; absent or null from a run trained before the force had its σ) as a band over
    // force ± 1σ on the bar and in the number; without σ the bar and number stand alone.
    const rows = $("contact-fingers").querySelectorAll(".cf-row");
    rows.forEach((row, k) => {
      const f = fingers[k];
      const force = f && isNum(f.force_n) ? f.force_n : null;
      const sd = force !== null && isNum(f.force_sigma_n) && f.force_sigma_n > 0
        ? f.force_sigma_n : null;
      const pct = (v) => (100 * Math.max(0, v) / contactView.forceScale).toFixed(1) + "%";
      row.classList.toggle("absent", !f);
      row.dataset.force = force === null ? "" : String(force);
      row.dataset.sigma = sd === null ? "" : String(sd);
      row.dataset.face = f ? f.face : "";
      row.querySelector(".bar").style.width = force === null ? "0.0%" : pct(force);
      const band = row.querySelector(".fsig");
      band.hidden = sd === null;
      band.style.left = sd === null ? "0%" : pct(force - sd);
      band.style.width = sd === null ? "0%" : (parseFloat(pct(force + sd)) -
        parseFloat(pct(force - sd))).toFixed(1) + "%";
      row.querySelector(".v").textContent = force === null ? "—"
        : force.toFixed(2) + (sd === null ? "" : " ± " + sd.toFixed(2)) + " N";
      row.querySelector(".where").textContent = f ? f.face + " (" + fmt(f.u_mm, 1) + ", " +
        fmt(f.v_mm, 1) + ") mm ± " + fmt(f.sigma_mm, 1) : "";
    });
    const ph = c && isNum(c.p_hover) ? c.p_hover : null;
    const hov = $("hover-indicator");
    const st = !c ? "none" : c.count > 0 ? "contact" : ph !== null && ph >= HOVER_AT ? "hover"
      : "none";
    hov.dataset.state = st;
    hov.dataset.p = ph === null ? "" : String(ph);
    setText("hover-indicator", { contact: "touching", hover: "hovering", none: "—" }[st]);
    setText("hover-p", fmt(ph, 2));
    $("hover-bar").style.width = (ph === null ? 0 : 100 * Math.max(0, Math.min(1, ph)))
      .toFixed(1) + "%";
  }

  // Heat-map colour of a value t in [-1, 1] (of the colour scale): positive change red to yellow
  // and more opaque as it grows; negative change faint blue; [r, g, b, alpha] 0-255.
  function heatColor(t) {
    if (!isNum(t) || t === 0) return [0, 0, 0, 0];
    const a = Math.min(1, Math.abs(t));
    if (t < 0) return [47, 111, 219, Math.round(127 * Math.pow(a, 0.7))];
    return [Math.round(226 + 19 * a), Math.round(65 + 132 * a), Math.round(59 + 7 * a),
            Math.round(235 * Math.pow(a, 0.7))];
  }

  function drawHeat(canvas, rows, gain) {
    const nv = Array.isArray(rows) ? rows.length : 0;
    const nu = nv && Array.isArray(rows[0]) ? rows[0].length : 0;
    if (!nv || !nu) return 0;
    if (canvas.width !== nu || canvas.height !== nv) { canvas.width = nu; canvas.height = nv; }
    const ctx = canvas.getContext("2d");
    const im = ctx.createImageData(nu, nv);
    for (let r = 0; r < nv; r++) {
      const row = rows[r], y = nv - 1 - r;  // row 0 is the lowest v: the bottom of the canvas
      for (let c = 0; c < nu; c++) {
        const col = heatColor(isNum(row[c]) ? row[c] * gain : NaN), i = 4 * (y * nu + c);
        im.data[i] = col[0]; im.data[i + 1] = col[1]; im.data[i + 2] = col[2];
        im.data[i + 3] = col[3];
      }
    }
    ctx.putImageData(im, 0, 0);
    return nu * nv;
  }

  function updateEct(e, seq) {
    const meta = state.meta;
    if (!meta || !meta.ect) return;
    const img = e.image || {};
    const now = performance.now() / 1000;
    const scale = isNum(img.scale) ? img.scale : 0;
    const held = contactView.heatScale * Math.exp(-(now - contactView.heatT) / HEAT_DECAY_S);
    contactView.heatScale = Math.max(scale, held);
    contactView.heatT = now;
    // a pixel q (in levels) is q * scale / levels; the colour scale is the held maximum
    const gain = contactView.heatScale > 0 && isNum(img.levels)
      ? scale / (img.levels * contactView.heatScale) : 0;
    let drawn = 0;
    for (const face in contactView.faces) {
      const view = contactView.faces[face];
      if (view.canvas && img.faces) drawn += drawHeat(view.canvas, img.faces[face], gain);
      const here = e.face === face && isNum(e.u_mm) && isNum(e.v_mm);
      view.peak.setAttribute("visibility", here ? "visible" : "hidden");
      if (here) {
        const x = e.u_mm, y = -e.v_mm, d = 3;
        view.peak.setAttribute("d", "M" + (x - d) + "," + (y - d) + "L" + (x + d) + "," + (y + d) +
          "M" + (x - d) + "," + (y + d) + "L" + (x + d) + "," + (y - d));
      }
    }
    const el = $("ect-peak");
    el.dataset.face = typeof e.face === "string" ? e.face : "";
    setText("ect-peak", "ECT peak " + (e.face || "—") + " (" + fmt(e.u_mm, 1) + ", " +
      fmt(e.v_mm, 1) + ") mm");
    state.ect = { seq, face: e.face, u_mm: e.u_mm, v_mm: e.v_mm, peak: e.peak,
                  scale: contactView.heatScale,
                  drawn: (state.ect ? state.ect.drawn : 0) + (drawn ? 1 : 0) };
  }

  // ------------------------------------------------------------------ strip chart
  const chart = { canvas: null, ctx: null, dpr: 1, W: 0, H: 0 };
  function resizeChart() {
    const c = $("strip-chart");
    chart.canvas = c;
    chart.ctx = c.getContext("2d");
    chart.dpr = window.devicePixelRatio || 1;
    const n = state.meta ? state.meta.n_pairs : 28;
    const rows = Math.max(1, Math.ceil(n / CHART_COLS));
    chart.W = c.clientWidth;
    chart.H = rows * 78;
    c.style.height = chart.H + "px";
    c.width = Math.round(chart.W * chart.dpr);
    c.height = Math.round(chart.H * chart.dpr);
    state.chartDirty = true;
    for (const id in state.views) if (state.views[id].bounds) drawAxes(state.views[id]);
  }

  function pairColor(meta, i) {
    const s = meta.pair_surfaces && meta.pair_surfaces[i];
    if (!s || s[0] !== s[1]) return getVar("--cross");
    return s[0] === "back" ? getVar("--back") : getVar("--front");
  }
  const varCache = {};
  function getVar(name) {
    if (!(name in varCache)) varCache[name] = getComputedStyle(document.documentElement)
      .getPropertyValue(name).trim() || "#888";
    return varCache[name];
  }

  // The vertical range drawn for values between lo and hi: at least the minimum span (so noise
  // stays small), plus a margin of 8 % on each side.
  function chartRange(lo, hi, calibrated) {
    const minSpan = calibrated ? MIN_SPAN_CALIBRATED : MIN_SPAN_RAW_PF;
    let span = hi - lo;
    if (!(span >= minSpan)) {
      const c = (hi + lo) / 2;
      lo = c - minSpan / 2; hi = c + minSpan / 2; span = minSpan;
    }
    return { lo: lo - 0.08 * span, hi: hi + 0.08 * span, span };
  }

  function drawChart() {
    const meta = state.meta, ctx = chart.ctx;
    if (!meta || !ctx) return;
    const dpr = chart.dpr, W = chart.W, H = chart.H;
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, W, H);
    const n = meta.n_pairs, cols = CHART_COLS, rows = Math.ceil(n / cols);
    const cw = W / cols, ch = H / rows;
    const fr = state.frames, mode = state.mode;
    // Time axis: seconds before now on the page clock; the data scroll to the left, even when
    // frames stop coming (then the traces end before "now").
    const tEnd = performance.now() / 1000, tStart = tEnd - WINDOW_S;
    const calibrated = mode === "calibrated";
    const series = fr.filter((f) => Array.isArray(f[mode]) && f.w / 1000 >= tStart);
    // Trial boundaries in the window (replay, sim): where the trial name changes.
    const bounds = [];
    for (let k = 1; k < series.length; k++) {
      const a = series[k - 1].trial, b = series[k].trial;
      if (a !== null && b !== null && a !== b) bounds.push({ s: series[k].w / 1000, trial: b });
    }
    state.chartBoundaries = bounds.map((b) => b.trial);
    const ticks = [];
    for (let s = -WINDOW_S; s <= 0; s += TICK_S) ticks.push(s === 0 ? "now" : s + " s");
    chart.canvas.dataset.ticks = ticks.join(",");
    const spans = [];
    ctx.font = "11px system-ui, sans-serif";
    ctx.textBaseline = "top";
    for (let i = 0; i < n; i++) {
      const x0 = (i % cols) * cw, y0 = Math.floor(i / cols) * ch;
      const px0 = x0 + 4, px1 = x0 + cw - 6, py0 = y0 + 16, py1 = y0 + ch - 14;
      const xOf = (sec) => px0 + (px1 - px0) * (sec - tStart) / WINDOW_S;
      ctx.strokeStyle = "#e6e9ed"; ctx.lineWidth = 1;
      ctx.strokeRect(px0 + 0.5, py0 + 0.5, px1 - px0, py1 - py0);
      ctx.strokeStyle = "#f1f3f5";
      for (let s = -WINDOW_S + GRID_S; s < 0; s += GRID_S) {
        const gx = xOf(tEnd + s);
        ctx.beginPath(); ctx.moveTo(gx + 0.5, py0); ctx.lineTo(gx + 0.5, py1); ctx.stroke();
      }
      ctx.setLineDash([3, 3]);
      ctx.strokeStyle = "#9aa5b1";
      for (const b of bounds) {
        const bx = xOf(b.s);
        ctx.beginPath(); ctx.moveTo(bx + 0.5, py0); ctx.lineTo(bx + 0.5, py1); ctx.stroke();
      }
      ctx.setLineDash([]);
      ctx.fillStyle = "#4b545e";
      ctx.textAlign = "left";
      ctx.fillText(meta.pair_names[i], px0, y0 + 2);
      if (i % cols === 0) {  // trial names once per row, at their boundary, where there is room
        ctx.fillStyle = "#6b7480";
        let free = -Infinity;
        for (const b of bounds) {
          const bx = xOf(b.s) + 3;
          if (bx < free) continue;
          ctx.fillText(b.trial, bx, py0 + 2);
          free = bx + ctx.measureText(b.trial).width + 6;
        }
      }
      if (Math.floor(i / cols) === rows - 1 || i + cols >= n) {  // time labels under the last row
        ctx.fillStyle = "#8a939e";
        ctx.font = "10px system-ui, sans-serif";
        for (let k = 0; k < ticks.length; k++) {
          const s = -WINDOW_S + k * TICK_S;
          ctx.textAlign = k === 0 ? "left" : k === ticks.length - 1 ? "right" : "center";
          ctx.fillText(ticks[k], xOf(tEnd + s), py1 + 2);
        }
        ctx.font = "11px system-ui, sans-serif";
        ctx.textAlign = "left";
      }
      let lo = Infinity, hi = -Infinity, last = null;
      for (const f of series) {
        const v = f[mode][i];
        if (isNum(v)) { lo = Math.min(lo, v); hi = Math.max(hi, v); last = v; }
      }
      if (!isFinite(lo)) {
        spans.push(null);
        ctx.fillStyle = "#a0a8b2";
        ctx.fillText(calibrated && fr.length ? "no reference yet" : "no data", px0 + 4, py0 + 14);
        continue;
      }
      const range = chartRange(lo, hi, calibrated);
      spans.push(range.span);
      // The newest value, and the span of the vertical scale (↕) next to it.
      const val = calibrated ? (last >= 0 ? "+" : "") + (100 * last).toFixed(2) + " %"
                             : last.toFixed(3);
      const spanText = " ↕" + (calibrated ? (100 * range.span).toFixed(1) + " %"
                                          : (1000 * range.span).toFixed(0) + " fF");
      ctx.textAlign = "right";
      ctx.fillStyle = "#a0a8b2";
      ctx.fillText(spanText, px1, y0 + 2);
      ctx.fillStyle = "#4b545e";
      ctx.fillText(val, px1 - ctx.measureText(spanText).width, y0 + 2);
      ctx.textAlign = "left";
      ctx.strokeStyle = pairColor(meta, i);
      ctx.lineWidth = 1.4;
      ctx.beginPath();
      let pen = false, prevW = -Infinity;
      for (const f of series) {
        const v = f[mode][i];
        if (!isNum(v)) { pen = false; continue; }
        if (f.w - prevW > GAP_MS) pen = false;  // no line across a gap in the stream
        prevW = f.w;
        const x = xOf(f.w / 1000);
        const y = py1 - (py1 - py0) * (v - range.lo) / (range.hi - range.lo);
        if (pen) ctx.lineTo(x, y); else ctx.moveTo(x, y);
        pen = true;
      }
      ctx.stroke();
    }
    state.chartSpans = spans;
  }

  let lastDraw = 0;
  function tick(now) {
    // Redraw on new data, and at least every 100 ms so that the time axis keeps scrolling.
    if (state.chartDirty || now - lastDraw > 100) {
      state.chartDirty = false; lastDraw = now; drawChart();
    }
    requestAnimationFrame(tick);
  }

  // ------------------------------------------------------------------ polling (when idle)
  async function pollStats() {
    try {
      const resp = await fetch("/api/stats");
      if (!resp.ok) return;
      const s = await resp.json();
      const d = s.dashboard || {};
      const errEl = $("engine-error");
      errEl.hidden = !d.engine_error;
      errEl.textContent = d.engine_error ? "engine: " + d.engine_error : "";
      if (typeof d.engine_state === "string" && d.engine_state !== state.engine) {
        state.engine = d.engine_state;
        updateBadge();
      }
      if (performance.now() - state.lastFrameWall > 1500) updateStats(s);
    } catch (e) { /* server gone: the websocket reports it */ }
  }
  function updateAge() {
    updateBadge();
    if (!state.lastFrameWall) return;
    const age = (performance.now() - state.lastFrameWall) / 1000;
    setText("frame-age", age < 1 ? "" : age.toFixed(0) + " s ago");
  }

  // ------------------------------------------------------------------ start
  // For the browser test: the page's state and its pure helpers.
  window.ectskinDashboard = { state, badge, chartRange, heatColor, MIN_SPAN_RAW_PF,
                              MIN_SPAN_CALIBRATED };
  document.querySelectorAll('input[name="chart-mode"]').forEach((el) => {
    el.addEventListener("change", () => { state.mode = el.value; state.chartDirty = true; });
  });
  $("capture-reference").addEventListener("click", captureReference);
  window.addEventListener("resize", resizeChart);
  resizeChart();
  connect();
  requestAnimationFrame(tick);
  setInterval(pollStats, 2000);
  setInterval(updateAge, 500);
})();
