// The watch page's script (served as /page.js: the Content-Security-Policy allows scripts
// from the server only).  Everything from the run directory reaches the page through
// textContent or esc(): a step result or an event is data, never markup.
"use strict";
const token = new URLSearchParams(location.search).get("token") || "";
const $ = (id) => document.getElementById(id);
let state = null, stopSent = false;

const PARAMS = [
  {key: "F_s_N", label: "F_s", unit: "N", scale: 1},
  {key: "x_s_m", label: "x_s", unit: "µm", scale: 1e6},
  {key: "n", label: "n", unit: "", scale: 1},
  {key: "mass_kg", label: "m", unit: "kg", scale: 1},
];
const BAD_EVENTS = new Set(["abort", "error", "instrument_error", "interrupted", "lock_lost", "not_locked"]);

function esc(s) { return String(s ?? "").replace(/[&<>"']/g, (c) => ({"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;"}[c])); }
function num(v, digits = 3) {   // never an overflowed or absurd number (bench/numbers.py)
  if (v === null || v === undefined || !isFinite(v)) return "–";
  const a = Math.abs(Number(v));
  return (a >= 1e30 || (a !== 0 && a <= 1e-30)) ? "absurd" : Number(v).toPrecision(digits);
}
function dur(s) {
  if (s === null || s === undefined || !isFinite(s)) return "–";
  s = Math.round(s);
  const h = Math.floor(s / 3600), m = Math.floor(s % 3600 / 60), r = s % 60;
  return h ? `${h} h ${m} min` : m ? `${m} min ${r} s` : `${r} s`;
}
function pct2(v) { return (v === null || v === undefined || !isFinite(v)) ? "–" : (100 * v).toFixed(2) + " %"; }
function pct(v) { return (v === null || v === undefined || !isFinite(v)) ? "–" : (100 * v).toFixed(1) + " %"; }
function levelColour(i, n) {           // viridis-like ramp from low to high force
  const stops = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]];
  const t = n > 1 ? i / (n - 1) : 0, k = Math.min(stops.length - 2, Math.floor(t * (stops.length - 1)));
  const f = t * (stops.length - 1) - k, c = stops[k].map((a, j) => Math.round(a + f * (stops[k + 1][j] - a)));
  return `rgb(${c[0] * 0.9 | 0},${c[1] * 0.9 | 0},${c[2] * 0.9 | 0})`;
}

function renderHeader(s) {
  $("title").textContent = s.name || "bench watch";
  $("subtitle").textContent = [s.rig && `rig: ${s.rig}${s.simulated ? " (simulated)" : ""}`, s.run_dir].filter(Boolean).join(" · ");
  const st = $("status");
  const shown = s.process_gone ? "stalled" : s.stop_pending && s.status === "running" ? "stopping" : s.status;
  st.textContent = shown;
  st.className = "badge " + (shown || "");
  document.title = `${s.status} · ${s.name || "bench watch"}`;
  const stop = $("stop");
  stop.disabled = !token || s.status !== "running" || s.process_gone || s.stop_pending || stopSent;
  $("message").textContent = s.process_gone ? "the run's process is gone (killed?): bench resume continues it" : $("message").textContent;
  stop.title = !token ? "open the URL printed by bench (with ?token=...) to enable stop"
                      : "ramp down, output off, run recorded as interrupted (as Ctrl-C)";
}

function renderProgress(s) {
  const p = s.progress || {};
  const bar = $("bar");
  bar.className = "bar " + (s.status === "completed" ? "completed" : s.status === "running" ? "" : "stopped");
  bar.firstElementChild.style.width = p.fraction ? (100 * Math.min(1, p.fraction)).toFixed(1) + "%" : "0";
  const end = s.status === "running" ? Date.now() / 1000 : (s.ended ? Date.parse(s.ended) / 1000 : null);
  const elapsed = p.started_s && end ? end - p.started_s : null;
  const parts = [`${p.done ?? 0} / ${p.total ?? "?"} steps (${pct(p.fraction)})`,
                 `elapsed ${dur(elapsed)}${s.status === "running" ? "" : " (this session)"}`];
  if (p.per_step_s) parts.push(`${num(p.per_step_s, 2)} s per step`);
  if (s.status === "running") parts.push(`ETA ${p.eta_s === null || p.eta_s === undefined ? "–" : dur(p.eta_s)}`);
  else if (s.ended) parts.push(`ended ${new Date(s.ended).toLocaleString()}`);
  $("progress-text").textContent = parts.join(" · ");
}

function renderCurrent(s) {
  const rows = [];
  const n = s.next_step, l = s.last_step;
  const unit = esc(s.level_unit || "N");
  if (n) rows.push(["now", `<b>${num(n.level_N)} ${unit}</b> at <b>${num(n.freq_Hz, 4)} Hz</b> (${esc(n.direction)})`]);
  else if (s.status !== "running") rows.push(["now", `<span class="muted">nothing: the run is ${esc(s.status)}</span>`]);
  if (l) {
    rows.push(["last done", `${num(l.level_N)} ${unit} at ${num(l.freq_Hz, 4)} Hz (${esc(l.direction)}) <span class="muted">${esc(l.key)}</span>`]);
    const ok = l.force_converged === false ? ' <span class="sev-warn">not within tolerance</span>' : "";
    if (unit === "N") rows.push(["force", `${num(l.force_N, 4)} N, error ${pct2(l.force_error)}${ok}`]);
    else rows.push([esc(s.level_quantity || "response"), `error ${pct2(l.control_error)}${ok}; the force it needed ${num(l.force_N, 4)} N`]);
    rows.push(["control iterations", esc(l.control_iterations ?? "–")]);
    rows.push(["THD", `force ${pct(l.thd_force)} · acceleration ${pct(l.thd_accel)} · displacement ${pct(l.thd_disp)}`]);
    rows.push(["drive", `${num(l.drive_V)} V amplitude`]);
  }
  $("current").innerHTML = rows.map(([k, v]) => `<tr><th>${k}</th><td>${v}</td></tr>`).join("");
}

function renderIdent(s) {
  const id = s.identification || {history: []};
  const est = id.final && id.final.values ? id.final : id.history[id.history.length - 1];
  $("ident-note").textContent = id.final && id.final.values
    ? `(${id.final.source || "final fit"} over all steps${id.final.misfit ? "; the model does not fit" : ""})`
    : est ? `(online, after ${est.steps_done} steps${est.misfit ? "; the model does not fit" : ""})` : "(no estimate yet)";
  let html = "<tr><th>parameter</th><th class='num'>estimate</th><th class='num'>95 % interval</th><th class='num'>start guess</th></tr>";
  for (const p of PARAMS) {
    const v = est ? est.values[p.key] * p.scale : null;
    const lo = est ? est.low[p.key] * p.scale : null, hi = est ? est.high[p.key] * p.scale : null;
    const g = id.expected && id.expected[p.key] !== null && id.expected[p.key] !== undefined ? id.expected[p.key] * p.scale : null;
    html += `<tr><td>${p.label}${p.unit ? " (" + p.unit + ")" : ""}</td><td class="num">${num(v, 4)}</td>` +
            `<td class="num">[${num(lo)}, ${num(hi)}]</td><td class="num muted">${num(g)}</td></tr>`;
  }
  if (id.final && id.final.error) html += `<tr><td colspan="4" class="sev-bad">final fit failed: ${esc(id.final.error)}</td></tr>`;
  for (const w of (id.final && id.final.warnings) || id.latest_warnings || [])
    html += `<tr><td colspan="4" class="sev-warn">${esc(w)}</td></tr>`;
  $("ident").innerHTML = html;
}

function renderModes(s) {
  const ms = s.modes || [];
  let html = `<tr><th>mode</th><th class='num'>level (${esc(s.level_unit || "N")})</th>` + "<th>status</th><th class='num'>resonance (Hz)</th>" +
             "<th class='num'>95 % interval</th><th class='num'>damping ratio</th><th class='num'>95 % interval</th></tr>";
  for (const m of ms) {
    const status = m.status === "below grid" || m.status === "above grid"
      ? `${m.status}: at or ${m.status === "below grid" ? "below" : "above"} ${num(m.edge_Hz, 4)} Hz` : m.status;
    html += `<tr><td>${esc(m.mode)}</td><td class="num">${num(m.level_N)}</td><td>${esc(status)}</td>` +
            `<td class="num">${num(m.resonance_Hz, 5)}</td><td class="num">[${num(m.resonance_low_Hz, 5)}, ${num(m.resonance_high_Hz, 5)}]</td>` +
            `<td class="num">${pct2(m.damping_ratio)}</td><td class="num">[${pct2(m.damping_ratio_low)}, ${pct2(m.damping_ratio_high)}]</td></tr>`;
  }
  if (!ms.length) html += "<tr><td colspan='7' class='muted'>none yet: a level needs at least 3 steps</td></tr>";
  $("modes").innerHTML = html;
}

function renderLock(s) {
  const k = s.lock;
  $("lockcard").hidden = !k;
  if (!k) return;
  const amp = (v) => k.response === "accel" ? `${num(v, 4)} m/s²` : `${num(1e6 * v, 4)} µm`;
  const b = k.latest;
  $("lockstate").innerHTML = b
    ? `latest block at ${num(b.level_N)} N: <b>${num(b.freq_Hz, 5)} Hz</b>, phase error <b>${num(b.phase_error_deg, 3)} deg</b> ` +
      `(target ${num(k.phase_target_deg)} deg, band ±${num(k.phase_band_deg)}), amplitude ${amp(b.amplitude)}, ` +
      `force ${num(b.force_N, 4)} N, ${esc(b.settled_periods)} periods in band (${esc(k.settle_periods)} needed)`
    : "<span class='muted'>no block yet</span>";
  let html = "<tr><th class='num'>level (N)</th><th class='num'>frequency (Hz)</th><th class='num'>amplitude (µm)</th>" +
             "<th class='num'>phase error (deg)</th><th class='num'>damping ratio</th><th>locked</th><th class='num'>periods</th></tr>";
  for (const p of k.points)
    html += `<tr><td class="num">${num(p.level_N)}</td><td class="num">${num(p.frequency_Hz, 5)}</td><td class="num">${num(1e6 * p.amplitude_m, 4)}</td>` +
            `<td class="num">${num(p.phase_error_deg, 3)}</td><td class="num">${pct2(p.damping_ratio)}</td>` +
            `<td class="${p.locked ? "" : "sev-bad"}">${p.locked ? "yes" : "no: " + esc(p.why)}</td><td class="num">${esc(p.periods)}</td></tr>`;
  if (!k.points.length) html += "<tr><td colspan='7' class='muted'>no point yet</td></tr>";
  $("lockpoints").innerHTML = html;
}

const FONT = {family: "system-ui, sans-serif", size: 12};

function renderCompliance(s) {
  const series = s.compliance || [];
  const nLevels = Math.max(1, (s.levels_N || []).length, ...series.map((c) => c.level_index + 1));
  const traces = [];
  let points = 0;
  for (const c of series) {
    const colour = levelColour(c.level_index, nLevels), dash = c.direction === "down" ? "dash" : "solid";
    const name = `${num(c.level_N)} ${esc(s.level_unit || "N")}${c.direction ? " " + esc(c.direction) : ""}`;
    const marker = {color: colour, size: 6, symbol: c.direction === "down" ? "triangle-down" : "circle",
                    line: {width: c.converged.map((ok) => ok ? 0 : 2), color: "#c62828"}};
    points += c.freq_Hz.length;
    traces.push({x: c.freq_Hz, y: c.abs_m_per_N, name, legendgroup: name, mode: "lines+markers", marker,
                 line: {color: colour, dash, width: 1.5}, customdata: (c.key || []).map(esc),
                 hovertemplate: "%{customdata}<br>%{x:.4g} Hz<br>|x/P| %{y:.3e} m/N<extra>" + name + "</extra>"});
    traces.push({x: c.freq_Hz, y: c.phase_deg, name, legendgroup: name, showlegend: false, mode: "lines+markers",
                 xaxis: "x", yaxis: "y2", marker, line: {color: colour, dash, width: 1.5}, customdata: (c.key || []).map(esc),
                 hovertemplate: "%{customdata}<br>%{x:.4g} Hz<br>phase %{y:.1f}°<extra>" + name + "</extra>"});
  }
  $("points").textContent = `(${points} steps)`;
  $("compliance").dataset.points = String(points);
  const layout = {
    uirevision: "keep", font: FONT, margin: {l: 70, r: 10, t: 34, b: 45},
    legend: {title: {text: "force level"}, font: {size: 11}},
    xaxis: {type: "log", title: {text: "frequency (Hz)"}, anchor: "y2", gridcolor: "#eee"},
    yaxis: {type: "log", title: {text: "|x/P| (m/N)"}, domain: [0.36, 1], exponentformat: "power", gridcolor: "#eee"},
    yaxis2: {title: {text: "phase (°)"}, domain: [0, 0.28], autorange: true, dtick: 45, gridcolor: "#eee"},
    annotations: points ? [] : [{text: "no step completed yet", showarrow: false, xref: "paper", yref: "paper", x: 0.5, y: 0.7}],
  };
  Plotly.react("compliance", traces, layout, {displaylogo: false, responsive: true});
  renderAccelerance(s, nLevels);
}

function renderAccelerance(s, nLevels) {
  // the drive-point accelerance |A1/F1|: where the pitching mode is clearest (1/m above the feed mode)
  const traces = [];
  let points = 0;
  for (const c of s.compliance || []) {
    const colour = levelColour(c.level_index, nLevels), dash = c.direction === "down" ? "dash" : "solid";
    const name = `${num(c.level_N)} ${esc(s.level_unit || "N")}${c.direction ? " " + esc(c.direction) : ""}`;
    const y = c.accel_abs_per_kg || [];
    points += y.filter((v) => v !== null && isFinite(v)).length;
    traces.push({x: c.freq_Hz, y, name, mode: "lines+markers", line: {color: colour, dash, width: 1.5},
                 marker: {color: colour, size: 6, symbol: c.direction === "down" ? "triangle-down" : "circle"},
                 customdata: (c.key || []).map(esc),
                 hovertemplate: "%{customdata}<br>%{x:.4g} Hz<br>|A/P| %{y:.3e} 1/kg<extra>" + name + "</extra>"});
  }
  $("accelerance").dataset.points = String(points);
  const layout = {uirevision: "keep", font: FONT, margin: {l: 70, r: 10, t: 20, b: 45},
    legend: {title: {text: "force level"}, font: {size: 11}},
    xaxis: {type: "log", title: {text: "frequency (Hz)"}, gridcolor: "#eee"},
    yaxis: {type: "log", title: {text: "|A1/F1| (1/kg)"}, exponentformat: "power", gridcolor: "#eee"}};
  Plotly.react("accelerance", traces, layout, {displaylogo: false, responsive: true});
}

function valueAxis(y, log) {
  // the range the estimates span (not their early, very wide intervals, which run off it)
  const v = y.filter((a) => isFinite(a) && (!log || a > 0));
  if (!v.length) return {type: log ? "log" : "linear"};
  const f = log ? Math.log10 : (a) => a;
  let lo = f(Math.min(...v)), hi = f(Math.max(...v));
  const pad = Math.max(0.15 * (hi - lo), log ? 0.05 : 0.05 * Math.abs(hi) || 0.05);
  return {type: log ? "log" : "linear", range: [lo - pad, hi + pad], dtick: log ? "D2" : undefined, exponentformat: "power"};
}

function renderIdentPlot(s) {
  const hist = (s.identification || {}).history || [];
  const x = hist.map((h) => h.steps_done);
  const traces = [], layout = {uirevision: "keep", font: FONT, margin: {l: 55, r: 10, t: 25, b: 40}, showlegend: false,
                               annotations: []};
  PARAMS.forEach((p, i) => {
    const ax = i ? String(i + 1) : "";
    const y = hist.map((h) => h.values[p.key] * p.scale);
    traces.push({x, y, xaxis: "x" + ax, yaxis: "y" + ax, mode: "lines+markers", marker: {size: 4, color: "#1565c0"},
                 line: {color: "#1565c0", width: 1},
                 error_y: {type: "data", symmetric: false, array: hist.map((h, k) => h.high[p.key] * p.scale - y[k]),
                           arrayminus: hist.map((h, k) => y[k] - h.low[p.key] * p.scale), color: "#90b4e0", thickness: 1, width: 0},
                 hovertemplate: `${p.label} %{y:.4g} ${p.unit}<br>after %{x} steps<extra></extra>`});
    const w = 1 / PARAMS.length, x0 = i * w + 0.015, x1 = (i + 1) * w - 0.025;
    layout["xaxis" + ax] = {domain: [x0, x1], anchor: "y" + ax, title: {text: "steps done"}, gridcolor: "#eee"};
    layout["yaxis" + ax] = Object.assign({anchor: "x" + ax, gridcolor: "#eee"}, valueAxis(y, p.key !== "n"));
    layout.annotations.push({text: `<b>${p.label}</b>${p.unit ? " (" + p.unit + ")" : ""}`, showarrow: false,
                             xref: "paper", yref: "paper", x: (x0 + x1) / 2, y: 1.07, xanchor: "center"});
  });
  Plotly.react("identplot", traces, layout, {displaylogo: false, responsive: true, displayModeBar: false});
}

function severity(e) {
  if (BAD_EVENTS.has(e.event) || (e.event === "output_off" && e.confirmed === false)) return "sev-bad";
  if (e.event === "end" && e.status !== "completed") return "sev-bad";
  return "";
}

function renderEvents(s) {
  const rows = [];
  for (const e of (s.events || [])) {
    const {time, event, ...rest} = e;
    const detail = Object.entries(rest).map(([k, v]) => `${k}: ${typeof v === "object" ? JSON.stringify(v) : v}`).join(", ");
    rows.push([time ? esc(new Date(time).toLocaleTimeString()) : "", `<span class="${severity(e)}">${esc(event)}</span>`, esc(detail)]);
  }
  for (const w of (s.warnings || []))
    rows.push(["", `<span class="sev-warn">${esc(w.source)} warning</span>`, esc(w.text)]);
  if (s.quiet_events) rows.push(["", "<span class='muted'>sensor</span>", `<span class="muted">${esc(s.quiet_events)} gap checks (not listed)</span>`]);
  $("events").innerHTML = rows.length ? "<table>" + rows.map((r) => `<tr><td>${r[0]}</td><td>${r[1]}</td><td>${r[2]}</td></tr>`).join("") + "</table>"
                                      : "<span class='muted'>none</span>";
}

function render(s) {
  state = s;
  renderHeader(s);
  renderProgress(s);
  if (s.status === "waiting" || s.status === "unreadable") { $("current").innerHTML = `<tr><td>${esc(s.message)}</td></tr>`; return; }
  renderCurrent(s);
  renderIdent(s);
  renderCompliance(s);
  renderModes(s);
  renderLock(s);
  renderIdentPlot(s);
  renderEvents(s);
}

function locked(why) {
  // the run's data need the link's token: say so where the technician looks, and stop trying
  const a = $("access");
  a.innerHTML = `<b>No access to the run's data.</b> ${esc(why)}. It looks like ` +
    `<code>http://127.0.0.1:PORT/?token=...</code>; the token changes each time the page is started.`;
  a.hidden = false;
  $("status").textContent = "token needed";
  $("status").className = "badge locked";
  $("conn").textContent = "not connected";
  $("conn").className = "lost";
  $("stop").disabled = true;
  $("stop").title = "open the URL printed by bench (with ?token=...) to enable stop";
}

async function refused(es) {
  // an event stream that ended on an HTTP error: ask the state endpoint why
  try {
    const r = await fetch("/api/state?token=" + encodeURIComponent(token));
    if (r.status === 403) { if (es) es.close(); locked((await r.json()).error || "the server refused this link's token"); return; }
  } catch (err) { /* the server is away: keep waiting for it */ }
  setTimeout(connect, 2000);
}

function connect() {
  if (!token) { refused(null); return; }           // the server says what is needed
  const es = new EventSource("/api/stream?token=" + encodeURIComponent(token));
  es.onopen = () => { $("conn").textContent = "live"; $("conn").className = ""; };
  es.onmessage = (ev) => { try { render(JSON.parse(ev.data)); } catch (err) { console.error(err); } };
  es.addEventListener("bye", () => {
    $("conn").textContent = "server closed: final state shown";
    $("conn").title = "the page reconnects if a server comes back on this address";
    $("conn").className = "lost";
  });
  es.onerror = () => {
    if (es.readyState === EventSource.CLOSED) { refused(es); return; }   // an HTTP error, not a lost link
    if (es.readyState !== EventSource.OPEN && !$("conn").textContent.startsWith("server closed")) {
      $("conn").textContent = "connection lost: showing the last state, reconnecting…";
      $("conn").className = "lost";
    }
  };
}

$("stop").addEventListener("click", async () => {
  const stop = $("stop");
  stop.disabled = true;
  $("message").textContent = "";
  try {
    const r = await fetch("/api/stop", {method: "POST", headers: {"X-Stop-Token": token}});
    const body = await r.json().catch(() => ({}));
    if (r.status === 202) { stopSent = true; stop.textContent = "Stop requested"; }
    else { $("message").textContent = body.error || `stop refused (${r.status})`; stop.disabled = false; }
  } catch (err) {
    $("message").textContent = "could not reach the server: " + err;
    stop.disabled = false;
  }
});

setInterval(() => { if (state && state.status === "running") renderProgress(state); }, 1000);
connect();
