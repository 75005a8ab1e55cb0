// nearsub view: draws the scene and frames the server pushes over /ws. Plain canvas, no libraries.
// window.nearsub exposes what was drawn last (tests read it): drawn = {step, t, x, y, psi} of the
// selected vehicle, drawnAll = {name: {step, t, x, y, psi}} of every vehicle, labels = {name: its label}.
"use strict";

const EVENT_STYLE = {
  collision: { color: "#ff4d4d", shape: "x" },
  close_call: { color: "#ffa31a", shape: "circle" },
  large_stray: { color: "#c77dff", shape: "triangle" },
  waypoint: { color: "#5cff8d", shape: "star" },
  swap: { color: "#4dd2ff", shape: "diamond" },
};

// Trail and body colours of the vehicles in name order; the first keeps the single UUV's look.
const VEHICLE_COLOURS = [["#ff5c5c", "#ffd23f"], ["#4dd2ff", "#9be7ff"], ["#5cff8d", "#b6ffcc"],
  ["#c77dff", "#e2c2ff"], ["#ffa31a", "#ffd08a"]];

const state = {
  scene: null, frame: null, drawn: null, drawnAll: {}, labels: {}, gridLabels: null, history: [], replies: [],
  selected: null,
  view: { cx: 0, cy: 0, scale: 4 }, follow: false, fitted: false, socket: null,
};
window.nearsub = state;

const canvas = document.getElementById("map");
const ctx = canvas.getContext("2d");
const $ = (id) => document.getElementById(id);

function send(message) {
  if (state.socket && state.socket.readyState === WebSocket.OPEN) state.socket.send(JSON.stringify(message));
}

function connect() {
  const socket = new WebSocket(`ws://${location.host}/ws${location.search}`);
  state.socket = socket;
  socket.onmessage = (event) => {
    const message = JSON.parse(event.data);
    if (message.type === "scene") onScene(message);
    else if (message.type === "frame") onFrame(message);
    else if (message.type === "reply") onReply(message);
  };
  socket.onclose = () => {
    $("st-state").textContent = "disconnected";
    $("st-state").className = "ended";
    setTimeout(connect, 2000);
  };
}

function onScene(scene) {
  state.scene = scene;
  $("title").textContent = `nearsub ${scene.mode === "replay" ? "replay" : "live"}: ${scene.community || scene.source}`;
  $("frame-label").textContent = scene.frame;
  const arrow = scene.band.rects.length ? `. Arrow: one UUV length = ${scene.force_reference.toFixed(0)} N.` : ".";
  $("band-note").textContent = scene.band.note + arrow;
  const select = $("behaviour");
  select.innerHTML = "";
  for (const name of scene.behaviours) {
    const option = document.createElement("option");
    option.textContent = name;
    option.selected = name === scene.behaviour;
    select.appendChild(option);
  }
  if (scene.warp !== null) $("warp-input").value = scene.warp;
  const replay = scene.mode === "replay";
  $("live-controls").hidden = replay || !scene.control; // a read-only page only watches
  $("timeline").hidden = !replay || !scene.control;
  if (replay) {
    $("scrub").min = scene.range[0];
    $("scrub").max = scene.range[1];
    const at = new URLSearchParams(window.location.search).get("t");  // ?t=SECONDS: open the replay there
    if (at !== null && Number.isFinite(Number(at))) send({ cmd: "seek", t: Number(at) });
  }
  state.fitted = false;
  resize();
}

// Every vehicle of a frame (a server without `vehicles` sends the one); the selected one first
// picks the panel's forces and status and what Follow follows.
function vehiclesOf(frame) {
  if (frame.vehicles) return frame.vehicles;
  return [{ name: frame.vehicle ? frame.vehicle.name : "", vehicle: frame.vehicle, trail: frame.trail, forces: frame.forces }];
}

function selectedOf(frame) {
  const all = vehiclesOf(frame);
  return all.find((v) => v.name === state.selected) || all.find((v) => frame.vehicle && v.name === frame.vehicle.name) || all[0];
}

