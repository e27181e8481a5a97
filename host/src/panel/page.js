// tribo front panel: reads the panel's event stream, draws on canvases, sends the controls.
"use strict";
const $ = (id) => document.getElementById(id);
const client = Math.random().toString(36).slice(2) + Date.now().toString(36);
let state = null;          // the last state received
let run = null;            // {id, rate, blocks: Map(block -> {t0, dt, v, env, te}), tmax}
let dirty = true;
let streamUp = false;

function fmt(v, d) { return (v === null || v === undefined || !isFinite(v)) ? "—" : Number(v).toFixed(d); }

async function send(name, body) {
  try {
    const r = await fetch("api/" + name, {
      method: "POST",
      headers: { "Content-Type": "application/json", "X-Panel-Client": client },
      body: JSON.stringify(body || {}),
    });
    const a = await r.json();
    // A release while the plate is still settling: the panel asks first (`tribo run` waits).
    if (!a.ok && a.confirm) {
      if (window.confirm(a.text)) return send(name, Object.assign({}, body || {}, { confirm: true }));
      say(false, name + ": not sent (the plate is still settling)");
      return a;
    }
    say(a.ok, a.text);
    return a;
  } catch (e) {
    say(false, name + ": the panel does not answer (" + e + "); is `tribo panel` still running?");
    return { ok: false };
  }
}

function say(ok, text) {
  const m = $("message");
  m.textContent = text;
  m.className = ok ? "ok" : "bad";
}

$("heater-set").onclick = () => send("heater", { setpoint_c: parseFloat($("setpoint").value), ramp_c_per_min: parseFloat($("ramp").value) });
$("heater-off").onclick = () => send("heater-off");
$("configure").onclick = () => send("configure", { load_n: parseFloat($("load").value), rate_hz: parseInt($("rate").value, 10), max_duration_s: parseFloat($("maxdur").value) });
$("arm").onclick = () => send("arm");
$("release").onclick = () => send("release");
$("safe").onclick = () => send("safe");
$("claim").onclick = () => send("claim");

function controls() {
  const s = state;
  const mine = s && s.control === "you";
  const can = streamUp && s && s.connected && mine && !s.busy;
  for (const b of document.querySelectorAll("button.ctl")) b.disabled = !can;
  $("claim").style.display = (streamUp && s && s.control === "free") ? "" : "none";
  $("safe").disabled = false; // Safe always works (the answer says when no rig is there)
  const c = $("control");
  if (!s) c.textContent = "";
  else if (s.control === "you") c.textContent = "this page controls the rig";
  else if (s.control === "other") c.textContent = "viewing: another page controls the rig";
  else c.textContent = "nobody controls the rig: take control";
}

function onState(s) {
  state = s;
  const link = $("link");
  if (s.connected) { link.textContent = "connected"; link.className = "badge ok"; }
  else { link.textContent = "disconnected"; link.className = "badge bad"; }
  $("rig-id").textContent = s.serial ? "serial " + s.serial + " · firmware " + s.firmware : "";
  $("port").textContent = s.port || "—";
  $("link-error").textContent = s.connected ? "" : (s.link_error || "");
  const st = s.status;
  $("state").textContent = (s.connected && st) ? st.state : "—";
  $("state").title = st ? st.state_text : "";
  $("lease").textContent = st ? st.lease : "—";
  $("magnet").textContent = st ? (st.magnet_on ? "on (holding the pin)" : "off") : "—";
  $("fault").textContent = st ? (st.heater_fault ? st.heater_fault + "; " : "") + (st.last_fault || "none since boot") : "—";
  $("reset").textContent = st ? ((s.boot && s.boot !== st.reset) ? s.boot : st.reset) : "—";
  $("uptime").textContent = st ? st.uptime : "—";
  if (st) {
    $("plate").textContent = fmt(st.temp_c, 1) + " °C" + (st.setpoint_c !== null ? " → " + fmt(st.setpoint_c, 1) + " °C" : ", heater off");
  }
  const set = $("settled");
  if (st && st.setpoint_c !== null && s.settled_for_s !== null) {
    if (s.settled_for_s >= s.settle_s) { set.textContent = "settled"; set.className = "settled"; }
    else { set.textContent = "within ±" + s.settle_tol_c + " °C for " + fmt(s.settled_for_s, 0) + " of " + s.settle_s + " s"; set.className = "settling"; }
  } else if (st && st.setpoint_c !== null) { set.textContent = "settling"; set.className = "settling"; }
  else { set.textContent = ""; }
  if (s.message && s.message.n !== lastMessage) { lastMessage = s.message.n; say(s.message.ok, s.message.text); }
  const t = s.trace;
  if (t) {
    if (!run || run.id !== t.run) run = { id: t.run, rate: t.rate, blocks: new Map(), tmax: 0 };
    run.a0 = t.a0; run.lineGaps = t.line_gaps; run.lost = t.lost; run.expected = t.expected; run.ended = t.ended;
    $("trace-info").textContent = "run " + t.run + ": " + t.blocks + " blocks" + (t.ended ? ", ended (" + t.ended + ")" : ", recording…");
  }
  result(s.result);
  grid(s.grid);
  controls();
  dirty = true;
}
let lastMessage = null;

