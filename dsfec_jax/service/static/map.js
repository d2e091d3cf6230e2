// The map page: fetch /tracks and /objects, draw them on a canvas, refresh every few seconds.
//
// Incremental: the first fetch takes the latest OBJECT_LIMIT objects and each device's track
// (the server spreads at most TRACK_POINTS positions over it); later fetches pass the answers'
// cursors (`after=`) and get only what was stored since, so an idle map costs the server two
// index seeks per refresh however large the database. The page keeps the latest OBJECT_LIMIT
// objects and thins a track that grows past 2 x TRACK_POINTS. A count that went down in /health
// (an operator's delete) starts over. Nothing here spreads an array into a call (Math.min(...xs)
// throws a RangeError past ~125k arguments): extents are computed in loops.
// Reads that need a token: open the page as /#token=<read token> (the fragment never leaves the
// browser; the page sends it as a bearer header).
//
// Projection: local equirectangular about the data's centre, in metres
//   x = R (lon - lon0) cos(lat0),  y = R (lat - lat0),  R = 6 371 008.8 m (mean Earth radius),
// fitted to the data with one scale for both axes (a metre is a metre in every direction). Good to
// well under 1 % over a city; this is a display, the service stores WGS84 degrees as posted.
// After each draw the body carries data-objects / data-tracks (counts drawn) and data-drawn (draws
// so far), so a headless browser can check what the page shows; data-error holds a failed
// update's message (and the status line says it).
"use strict";

const REFRESH_MS = 3000;
const OBJECT_LIMIT = 5000;
const TRACK_POINTS = 2000;
const R_EARTH = 6371008.8;
const CLASS_COLOURS = { car: "#1f77b4", truck: "#8c564b", bus: "#9467bd", pedestrian: "#d62728", person: "#d62728",
                        cyclist: "#ff7f0e", bicycle: "#ff7f0e", motorbike: "#e377c2", motorcycle: "#e377c2" };
const SPARE_COLOURS = ["#2ca02c", "#17becf", "#bcbd22", "#7f7f7f", "#aec7e8", "#98df8a", "#c49c94", "#f7b6d2"];
// track lines in colours no class dot uses (no blue, red, orange, brown)
const TRACK_COLOURS = ["#2b8a3e", "#0b7285", "#5f3dc4", "#495057", "#5c940d", "#a61e4d", "#15aabf", "#868e96"];
const TOKEN = new URLSearchParams(location.hash.slice(1)).get("token");

const canvas = document.getElementById("map");
const legend = document.getElementById("legend");
const statusEl = document.getElementById("status");
const tip = document.getElementById("tip");
let state = { tracks: [], objects: [], truncated: false, view: null };
let cursors = { objects: null, tracks: null };
let lastBatches = -1;
let draws = 0;

function classColour(name) {
  if (CLASS_COLOURS[name]) return CLASS_COLOURS[name];
  let h = 0;
  for (const ch of name) h = (h * 31 + ch.charCodeAt(0)) >>> 0;
  return SPARE_COLOURS[h % SPARE_COLOURS.length];
}

async function getJson(path) {
  const reply = await fetch(path, { cache: "no-store", headers: TOKEN ? { Authorization: `Bearer ${TOKEN}` } : {} });
  if (!reply.ok) throw new Error(`${path.split("?")[0]}: HTTP ${reply.status}`);
  return reply.json();
}

async function refresh() {
  try {
    const health = await getJson("health");
    if (health.batches < lastBatches) cursors = { objects: null, tracks: null };  // rows were deleted: start over
    lastBatches = health.batches;
    await Promise.all([updateObjects(), updateTracks()]);
    draw();  // inside the try: a drawing error shows in the status line, not a stale "updated"
    const n = state.objects.length;
    statusEl.className = "status";
    statusEl.textContent = `${state.tracks.length} device${state.tracks.length === 1 ? "" : "s"}, ` +
      `${n}${state.truncated ? " latest" : ""} object${n === 1 ? "" : "s"} · updated ${new Date().toLocaleTimeString()}`;
    delete document.body.dataset.error;
  } catch (err) {
    statusEl.className = "status error";
    statusEl.textContent = `update failed (${err.message}); retrying every ${REFRESH_MS / 1000} s`;
    document.body.dataset.error = err.message;
  }
}