function updateVehicleList(frame) {
  const names = vehiclesOf(frame).map((v) => v.name);
  const select = $("vehicle");
  $("vehicle-row").hidden = names.length < 2;
  if (select.dataset.names === names.join(",")) return;
  select.dataset.names = names.join(",");
  select.innerHTML = "";
  for (const name of names) {
    const option = document.createElement("option");
    option.textContent = name;
    option.selected = name === (state.selected || (frame.vehicle && frame.vehicle.name));
    select.appendChild(option);
  }
}

function onFrame(frame) {
  state.frame = frame;
  updateVehicleList(frame);
  if (!state.fitted) fit();
  updatePanel(frame);
  draw();
}

function onReply(reply) {
  state.replies.push(reply);
  const box = $("reply");
  box.textContent = `${reply.cmd}: ${reply.text}`;
  box.className = reply.ok ? "reply" : "reply error";
}

function fmt(value, digits) {
  return value === null || value === undefined ? "-" : Number(value).toFixed(digits);
}

function updatePanel(frame) {
  const s = frame.status;
  $("st-t").textContent = fmt(s.t, 2);
  $("st-step").textContent = s.step ?? "-";
  const requested = s.requested_warp === null ? "-" : s.requested_warp === 0 ? "max" : fmt(s.requested_warp, 1);
  $("st-warp").textContent = `${requested} / ${fmt(s.achieved_warp, 1)}`;
  $("st-warp").title = "requested / achieved (simulated seconds per wall second)";
  const chosen = selectedOf(frame);
  const several = vehiclesOf(frame).length > 1;
  $("st-behaviour").textContent = (several ? chosen.behaviour : s.behaviour) ?? "-";
  $("st-waypoints").textContent = (several ? chosen.waypoints_reached : s.waypoints_reached) ?? "-";
  $("st-outcome").textContent = s.outcome ? `${s.outcome}` : "-";
  $("st-outcome").title = s.reason || "";
  const label = $("st-state");
  if (state.scene && state.scene.mode === "replay") {
    $("st-warp").textContent = `replay ${frame.replay.rate}x`;
    $("st-warp").title = "playback speed of the replay";
    label.textContent = frame.replay.playing ? "playing" : "replay";
    label.className = frame.replay.playing ? "running" : "";
    $("play").textContent = frame.replay.playing ? "Pause" : "Play";
    if (document.activeElement !== $("scrub")) $("scrub").value = frame.replay.cursor;
    $("cursor").textContent = `${frame.replay.cursor.toFixed(2)} / ${Number($("scrub").max).toFixed(2)} s`;
  } else if (s.outcome) {
    label.textContent = "ended"; label.className = "ended";
    for (const id of ["pause", "resume", "warp-set", "swap"]) $(id).disabled = true;  // nothing left to steer
  } else if (s.paused) {
    label.textContent = "paused"; label.className = "paused";
  } else {
    label.textContent = s.paused === false ? "running" : "live"; label.className = "running";
  }
  const v = chosen ? chosen.vehicle : frame.vehicle;  // pMarineViewer's readout of the selected vehicle
  $("readout-of").textContent = v ? v.name : "";
  $("r-x").textContent = v ? fmt(v.x, 2) : "-";
  $("r-y").textContent = v ? fmt(v.y, 2) : "-";
  $("r-heading").textContent = v ? fmt(v.heading_deg, 1) : "-";
  $("r-speed").textContent = v ? fmt(v.speed, 2) : "-";
  const f = chosen ? chosen.forces : frame.forces;
  $("forces-of").textContent = several && chosen ? `of ${chosen.name}` : "";
  $("f-x").textContent = f ? fmt(f.X_s, 1) : "-";
  $("f-y").textContent = f ? fmt(f.Y_s, 1) : "-";
  $("f-n").textContent = f ? fmt(f.N_s, 1) : "-";
  $("f-w").textContent = f ? fmt(f.weight, 3) : "-";
  drawGauge(f);
  $("event-count").textContent = frame.event_count ? `(${frame.event_count})` : "";
  const list = $("events");
  const items = frame.events.slice(-60).reverse();
  const signature = items.length + ":" + (items[0] ? items[0].t + items[0].kind : "");
  if (list.dataset.signature !== signature) {
    list.dataset.signature = signature;
    list.innerHTML = "";
    for (const e of items) {
      const li = document.createElement("li");
      const style = EVENT_STYLE[e.kind];
      li.innerHTML = `<span class="kind" style="color:${style ? style.color : "#ccd"}"></span><span class="t"></span> `;
      li.firstChild.textContent = e.kind;
      li.childNodes[1].textContent = `t=${e.t.toFixed(2)}`;
      li.appendChild(document.createTextNode((several && e.vehicle ? `${e.vehicle}: ` : "") + e.detail));
      list.appendChild(li);
    }
  }
}

