// rtseg live monitor page: reads the session's batches from /ws and draws them.
// Times are seconds since the session start (as the cut lines rtseg prints).
"use strict";
(function () {
  const WINDOW_S = 30;
  const COLOURS = ["#4e79a7", "#f28e2b", "#59a14f", "#e15759", "#76b7b2", "#edc948",
                   "#b07aa1", "#ff9da7", "#9c755f", "#bab0ac"];
  const st = { info: null, stat: [], pre: [], gated: [], cuts: [], behaviours: {},
               health: null, now: 0, nowAt: 0, ended: false, dirty: true };
  const $ = (id) => document.getElementById(id);
  let plot = null;

  function colour(id) {
    const n = parseInt(id, 10);
    return isNaN(n) ? "#888" : COLOURS[(n - 1) % COLOURS.length];
  }
  function nameOf(seg) {
    const b = st.behaviours[seg];
    return b ? (b.name || b.behaviour) : null;
  }
  function sessionNow() {
    if (st.ended) return st.now;
    return st.now + (performance.now() - st.nowAt) / 1000;
  }
  function trim(arr, lo) { let i = 0; while (i < arr.length && arr[i][0] < lo) i++; if (i) arr.splice(0, i); }

  function makePlot() {
    const info = st.info || {};
    const el = $("chart");
    const opts = {
      width: Math.max(400, el.clientWidth || 800), height: 260,
      scales: { x: { time: false }, y: { range: (u, lo, hi) => [0, Math.max(hi || 0, (info.threshold || 1) * 1.5)] } },
      axes: [{ stroke: "#aaa", grid: { stroke: "#333" }, label: "s since start" },
             { stroke: "#aaa", grid: { stroke: "#333" } }],
      series: [{ label: "t (s)" },
               { label: info.statistic || "statistic", stroke: "#4fc3f7", width: 2, spanGaps: true },
               { label: "pre-look", stroke: "#ba68c8", width: 1, spanGaps: true, show: info.pre_level != null },
               { label: "threshold", stroke: "#e57373", dash: [6, 4], width: 1, points: { show: false } },
               { label: "pre-look level", stroke: "#ce93d8", dash: [2, 4], width: 1, points: { show: false },
                 show: info.pre_level != null }],
      legend: { live: false },
      hooks: { draw: [drawCuts] },
    };
    el.innerHTML = "";
    plot = new uPlot(opts, data(), el);
  }

  function data() {
    const pts = [];
    for (const p of st.stat) pts.push([p[0], p[1], null]);
    for (const p of st.pre) pts.push([p[0], null, p[1]]);
    pts.sort((a, b) => a[0] - b[0]);
    const thr = st.info && st.info.threshold, ethr = st.info && st.info.pre_level;
    return [pts.map((p) => p[0]), pts.map((p) => p[1]), pts.map((p) => p[2]),
            pts.map(() => thr), pts.map(() => ethr)];
  }

  function drawCuts(u) {
    const ctx = u.ctx, top = u.bbox.top, h = u.bbox.height;
    const [lo, hi] = [u.scales.x.min, u.scales.x.max];
    ctx.save();
    ctx.font = `${Math.round(11 * devicePixelRatio)}px sans-serif`;
    for (const g of st.gated) {
      if (g[0] < lo || g[0] > hi) continue;
      const x = u.valToPos(g[0], "x", true);
      ctx.strokeStyle = "#666"; ctx.setLineDash([4, 4]); ctx.beginPath();
      ctx.moveTo(x, top); ctx.lineTo(x, top + h); ctx.stroke();
      ctx.fillStyle = "#777"; ctx.fillText("gated", x + 3, top + h - 4);
    }
    ctx.setLineDash([]);
    for (const c of st.cuts) {
      if (c.method !== (st.info && st.info.primary) || c.time < lo || c.time > hi) continue;
      const x = u.valToPos(c.time, "x", true);
      const name = nameOf(c.segment);
      ctx.strokeStyle = name ? colour(st.behaviours[c.segment].behaviour) : "#fff";
      ctx.lineWidth = 2; ctx.beginPath(); ctx.moveTo(x, top); ctx.lineTo(x, top + h); ctx.stroke();
      ctx.fillStyle = "#fff";
      ctx.fillText(`${name || "#" + c.event} ${c.confidence.toFixed(2)}`, x + 3, top + 12 * devicePixelRatio);
    }
    ctx.restore();
  }

  function renderCuts() {
    const ol = $("cuts");
    const items = st.cuts.slice(-50).reverse().map((c) => {
      const name = nameOf(c.segment);
      const li = document.createElement("li");
      li.className = "cut" + (c.wire ? "" : " log");
      li.dataset.event = c.event; li.dataset.segment = c.segment;
      li.textContent = `t=${c.time.toFixed(2)} s  ${c.method} segment ${c.segment}  ` +
        `confidence ${c.confidence.toFixed(2)}` + (c.wire ? `  #${c.event}` : "  (log)") +
        (name ? `  → ${name}` : "");
      if (name) { const b = document.createElement("b"); b.className = "behaviour"; b.textContent = ""; li.appendChild(b); }
      return li;
    });
    ol.replaceChildren(...items);
  }

  function renderTimeline() {
    const tl = $("timeline");
    const segs = Object.values(st.behaviours).sort((a, b) => a.start - b.start);
    const end = Math.max(sessionNow(), 1);
    const bands = segs.map((b, i) => {
      const next = i + 1 < segs.length ? segs[i + 1].start : end;
      const d = document.createElement("div");
      d.className = "band"; d.dataset.behaviour = b.behaviour;
      d.style.left = (100 * b.start / end) + "%";
      d.style.width = (100 * Math.max(0, next - b.start) / end) + "%";
      d.style.background = colour(b.behaviour);
      d.textContent = b.name || b.behaviour;
      d.title = `${b.name || b.behaviour} (id ${b.behaviour}) from ${b.start.toFixed(1)} s, confidence ${b.confidence.toFixed(2)}`;
      return d;
    });
    tl.replaceChildren(...bands);
  }

  function row(k, v) { return `<tr><td>${k}</td><td>${v}</td></tr>`; }
  function esc(s) { return String(s).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" }[c])); }
  function renderHealth() {
    const h = st.health, info = st.info;
    if (!h || !info) return;
    const inp = Object.entries(h.input || {}).filter(([, v]) => v).map(([k, v]) => `${k} ${v}`).join(", ") || "none";
    const lat = h.latency_ms || [];
    const rec = h.recording ? `on: ${esc(h.recording)} (${((h.recording_bytes || 0) / 1e6).toFixed(1)} MB)` : "off";
    const mon = h.monitor || {};
    $("health-table").tBodies[0].innerHTML =
      row("frames/s", `<span id="fps">${h.fps.toFixed(1)}</span>`) + row("frames", h.frames) +
      row("dropped", `<span id="dropped">${h.dropped}</span>`) + row("bad input", esc(inp)) +
      row("latency p50 / p99", `${lat[0] == null ? "-" : lat[0].toFixed(2)} / ${lat[1] == null ? "-" : lat[1].toFixed(2)} ms`) +
      row("lag", `${h.lag_ms} ms`) + row("cuts", h.cuts) + row("recording", rec) +
      row("monitor", `${mon.clients || 0} page(s), ${(h.monitor_dropped || 0) + (mon.dropped || 0)} updates dropped`);
    const grid = $("sensors");
    if (grid.children.length !== info.joints.length) {
      grid.replaceChildren(...info.joints.map((n) => { const d = document.createElement("div"); d.className = "joint"; d.dataset.joint = n; d.textContent = n; return d; }));
    }
    let online = 0;
    info.joints.forEach((n, j) => {
      const d = grid.children[j], age = h.stale[j] || 0, lost = h.lost[j] || h.source_lost;
      d.className = "joint" + (lost ? " lost" : age > 0.1 ? " stale" : "");
      d.title = lost ? `${n}: lost (${age.toFixed(1)} s)` : age ? `${n}: last valid ${age.toFixed(2)} s ago` : `${n}: ok`;
      if (!lost) online++;
    });
    $("online").textContent = `${online} of ${info.joints.length} online`;
    $("targets").innerHTML = (h.targets || []).map((t) =>
      `<li class="${t.up ? "up" : "down"}">${esc(t.target)}: ${t.up ? "reachable" : "not reachable"}, sent ${t.sent || 0}, dropped ${t.dropped || 0}</li>`).join("") || "<li>none</li>";
  }

  function addEvents(events) {
    for (const ev of events) {
      if (ev.kind === "cut") { st.cuts.push(ev); if (st.cuts.length > 200) st.cuts.shift(); }
      else if (ev.kind === "behaviour") st.behaviours[ev.segment] = ev;
      else if (ev.kind === "end") st.ended = true;
    }
  }

  function onMessage(msg) {
    if (msg.type === "hello") {
      if (!msg.info.joints) return;            // the session is still starting
      st.info = msg.info; const hist = msg.history;
      st.stat = hist.stat; st.pre = hist.pre; st.gated = hist.gated; st.cuts = hist.cuts;
      st.behaviours = {}; for (const b of hist.behaviours) st.behaviours[b.segment] = b;
      st.health = hist.health; st.ended = msg.ended;
      $("source").textContent = `${msg.info.source} · ${msg.info.joints.length} sensors · ${msg.info.frame_rate} Hz`;
      $("stat-title").textContent = `${msg.info.statistic || "no detector statistic"} (last ${WINDOW_S} s), threshold ${msg.info.threshold}`;
      makePlot();
    } else if (msg.type === "batch") {
      st.stat.push(...msg.stat); st.pre.push(...msg.pre); st.gated.push(...msg.gated);
      addEvents(msg.events);
      if (msg.health) st.health = msg.health;
      if (msg.events.length) { renderCuts(); renderTimeline(); }
      if (msg.health) renderHealth();
    }
    st.now = msg.now; st.nowAt = performance.now();
    if (msg.type === "hello") { renderCuts(); renderTimeline(); renderHealth(); }
    if (st.ended) { $("conn").textContent = "session ended"; $("conn").className = "conn ended"; }
  }

  function frame() {
    if (plot) {
      const now = sessionNow(), lo = now - WINDOW_S;
      trim(st.stat, lo - 5); trim(st.pre, lo - 5); trim(st.gated, lo - 5);
      plot.batch(() => { plot.setData(data(), false); plot.setScale("x", { min: lo, max: now }); });
      $("clock").textContent = `t = ${now.toFixed(1)} s`;
    }
    setTimeout(() => requestAnimationFrame(frame), 33);    // about 30 redraws a second
  }

  function connect() {
    const ws = new WebSocket(`ws://${location.host}/ws`);
    ws.onopen = () => { $("conn").textContent = "live"; $("conn").className = "conn up"; };
    ws.onmessage = (e) => onMessage(JSON.parse(e.data));
    ws.onclose = () => {
      if (!st.ended) { $("conn").textContent = "disconnected, retrying…"; $("conn").className = "conn down"; setTimeout(connect, 1000); }
    };
  }
  window.rtsegMonitor = st;
  window.addEventListener("resize", () => { if (plot) plot.setSize({ width: $("chart").clientWidth, height: 260 }); });
  connect();
  requestAnimationFrame(frame);
})();