async function updateObjects() {
  if (cursors.objects === null) {
    const fc = await getJson(`objects?limit=${OBJECT_LIMIT}`);
    state.objects = fc.features.slice().reverse();  // newest last: drawn on top
    state.truncated = Boolean(fc.truncated);
    cursors.objects = fc.cursor;
    return;
  }
  const fc = await getJson(`objects?after=${cursors.objects}&limit=${OBJECT_LIMIT}`);
  if (fc.truncated) {  // more new objects than the page keeps: take the latest afresh
    cursors.objects = null;
    return updateObjects();
  }
  for (const f of fc.features) state.objects.push(f);
  if (state.objects.length > OBJECT_LIMIT) {
    state.objects = state.objects.slice(state.objects.length - OBJECT_LIMIT);
    state.truncated = true;
  }
  cursors.objects = fc.cursor;
}

async function updateTracks() {
  const full = cursors.tracks === null;
  const fc = await getJson(full ? `tracks?max_points=${TRACK_POINTS}`
                                : `tracks?after=${cursors.tracks}&max_points=${TRACK_POINTS}`);
  // a device seen once is a Point (a LineString needs two positions): one list of positions for both
  const fresh = fc.features.filter(f => f.geometry).map(f => ({
    device: (f.properties && f.properties.device) || "device",
    positions: f.geometry.type === "Point" ? [f.geometry.coordinates] : f.geometry.coordinates,
  }));
  if (full) {
    state.tracks = fresh;
  } else {
    for (const t of fresh) {
      const known = state.tracks.find(k => k.device === t.device);
      if (!known) { state.tracks.push(t); continue; }
      for (const p of t.positions) known.positions.push(p);
      if (known.positions.length > 2 * TRACK_POINTS) known.positions = thinned(known.positions);
    }
    state.tracks.sort((a, b) => (a.device < b.device ? -1 : a.device > b.device ? 1 : 0));  // stable colours
  }
  cursors.tracks = fc.cursor;
}

function thinned(positions) {  // every other position, the latest kept
  const out = positions.filter((_, i) => i % 2 === 0);
  if (out[out.length - 1] !== positions[positions.length - 1]) out.push(positions[positions.length - 1]);
  return out;
}

// -- projection ----------------------------------------------------------------------------------
function extent() {
  let minLon = Infinity, maxLon = -Infinity, minLat = Infinity, maxLat = -Infinity;
  const add = (lon, lat) => {
    if (lon < minLon) minLon = lon;
    if (lon > maxLon) maxLon = lon;
    if (lat < minLat) minLat = lat;
    if (lat > maxLat) maxLat = lat;
  };
  for (const t of state.tracks) for (const [lon, lat] of t.positions) add(lon, lat);
  for (const o of state.objects) add(o.geometry.coordinates[0], o.geometry.coordinates[1]);
  return minLon <= maxLon ? { minLon, maxLon, minLat, maxLat } : null;
}

function fitView(width, height, reserveRight) {
  const e = extent();
  if (!e) return null;
  const lat0 = (e.minLat + e.maxLat) / 2, lon0 = (e.minLon + e.maxLon) / 2;
  const k = Math.cos(lat0 * Math.PI / 180) * R_EARTH * Math.PI / 180;  // metres per degree of longitude
  const m = R_EARTH * Math.PI / 180;                                    // metres per degree of latitude
  const spanX = Math.max((e.maxLon - e.minLon) * k, 40), spanY = Math.max((e.maxLat - e.minLat) * m, 40);
  const pad = 40, usable = Math.max(width - reserveRight, width / 2);  // keep the data clear of the legend
  const scale = Math.min((usable - 2 * pad) / spanX, (height - 2 * pad) / spanY);  // pixels per metre
  return {
    scale,
    project(lon, lat) {
      return [usable / 2 + (lon - lon0) * k * scale, height / 2 - (lat - lat0) * m * scale];
    },
  };
}