function drawGauge(f) {
  const g = $("gauge").getContext("2d");
  const w = 220, h = 70, cx = w / 2, cy = 62, r = 50;
  g.clearRect(0, 0, w, h);
  g.lineWidth = 8;
  g.strokeStyle = "#2d4257";
  g.beginPath(); g.arc(cx, cy, r, Math.PI, 2 * Math.PI); g.stroke();
  if (f) {
    const frac = f.moment_fraction;  // + = counter-clockwise (towards +y): to the left on the gauge
    g.strokeStyle = "#ff66cc";
    g.beginPath();
    if (frac >= 0) g.arc(cx, cy, r, 1.5 * Math.PI - frac * 0.5 * Math.PI, 1.5 * Math.PI);
    else g.arc(cx, cy, r, 1.5 * Math.PI, 1.5 * Math.PI - frac * 0.5 * Math.PI);
    g.stroke();
  }
  g.fillStyle = "#8fa9bf"; g.font = "11px system-ui"; g.textAlign = "center";
  g.fillText("yaw moment N_s", cx, cy - 8);
  g.textAlign = "left"; g.fillText("+", 4, cy); g.textAlign = "right"; g.fillText("-", w - 4, cy);
}

// -- the map ------------------------------------------------------------------------------------
function resize() {
  const ratio = window.devicePixelRatio || 1;
  canvas.width = canvas.clientWidth * ratio;
  canvas.height = canvas.clientHeight * ratio;
  ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
  draw();
}

function toScreen(x, y) {
  const v = state.view;
  return [canvas.clientWidth / 2 + (x - v.cx) * v.scale, canvas.clientHeight / 2 - (y - v.cy) * v.scale];
}

function toWorld(px, py) {
  const v = state.view;
  return [v.cx + (px - canvas.clientWidth / 2) / v.scale, v.cy - (py - canvas.clientHeight / 2) / v.scale];
}

function fit() {
  const scene = state.scene, frame = state.frame;
  if (!scene) return;
  const points = [];
  if (scene.hull) points.push(...scene.hull);
  for (const leg of scene.legs) points.push(...leg.track);
  if (frame) for (const v of vehiclesOf(frame)) {
    if (v.vehicle) points.push([v.vehicle.x, v.vehicle.y]);
    points.push(...v.trail);
  }
  if (!points.length) points.push([-50, -50], [50, 50]);
  let [x0, y0, x1, y1] = [Infinity, Infinity, -Infinity, -Infinity];
  for (const [x, y] of points) { x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y); }
  const margin = 0.08 * Math.max(x1 - x0, y1 - y0, 10);
  x0 -= margin; x1 += margin; y0 -= margin; y1 += margin;
  state.view.cx = (x0 + x1) / 2;
  state.view.cy = (y0 + y1) / 2;
  state.view.scale = Math.min(canvas.clientWidth / (x1 - x0), canvas.clientHeight / (y1 - y0));
  state.fitted = true;
  state.follow = false;
  draw();
}

function path(points, close) {
  ctx.beginPath();
  points.forEach(([x, y], i) => { const [px, py] = toScreen(x, y); if (i) ctx.lineTo(px, py); else ctx.moveTo(px, py); });
  if (close) ctx.closePath();
}