function result(r) {
  if (!r) { $("mu").textContent = "—"; $("result-table").textContent = ""; $("result-more").textContent = ""; return; }
  const h = r.host, o = r.onboard;
  $("mu").textContent = h ? "μ0 = " + fmt(h.mu0, 5) + " ± " + Number(h.mu0_se).toExponential(1) : (o ? "μ0 = " + fmt(o.mu0, 5) + " (on board)" : "no result");
  $("result-table").textContent = r.table;
  const more = $("result-more");
  more.textContent = "";
  const p = document.createElement("div");
  p.textContent = "run " + r.run + ": " + r.completeness + (r.incomplete ? " — " + r.incomplete : "");
  more.appendChild(p);
  if (typeof r.report === "string") {
    const a = document.createElement("a"); a.href = r.report.replace(/^\//, ""); a.id = "report-link"; a.textContent = "the run's report"; a.target = "_blank";
    more.appendChild(a);
  } else if (r.report && r.report.error) {
    const d = document.createElement("div"); d.textContent = "report: " + r.report.error; more.appendChild(d);
  } else {
    const d = document.createElement("div"); d.textContent = "writing the report…"; more.appendChild(d);
  }
}

function grid(g) {
  const el = $("grid");
  // Runs the grid cannot hold (damaged, incomplete): named, with how to repair each.
  const left = (g && g.left_out) || [];
  const leftOut = () => {
    if (!left.length) return;
    const d = document.createElement("div");
    d.id = "grid-left-out";
    d.className = "bad";
    d.textContent = left.length + " run" + (left.length === 1 ? "" : "s") + " left out of the grid: " +
      left.map((l) => l.run + " (" + l.why + ")").join("; ");
    el.appendChild(d);
  };
  if (!g || !g.loads || g.loads.length === 0) { el.textContent = "no complete run in the store yet"; leftOut(); return; }
  let h = "<table class='grid'><tr><th>load \\ temp</th>" + g.temps.map((t) => "<th>" + t + "</th>").join("") + "</tr>";
  g.loads.forEach((l, i) => {
    h += "<tr><th>" + l + "</th>" + g.cells[i].map((c) => "<td>" + (c ? fmt(c.mean, 5) + (c.sd !== null ? " ± " + fmt(c.sd, 5) : "") + " (" + c.n + ")" : "—") + "</td>").join("") + "</tr>";
  });
  el.innerHTML = h + "</table>";
  leftOut();
}

function onTrace(t) {
  if (!run || run.id !== t.run) run = { id: t.run, rate: 0, blocks: new Map(), tmax: 0 };
  for (const b of t.blocks) {
    run.blocks.set(b.b, b);
    run.tmax = Math.max(run.tmax, b.te);
  }
  dirty = true;
}

// ---- drawing ----
function canvas(id) {
  const c = $(id), r = window.devicePixelRatio || 1, w = c.clientWidth, h = c.height / 1;
  if (c.width !== Math.round(w * r)) { c.width = Math.round(w * r); }
  const ctx = c.getContext("2d");
  ctx.setTransform(c.width / w, 0, 0, 1, 0, 0);
  ctx.clearRect(0, 0, w, c.height);
  return { ctx, w, h: c.height };
}

// Round ticks inside [lo, hi]: about n of them, a step of 1, 2 or 5 × 10^k, each a multiple of
// the step, with the digits the step needs ({values, digits}).
function niceTicks(lo, hi, n) {
  if (!(isFinite(lo) && isFinite(hi)) || hi <= lo) return { values: [lo], digits: 0 };
  const raw = (hi - lo) / Math.max(1, n);
  const p = Math.pow(10, Math.floor(Math.log10(raw)));
  const m = raw / p;
  const step = (m < 1.5 ? 1 : m < 3 ? 2 : m < 7 ? 5 : 10) * p;
  const digits = Math.max(0, -Math.floor(Math.log10(step) + 1e-9));
  const values = [];
  for (let k = Math.ceil(lo / step - 1e-9); k * step <= hi + step * 1e-9; k++) {
    values.push(Number((k * step).toFixed(digits)));
  }
  return { values, digits };
}
window.niceTicks = niceTicks;

function axes(g, x0, x1, y0, y1, unit) {
  const { ctx, w, h } = g, L = 48, B = 16, T = 14;
  const X = (x) => L + (x - x0) / (x1 - x0 || 1) * (w - L - 6);
  const Y = (y) => h - B - (y - y0) / (y1 - y0 || 1) * (h - B - T);
  ctx.strokeStyle = "#ccc"; ctx.fillStyle = "#6b7280"; ctx.font = "10px system-ui"; ctx.lineWidth = 1;
  const ys = niceTicks(y0, y1, 4);
  for (const y of ys.values) {
    ctx.beginPath(); ctx.moveTo(L, Y(y)); ctx.lineTo(w - 6, Y(y)); ctx.stroke();
    ctx.fillText(y.toFixed(ys.digits), 2, Y(y) + 3);
  }
  ctx.fillText(unit, L, 10);
  const xs = niceTicks(x0, x1, 5);
  for (const x of xs.values) ctx.fillText(x.toFixed(xs.digits) + " s", X(x) - 10, h - 3);
  window.panelTicks[unit] = ys.values.map((v) => v.toFixed(ys.digits));
  return { X, Y };
}
// The ticks last drawn, per unit (read by the browser tests).
window.panelTicks = {};

function drawPlate() {
  const g = canvas("c-plate");
  const temps = state ? state.temps : [];
  if (!temps.length) return;
  let lo = Infinity, hi = -Infinity;
  for (const [, c, sp] of temps) { if (c !== null) { lo = Math.min(lo, c); hi = Math.max(hi, c); } if (sp !== null) { lo = Math.min(lo, sp); hi = Math.max(hi, sp); } }
  lo = Math.floor(lo - 1); hi = Math.ceil(hi + 1);
  const t0 = Math.min(-60, temps[0][0]);
  const { X, Y } = axes(g, t0, 0, lo, hi, "°C");
  const ctx = g.ctx;
  ctx.strokeStyle = "#b26a00"; ctx.setLineDash([5, 4]); ctx.beginPath();
  let on = false;
  for (const [t, , sp] of temps) { if (sp === null) { on = false; continue; } if (on) ctx.lineTo(X(t), Y(sp)); else ctx.moveTo(X(t), Y(sp)); on = true; }
  ctx.stroke(); ctx.setLineDash([]);
  ctx.strokeStyle = "#c62828"; ctx.lineWidth = 2; ctx.beginPath(); on = false;
  for (const [t, c] of temps) { if (c === null) { on = false; continue; } if (on) ctx.lineTo(X(t), Y(c)); else ctx.moveTo(X(t), Y(c)); on = true; }
  ctx.stroke(); ctx.lineWidth = 1;
}

// Draws channel k (0 x, 1 v, 2 force, 3 ECR) as min–max columns per pixel, in block order, with the
// envelope for the displacement and the gaps shaded.
function drawChannel(id, k, scale, unit, envelope) {
  const g = canvas(id);
  if (!run || run.blocks.size === 0) return;
  const keys = [...run.blocks.keys()].sort((a, b) => a - b);
  let lo = Infinity, hi = -Infinity;
  for (const key of keys) { const b = run.blocks.get(key); for (let i = 2 * k; i < b.v.length; i += 8) { const a = b.v[i], c = b.v[i + 1]; if (a !== null) { lo = Math.min(lo, a * scale); hi = Math.max(hi, c * scale); } } }
  if (!isFinite(lo)) { g.ctx.fillStyle = "#6b7280"; g.ctx.fillText("not recorded in this run", 60, 30); return; }
  if (envelope && run.a0) { lo = Math.min(lo, -run.a0 * scale); hi = Math.max(hi, run.a0 * scale); }
  const pad = (hi - lo) * 0.05 || 1e-9;
  const tmax = Math.max(run.tmax, 0.5);
  const { X, Y } = axes(g, 0, tmax, lo - pad, hi + pad, unit);
  const ctx = g.ctx;
  // Gaps: blocks not (yet) received before the last one (lost on the line, fetched at the end),
  // and samples the rig itself lost.
  const blockS = 64 / (run.rate || 10000);
  ctx.fillStyle = "rgba(198,40,40,0.18)";
  let prev = -1;
  for (const key of keys) { if (key > prev + 1) ctx.fillRect(X((prev + 1) * blockS), 0, Math.max(2, X(key * blockS) - X((prev + 1) * blockS)), g.h - 16); prev = key; }
  ctx.fillStyle = "rgba(120,120,120,0.25)";
  for (const [a, b] of (run.lost || [])) ctx.fillRect(X(a), 0, Math.max(2, X(b) - X(a)), g.h - 16);
  // Min–max per pixel column.
  const cols = new Map();
  for (const key of keys) {
    const b = run.blocks.get(key);
    for (let j = 0, i = 2 * k; i < b.v.length; i += 8, j++) {
      const a = b.v[i], c = b.v[i + 1]; if (a === null) continue;
      const px = Math.round(X(b.t0 + j * b.dt));
      const m = cols.get(px);
      if (m) { m[0] = Math.min(m[0], a); m[1] = Math.max(m[1], c); } else cols.set(px, [a, c]);
    }
  }
  panelStats.maxColumns = Math.max(panelStats.maxColumns, cols.size);
  panelStats.maxWidth = Math.max(panelStats.maxWidth, g.w);
  ctx.strokeStyle = "#1f5fbf"; ctx.beginPath();
  for (const [px, [a, c]] of cols) { ctx.moveTo(px + 0.5, Y(a * scale)); ctx.lineTo(px + 0.5, Y(c * scale) - 0.5); }
  ctx.stroke();
  if (envelope) {
    ctx.strokeStyle = "#1a7f37"; ctx.lineWidth = 1.5;
    for (const sign of [1, -1]) {
      ctx.beginPath(); let on = false;
      for (const key of keys) { const b = run.blocks.get(key); if (b.env === null) { on = false; continue; } const x = X(b.te), y = Y(sign * b.env * scale); if (on) ctx.lineTo(x, y); else ctx.moveTo(x, y); on = true; }
      ctx.stroke();
    }
    ctx.lineWidth = 1;
  }
}

// How long drawing takes, and the most min–max columns one trace drew against the widest canvas
// (read by the browser tests): the traces are drawn a column per pixel, whatever the samples.
window.panelStats = { frames: 0, maxDrawMs: 0, totalDrawMs: 0, maxColumns: 0, maxWidth: 0 };
function draw() {
  if (dirty) {
    dirty = false;
    const t0 = performance.now();
    drawPlate();
    drawChannel("c-x", 0, 1e6, "µm", true);
    drawChannel("c-v", 1, 1e3, "mm/s", false);
    drawChannel("c-f", 2, 1e3, "mN", false);
    drawChannel("c-ecr", 3, 1, "V", false);
    const ms = performance.now() - t0;
    panelStats.frames++; panelStats.totalDrawMs += ms; panelStats.maxDrawMs = Math.max(panelStats.maxDrawMs, ms);
  }
  requestAnimationFrame(draw);
}
window.addEventListener("resize", () => { dirty = true; });

// ---- the event stream ----
function connect() {
  const es = new EventSource("events?client=" + client);
  es.addEventListener("open", () => { streamUp = true; controls(); });
  es.addEventListener("state", (e) => onState(JSON.parse(e.data)));
  es.addEventListener("trace", (e) => onTrace(JSON.parse(e.data)));
  es.addEventListener("error", () => {
    streamUp = false;
    const link = $("link"); link.textContent = "panel not reachable"; link.className = "badge bad";
    controls();
  });
}
connect();
requestAnimationFrame(draw);