// -- drawing -------------------------------------------------------------------------------------
function draw() {
  const dpr = window.devicePixelRatio || 1;
  const width = canvas.clientWidth, height = canvas.clientHeight;
  canvas.width = Math.round(width * dpr);
  canvas.height = Math.round(height * dpr);
  const ctx = canvas.getContext("2d");
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.fillStyle = "#f7f8f5";
  ctx.fillRect(0, 0, width, height);
  drawLegend();  // first: the view keeps the data out from under it
  const view = state.view = fitView(width, height, legend.offsetWidth ? legend.offsetWidth + 20 : 0);
  if (view) {
    drawGrid(ctx, view, width, height);
    const radius = state.objects.length > 1000 ? 2.5 : 3.5;  // dense maps: smaller dots, less overdraw
    for (const o of state.objects) drawObject(ctx, view, o, radius);
    // tracks over the objects: a car ahead in the ego's lane would otherwise hide the ego's path
    state.tracks.forEach((t, i) => drawTrack(ctx, view, t, TRACK_COLOURS[i % TRACK_COLOURS.length]));
    drawScaleBar(ctx, view, height);
    drawNorth(ctx, width, height);
  } else {
    ctx.fillStyle = "#5a6675";
    ctx.font = "15px system-ui, sans-serif";
    ctx.textAlign = "center";
    ctx.fillText("No data yet: waiting for an edge device to post a frame batch.", width / 2, height / 2);
  }
  draws += 1;
  document.body.dataset.objects = String(view ? state.objects.length : 0);
  document.body.dataset.tracks = String(view ? state.tracks.length : 0);
  document.body.dataset.drawn = String(draws);
}

function niceLength(metres) {
  const p = Math.pow(10, Math.floor(Math.log10(metres)));
  for (const f of [5, 2, 1]) if (f * p <= metres) return f * p;
  return p;
}

function drawGrid(ctx, view, width, height) {
  // a line every ~120 px at a round number of metres (the scale bar's unit), through the view's centre
  const px = niceLength(120 / view.scale) * view.scale;
  ctx.strokeStyle = "#e2e6e0";
  ctx.lineWidth = 1;
  ctx.beginPath();
  for (let x = (width / 2) % px; x < width; x += px) { ctx.moveTo(x, 0); ctx.lineTo(x, height); }
  for (let y = (height / 2) % px; y < height; y += px) { ctx.moveTo(0, y); ctx.lineTo(width, y); }
  ctx.stroke();
}

function drawTrack(ctx, view, track, colour) {
  const pts = track.positions.map(([lon, lat]) => view.project(lon, lat));
  ctx.lineJoin = ctx.lineCap = "round";
  ctx.strokeStyle = "rgba(255,255,255,.9)";
  ctx.lineWidth = 7;
  polyline(ctx, pts);
  ctx.strokeStyle = colour;
  ctx.lineWidth = 3;
  polyline(ctx, pts);
  const [sx, sy] = pts[0], [ex, ey] = pts[pts.length - 1];
  ctx.fillStyle = "#fff";
  ctx.strokeStyle = colour;
  ctx.lineWidth = 2;
  ctx.beginPath(); ctx.arc(sx, sy, 5, 0, 2 * Math.PI); ctx.fill(); ctx.stroke();        // start: hollow
  ctx.fillStyle = colour;
  ctx.beginPath(); ctx.arc(ex, ey, 6, 0, 2 * Math.PI); ctx.fill();                      // latest position: filled
  ctx.font = "600 12px system-ui, sans-serif";
  const name = track.device, right = ex + 9 + ctx.measureText(name).width < ctx.canvas.clientWidth;
  ctx.textAlign = right ? "left" : "right";  // the label stays inside the canvas
  ctx.lineWidth = 3;
  ctx.strokeStyle = "#fff";
  ctx.strokeText(name, right ? ex + 9 : ex - 9, ey - 8);
  ctx.fillText(name, right ? ex + 9 : ex - 9, ey - 8);
}