function marker(shape, px, py, size) {
  ctx.beginPath();
  if (shape === "circle") ctx.arc(px, py, size, 0, 2 * Math.PI);
  else if (shape === "x") { ctx.moveTo(px - size, py - size); ctx.lineTo(px + size, py + size); ctx.moveTo(px + size, py - size); ctx.lineTo(px - size, py + size); }
  else if (shape === "triangle") { ctx.moveTo(px, py - size); ctx.lineTo(px + size, py + size); ctx.lineTo(px - size, py + size); ctx.closePath(); }
  else if (shape === "diamond") { ctx.moveTo(px, py - size); ctx.lineTo(px + size, py); ctx.lineTo(px, py + size); ctx.lineTo(px - size, py); ctx.closePath(); }
  else { for (let i = 0; i < 10; i++) { const a = -Math.PI / 2 + i * Math.PI / 5, r = i % 2 ? size * 0.45 : size; ctx.lineTo(px + r * Math.cos(a), py + r * Math.sin(a)); } ctx.closePath(); }
}

function draw() {
  const scene = state.scene, frame = state.frame;
  const w = canvas.clientWidth, h = canvas.clientHeight;
  ctx.clearRect(0, 0, w, h);
  if (!scene) return;
  const followed = frame ? selectedOf(frame) : null;
  if (state.follow && followed && followed.vehicle) { state.view.cx = followed.vehicle.x; state.view.cy = followed.vehicle.y; }
  drawGrid(w, h);
  for (const r of scene.band.rects) {  // where the residual GP is trained
    const [ax, ay] = toScreen(r.x0, r.y1), [bx, by] = toScreen(r.x1, r.y0);
    ctx.fillStyle = "rgba(80, 220, 140, 0.18)";
    ctx.fillRect(ax, ay, bx - ax, by - ay);
    ctx.strokeStyle = "rgba(80, 220, 140, 0.6)"; ctx.lineWidth = 1;
    ctx.strokeRect(ax, ay, bx - ax, by - ay);
  }
  if (scene.hull) {
    path(scene.hull, true);
    ctx.fillStyle = "#5d6b78"; ctx.fill();
    ctx.strokeStyle = "#aab7c4"; ctx.lineWidth = 1; ctx.stroke();
  }
  ctx.setLineDash([6, 4]); ctx.strokeStyle = "#6fa8ff"; ctx.lineWidth = 1.5;
  for (const leg of scene.legs) { path(leg.track, false); ctx.stroke(); }
  ctx.setLineDash([]);
  ctx.fillStyle = "#6fa8ff"; ctx.font = "11px system-ui";
  for (const leg of scene.legs) {
    leg.points.forEach(([x, y], i) => {
      const [px, py] = toScreen(x, y);
      ctx.fillRect(px - 4, py - 4, 8, 8);
      ctx.fillText(`${leg.name} ${i + 1}`, px + 7, py - 6);
    });
  }
  if (!frame) return;
  const all = vehiclesOf(frame);
  all.forEach((item, i) => {
    const [trailColour, bodyColour] = VEHICLE_COLOURS[i % VEHICLE_COLOURS.length];
    if (item.trail.length > 1) {
      path(item.trail, false);
      ctx.strokeStyle = trailColour; ctx.lineWidth = 1.8; ctx.stroke();
    }
    if (item.vehicle) drawVehicle(item.vehicle, item.forces, scene, bodyColour, item === followed);
  });
  for (const e of frame.events) {  // on top of the UUV: a collision marks where it is
    const style = EVENT_STYLE[e.kind];
    if (!e.marked || !style || e.x === null) continue;
    const [px, py] = toScreen(e.x, e.y);
    marker(style.shape, px, py, 7);
    ctx.strokeStyle = style.color; ctx.fillStyle = style.color; ctx.lineWidth = 2;
    if (style.shape === "x") ctx.stroke(); else { ctx.globalAlpha = 0.75; ctx.fill(); ctx.globalAlpha = 1; }
  }
  drawScaleBar(w, h);
  drawLegend(w);
}