function polyline(ctx, pts) {
  ctx.beginPath();
  pts.forEach(([x, y], i) => (i ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
  ctx.stroke();
}

function drawObject(ctx, view, o, radius) {
  const [x, y] = view.project(o.geometry.coordinates[0], o.geometry.coordinates[1]);
  ctx.fillStyle = classColour(o.properties["class"]);
  ctx.globalAlpha = 0.35 + 0.6 * Math.min(1, Math.max(0, o.properties.score));  // confident detections stand out
  ctx.beginPath();
  ctx.arc(x, y, radius, 0, 2 * Math.PI);
  ctx.fill();
  ctx.globalAlpha = 1;
}

function drawScaleBar(ctx, view, height) {
  const metres = niceLength(160 / view.scale);
  const px = metres * view.scale, x = 16, y = height - 22;
  ctx.fillStyle = "rgba(255,255,255,.85)";
  ctx.fillRect(x - 8, y - 22, px + 16, 34);
  ctx.strokeStyle = "#1d2733";
  ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.moveTo(x, y - 6); ctx.lineTo(x, y); ctx.lineTo(x + px, y); ctx.lineTo(x + px, y - 6);
  ctx.stroke();
  ctx.fillStyle = "#1d2733";
  ctx.font = "12px system-ui, sans-serif";
  ctx.textAlign = "center";
  ctx.fillText(metres >= 1000 ? `${metres / 1000} km` : `${metres} m`, x + px / 2, y - 9);
}

function drawNorth(ctx, width, height) {
  const x = width - 30, y = height - 40;
  ctx.fillStyle = "#1d2733";
  ctx.beginPath(); ctx.moveTo(x, y - 16); ctx.lineTo(x + 7, y + 6); ctx.lineTo(x, y + 1); ctx.lineTo(x - 7, y + 6); ctx.closePath();
  ctx.fill();
  ctx.font = "600 12px system-ui, sans-serif";
  ctx.textAlign = "center";
  ctx.fillText("N", x, y + 20);
}

function drawLegend() {
  const counts = new Map();
  for (const o of state.objects) counts.set(o.properties["class"], (counts.get(o.properties["class"]) || 0) + 1);
  const rows = [];
  if (counts.size) {
    rows.push("<h2>Objects by class</h2>");
    for (const [name, n] of [...counts].sort((a, b) => b[1] - a[1]))
      rows.push(`<div class="row"><span class="swatch" style="background:${classColour(name)}"></span>` +
                `${escapeHtml(name)}<span class="count">${n}</span></div>`);
  }
  if (state.tracks.length) {
    rows.push("<h2>Ego tracks</h2>");
    state.tracks.forEach((t, i) => rows.push(
      `<div class="row"><span class="line" style="border-color:${TRACK_COLOURS[i % TRACK_COLOURS.length]}"></span>` +
      `${escapeHtml(t.device)}<span class="count">${t.positions.length} position${t.positions.length === 1 ? "" : "s"}</span></div>`));
  }
  legend.innerHTML = rows.join("");
  legend.style.display = rows.length ? "" : "none";
}

function escapeHtml(text) {
  return String(text).replace(/[&<>"']/g, c => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" })[c]);
}

// -- hover: the nearest object within 8 px ---------------------------------------------------------
canvas.addEventListener("mousemove", ev => {
  const view = state.view;
  let best = null, bestD = 64;
  if (view) for (const o of state.objects) {
    const [x, y] = view.project(o.geometry.coordinates[0], o.geometry.coordinates[1]);
    const d = (x - ev.offsetX) ** 2 + (y - ev.offsetY) ** 2;
    if (d < bestD) { best = o; bestD = d; }
  }
  if (!best) { tip.style.display = "none"; return; }
  const p = best.properties;
  tip.textContent = `${p["class"]}  score ${Number(p.score).toFixed(2)}\n${p.device}  ${p.time_iso || p.time}\n` +
                    `depth ${Number(p.depth_m).toFixed(1)} m, x ${Number(p.x_m).toFixed(1)} m`;
  tip.style.left = `${ev.offsetX + 12}px`;
  tip.style.top = `${ev.offsetY + 12}px`;
  tip.style.display = "block";
});
canvas.addEventListener("mouseleave", () => { tip.style.display = "none"; });
window.addEventListener("resize", draw);

refresh();
setInterval(refresh, REFRESH_MS);