function drawVehicle(v, forces, scene, colour, selected) {
  // Below 16 px the outline is magnified about its centre (as pMarineViewer's vehicle scale).
  const length = (v.length || scene.vehicle.length) * state.view.scale;
  const magnify = length < 16 ? 16 / length : 1;
  const [cx, cy] = toScreen(v.x, v.y);
  ctx.beginPath();
  v.outline.forEach(([x, y], i) => {
    const [px, py] = toScreen(x, y);
    const qx = cx + (px - cx) * magnify, qy = cy + (py - cy) * magnify;
    if (i) ctx.lineTo(qx, qy); else ctx.moveTo(qx, qy);
  });
  ctx.closePath();
  ctx.fillStyle = colour; ctx.fill();
  ctx.strokeStyle = "#1a1a1a"; ctx.lineWidth = 1; ctx.stroke();
  // Each vehicle's name beside it (pMarineViewer's vehicle labels), marked when drawn magnified.
  const label = magnify > 1 ? `${v.name} (not to scale)` : v.name;
  ctx.fillStyle = colour; ctx.font = selected ? "bold 12px system-ui" : "12px system-ui";
  ctx.fillText(label, cx + 10, cy - 8);
  state.labels[v.name] = label;
  if (forces && forces.arrow) {
    const [[x0, y0], [x1, y1]] = forces.arrow;
    const [ax, ay] = toScreen(x0, y0), [bx, by] = toScreen(x1, y1);
    if (Math.hypot(bx - ax, by - ay) > 2) {
      ctx.strokeStyle = "#ff66cc"; ctx.fillStyle = "#ff66cc"; ctx.lineWidth = 2.5;
      ctx.beginPath(); ctx.moveTo(ax, ay); ctx.lineTo(bx, by); ctx.stroke();
      const a = Math.atan2(by - ay, bx - ax);
      ctx.beginPath(); ctx.moveTo(bx, by);
      ctx.lineTo(bx - 10 * Math.cos(a - 0.4), by - 10 * Math.sin(a - 0.4));
      ctx.lineTo(bx - 10 * Math.cos(a + 0.4), by - 10 * Math.sin(a + 0.4));
      ctx.closePath(); ctx.fill();
    }
    if (Math.abs(forces.moment_fraction) > 0.005) {  // the yaw moment as an arc around the UUV
      const r = Math.max(length * magnify * 0.7, 14);
      ctx.strokeStyle = "#ff66cc"; ctx.lineWidth = 2;
      ctx.beginPath();
      const sweep = -forces.moment_fraction * Math.PI;  // screen y is down: + (towards +y) is anticlockwise
      ctx.arc(cx, cy, r, -v.psi, -v.psi + sweep, sweep < 0);
      ctx.stroke();
    }
  }
  const drawn = { step: v.step, t: v.t, x: v.x, y: v.y, psi: v.psi };
  state.drawnAll[v.name] = drawn;
  if (!selected) return;
  state.drawn = drawn;
  state.history.push(state.drawn);
  if (state.history.length > 500) state.history.shift();
  canvas.dataset.step = v.step;
  canvas.dataset.x = v.x;
  canvas.dataset.y = v.y;
}

function niceStep(target) {
  const p = Math.pow(10, Math.floor(Math.log10(target)));
  for (const m of [1, 2, 5, 10]) if (m * p >= target) return m * p;
  return 10 * p;
}

function drawGrid(w, h) {
  const step = niceStep(80 / state.view.scale);
  const [x0, y1] = toWorld(0, 0), [x1, y0] = toWorld(w, h);
  ctx.strokeStyle = "rgba(255,255,255,0.06)"; ctx.lineWidth = 1;
  ctx.beginPath();
  const xs = [], ys = [];
  for (let x = Math.ceil(x0 / step) * step; x <= x1; x += step) { const [px] = toScreen(x, 0); ctx.moveTo(px, 0); ctx.lineTo(px, h); xs.push(x); }
  for (let y = Math.ceil(y0 / step) * step; y <= y1; y += step) { const [, py] = toScreen(0, y); ctx.moveTo(0, py); ctx.lineTo(w, py); ys.push(y); }
  ctx.stroke();
  // Each line's coordinate in metres (x along the bottom edge, y along the left one), as a chart's ticks.
  const label = (v) => `${Number(v.toPrecision(6))}`;
  ctx.fillStyle = "rgba(221,230,238,0.55)"; ctx.font = "10px system-ui";
  for (const x of xs) { const [px] = toScreen(x, 0); ctx.fillText(label(x), px + 3, h - 4); }
  for (const y of ys) { const [, py] = toScreen(0, y); if (py > 60) ctx.fillText(label(y), 4, py - 3); }
  state.gridLabels = { x: xs.map(label), y: ys.map(label), step };
}

function drawScaleBar(w, h) {
  const metres = niceStep(120 / state.view.scale);
  const px = metres * state.view.scale;
  ctx.strokeStyle = "#dde6ee"; ctx.fillStyle = "#dde6ee"; ctx.lineWidth = 2;
  ctx.beginPath(); ctx.moveTo(16, h - 18); ctx.lineTo(16 + px, h - 18); ctx.stroke();
  ctx.font = "11px system-ui"; ctx.fillText(`${metres} m`, 16, h - 24);
}

function drawLegend(w) {
  const names = state.frame ? vehiclesOf(state.frame).map((v) => v.name) : [];
  const uuvs = names.length > 1  // several vehicles: each one's colour and name
    ? names.map((name, i) => [VEHICLE_COLOURS[i % VEHICLE_COLOURS.length][0], name])
    : [["#ff5c5c", "trail"], ["#ffd23f", "UUV"]];
  const items = [["#5d6b78", "submarine"], ["rgba(80,220,140,0.6)", "surrogate band"], ["#6fa8ff", "track-lines"],
    ...uuvs, ["#ff66cc", "interaction force / moment"]];
  ctx.font = "11px system-ui";
  items.forEach(([color, text], i) => {
    const y = 16 + i * 15;
    ctx.fillStyle = color; ctx.fillRect(w - 170, y - 8, 10, 10);
    ctx.fillStyle = "#cdd9e3"; ctx.fillText(text, w - 154, y + 1);
  });
}

// -- input ----------------------------------------------------------------------------------------
let drag = null;
canvas.addEventListener("mousedown", (e) => { drag = [e.clientX, e.clientY]; state.follow = false; });
window.addEventListener("mouseup", () => { drag = null; });
window.addEventListener("mousemove", (e) => {
  if (!drag) return;
  state.view.cx -= (e.clientX - drag[0]) / state.view.scale;
  state.view.cy += (e.clientY - drag[1]) / state.view.scale;
  drag = [e.clientX, e.clientY];
  draw();
});
canvas.addEventListener("wheel", (e) => {
  e.preventDefault();
  const rect = canvas.getBoundingClientRect();
  const [wx, wy] = toWorld(e.clientX - rect.left, e.clientY - rect.top);
  const factor = Math.exp(-e.deltaY * 0.0015);
  state.view.scale *= factor;
  state.view.cx = wx - (wx - state.view.cx) / factor;
  state.view.cy = wy - (wy - state.view.cy) / factor;
  draw();
}, { passive: false });
window.addEventListener("resize", resize);

$("pause").onclick = () => send({ cmd: "pause" });
$("resume").onclick = () => send({ cmd: "resume" });
$("warp-set").onclick = () => send({ cmd: "warp", warp: Number($("warp-input").value) });
$("swap").onclick = () => send({ cmd: "swap", behaviour: $("behaviour").value });
$("fit").onclick = fit;
$("follow").onclick = () => {
  state.follow = true;
  const chosen = state.frame ? selectedOf(state.frame) : null;
  const length = chosen && chosen.vehicle ? chosen.vehicle.length : state.scene && state.scene.vehicle.length;
  if (length) state.view.scale = Math.max(state.view.scale, canvas.clientWidth / (12 * length));
  draw();
};
$("vehicle").onchange = () => {
  state.selected = $("vehicle").value;
  if (state.frame) updatePanel(state.frame);
  draw();
};
$("play").onclick = () => send({ cmd: state.frame && state.frame.replay && state.frame.replay.playing ? "stop" : "play" });
$("scrub").oninput = () => send({ cmd: "seek", t: Number($("scrub").value) });
$("rate").onchange = () => send({ cmd: "rate", rate: Number($("rate").value) });

connect();
