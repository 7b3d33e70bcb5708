// The preview page: sends the whole state (the file's key edits and the view) on every change,
// paints the frames the server sends back (xrayraster/preview/encoding.py), and applies window and
// level itself. One request is in flight at a time and the newest change waits in its place, so
// the image follows the hand instead of a queue of stale frames (the server also keeps only the
// newest request it has not started). While an input moves (a slider or the image dragged) the
// requests say so ("moving": true) and the server answers with a reduced frame, the detector binned
// to fewer pixels, which the canvas stretches to the full frame's size; SETTLE_MS after the last
// such input the page asks for the full frame. The label above the image says which it shows.
"use strict";

const $ = (id) => document.getElementById(id);
const token = new URLSearchParams(location.search).get("token");
const query = token ? `?token=${encodeURIComponent(token)}` : "";
const state = { edits: {}, view: { output: "lineint", material: 0, noise: false, seed: 0, angle_deg: null } };
// window.xrPreview, read by tests and scripts/bench_preview.py: the frame shown, frames painted, and
// each painted frame's latency from the first input event it answers to its paint (ms).
// paintedAt: when the last frame was painted; reduced: the last reduced frame painted, and
// paintedReduced how many were.
const preview = { state, frame: null, painted: 0, paintedReduced: 0, paintedAt: null, reduced: null, window: null,
  latencies: [] };
window.xrPreview = preview;
let socket = null, nextId = 1, inFlight = null, pending = false, inputAt = {}, firstInput = null;
// The input counts as moving until it has been still for SETTLE_MS (a hand on a 60 Hz display moves
// every 17 ms; a slow one every few frames): settleTimer runs meanwhile. sentMoving: whether the
// last request sent asked for a reduced frame (so the full one is still to ask for).
const SETTLE_MS = 80;
let settleTimer = null, sentMoving = false;
let win = { level: 0, width: 1, auto: true };

function decodeFrame(buffer) {
  const length = new DataView(buffer).getUint32(0, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, length)));
  const levels = new Uint16Array(buffer, 4 + length, header.shape[0] * header.shape[1]);
  return { header, levels };
}

function value(frame, level) {
  const h = frame.header;
  return h.lo + level * ((h.hi - h.lo) / 65535);
}

function send() {
  if (firstInput === null) firstInput = performance.now();
  if (!socket || socket.readyState !== WebSocket.OPEN) return;
  if (inFlight !== null) { pending = true; return; }
  const id = nextId++, moving = settleTimer !== null;
  inFlight = id;
  inputAt[id] = firstInput;
  firstInput = null;
  sentMoving = moving;
  socket.send(JSON.stringify({ id, edits: state.edits, view: state.view, moving }));
}

function moved() {  // an input that moves on (a slider or the image dragged): reduced frames until it stops
  clearTimeout(settleTimer);
  settleTimer = setTimeout(settled, SETTLE_MS);
}

function settled() {  // the input has stopped: the full frame, unless it is asked for or shown already
  settleTimer = null;
  // A detector too small to reduce answers a moving request with its full frame: nothing to ask for.
  const f = preview.frame, last = nextId - 1;
  const shownFull = inFlight === null && f !== null && f.header.id === last && (f.header.binning || 1) === 1;
  if (sentMoving && !shownFull) send();  // with a frame in flight, sent (in full) when that one comes back
}

function received(event) {
  if (typeof event.data === "string") {
    const message = JSON.parse(event.data);
    if (message.type === "hello") return hello(message);
    done(message.id);
    $("error").textContent = message.error;  // the last good image stays
    $("error").hidden = false;
    return;
  }
  const arrived = performance.now();
  const frame = decodeFrame(event.data);
  preview.frame = frame;
  $("error").hidden = true;
  if (win.auto) autoWindow();
  paint();
  histogram();
  schematic(frame.header.layout);
  const t = frame.header.seconds, ms = (s) => (1000 * s).toFixed(0);
  const stages = Object.entries(t).map(([k, s]) => `${k.replace("_", " ")} ${ms(s)}`).join(", ");
  const now = performance.now(), latency = now - inputAt[frame.header.id];
  preview.latencies.push(latency);
  preview.pageMs = now - arrived;
  preview.paintedAt = now;
  const [rows, cols] = frame.header.shape;
  $("timing").textContent = `frame ${frame.header.id} (${rows} × ${cols}): ${stages} ms on the server, ` +
    `${ms((now - arrived) / 1000)} ms in the page; ${latency.toFixed(0)} ms from input to paint`;
  $("command").textContent = frame.header.command;
  done(frame.header.id);
}

function done(id) {
  delete inputAt[id];
  if (id !== inFlight) return;
  inFlight = null;
  if (pending) { pending = false; send(); }
}

function paint() {
  const frame = preview.frame;
  if (!frame) return;
  const [rows, cols] = frame.header.shape, binning = frame.header.binning || 1;
  const canvas = $("image");
  if (canvas.width !== cols || canvas.height !== rows) { canvas.width = cols; canvas.height = rows; }
  // A reduced frame is stretched to the full one's size on screen (the canvas's CSS size), smoothly.
  canvas.classList.toggle("reduced", binning > 1);
  if (binning > 1) { preview.reduced = frame; preview.paintedReduced++; }
  const [fullRows, fullCols] = frame.header.full_shape || frame.header.shape;
  $("resolution").textContent = binning > 1
    ? `preview: 1/${binning} resolution while moving (${rows} × ${cols} of ${fullRows} × ${fullCols} pixels)`
    : `full resolution (${rows} × ${cols} pixels)`;
  $("resolution").className = binning > 1 ? "reduced" : "full";
  preview.window = win;
  const lut = new Uint8ClampedArray(65536), low = win.level - win.width / 2;
  for (let q = 0; q < 65536; q++) lut[q] = Math.round(255 * (value(frame, q) - low) / win.width);
  const image = new ImageData(cols, rows), px = image.data, levels = frame.levels;
  for (let i = 0; i < levels.length; i++) {
    const g = lut[levels[i]];
    px[4 * i] = px[4 * i + 1] = px[4 * i + 2] = g;
    px[4 * i + 3] = 255;
  }
  canvas.getContext("2d").putImageData(image, 0, 0);
  preview.painted++;
}

function autoWindow() {  // the 0.5th to 99.5th percentile of the frame's values
  const frame = preview.frame, counts = new Uint32Array(65536);
  for (const q of frame.levels) counts[q]++;
  const n = frame.levels.length;
  let seen = 0, lo = 0, hi = 65535;
  for (let q = 0; q < 65536; q++) { seen += counts[q]; if (seen > 0.005 * n) { lo = q; break; } }
  seen = 0;
  for (let q = 65535; q >= 0; q--) { seen += counts[q]; if (seen > 0.005 * n) { hi = q; break; } }
  const a = value(frame, lo), b = value(frame, Math.max(hi, lo + 1));
  win = { level: (a + b) / 2, width: Math.max(b - a, 1e-12), auto: win.auto };
  syncWindowSliders();
}

function syncWindowSliders() {  // the sliders span the frame's range, in thousandths
  const h = preview.frame.header, span = Math.max(h.hi - h.lo, 1e-12);
  $("level").value = Math.round(1000 * (win.level - h.lo) / span);
  $("window").value = Math.max(1, Math.round(1000 * win.width / span));
}

function fromWindowSliders() {
  const h = preview.frame.header, span = Math.max(h.hi - h.lo, 1e-12);
  win = { level: h.lo + span * $("level").value / 1000, width: span * $("window").value / 1000, auto: false };
  paint();
  histogram();
}

function histogram() {
  const frame = preview.frame, canvas = $("histogram"), ctx = canvas.getContext("2d");
  const bins = new Float64Array(256);
  for (const q of frame.levels) bins[q >> 8]++;
  const top = Math.log1p(Math.max(...bins));
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  ctx.fillStyle = "#8ab";
  const w = canvas.width / 256;
  bins.forEach((c, i) => {
    const h = canvas.height * Math.log1p(c) / top;
    ctx.fillRect(i * w, canvas.height - h, Math.ceil(w), h);
  });
  const x = (v) => canvas.width * (v - frame.header.lo) / Math.max(frame.header.hi - frame.header.lo, 1e-12);
  ctx.fillStyle = "rgba(255, 200, 80, 0.25)";
  ctx.fillRect(x(win.level - win.width / 2), 0, x(win.level + win.width / 2) - x(win.level - win.width / 2), canvas.height);
  ctx.fillStyle = "#ccc";
  ctx.fillText(`${frame.header.lo.toPrecision(4)}`, 2, 10);
  const hiText = `${frame.header.hi.toPrecision(4)} ${frame.header.unit}`;
  ctx.fillText(hiText, canvas.width - ctx.measureText(hiText).width - 2, 10);
}

function schematic(layout) {  // view 0 from above, turned so the source is on the left
  const canvas = $("schematic"), ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (!layout) return;
  const toward = layout.source ? layout.source : layout.direction.map((c) => -c);
  const turn = Math.PI - Math.atan2(toward[1], toward[0]), cos = Math.cos(turn), sin = Math.sin(turn);
  const rotate = ([x, y]) => [x * cos - y * sin, x * sin + y * cos];
  const detector = layout.detector.map(rotate), sample = layout.sample.map(rotate);
  const source = layout.source ? rotate(layout.source) : null;
  const points = [...detector, ...sample, ...(source ? [source] : [])];
  const extent = Math.max(layout.fov_mm, ...points.map(([x, y]) => Math.max(Math.abs(x), Math.abs(y))));
  const scale = (canvas.width / 2 - 12) / extent, c = canvas.width / 2;
  const at = ([x, y]) => [c + x * scale, c - y * scale];
  const line = (pts, style, close) => {
    ctx.beginPath();
    pts.map(at).forEach(([x, y], i) => (i ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
    if (close) ctx.closePath();
    ctx.strokeStyle = style;
    ctx.stroke();
  };
  ctx.lineWidth = 1;
  if (source) { line([detector[0], source, detector[1]], "#fc6"); }
  ctx.setLineDash([4, 3]);
  ctx.beginPath();
  ctx.arc(c, c, layout.fov_mm * scale, 0, 2 * Math.PI);
  ctx.strokeStyle = "#6a6";
  ctx.stroke();
  ctx.setLineDash([]);
  line(sample, "#9cf", true);
  ctx.lineWidth = 3;
  line(detector, "#eee");
  if (source) { const [x, y] = at(source); ctx.fillStyle = "#fc6"; ctx.fillRect(x - 3, y - 3, 6, 6); }
  ctx.fillStyle = "#999";
  ctx.fillText(`field of view ⌀ ${(2 * layout.fov_mm).toPrecision(3)} mm`, 4, canvas.height - 4);
}

function readout(event) {
  const frame = preview.frame;
  if (!frame) return;
  const canvas = $("image"), box = canvas.getBoundingClientRect();
  const col = Math.floor((event.clientX - box.left) * canvas.width / box.width);
  const row = Math.floor((event.clientY - box.top) * canvas.height / box.height);
  if (row < 0 || col < 0 || row >= canvas.height || col >= canvas.width) return;
  const v = value(frame, frame.levels[row * canvas.width + col]), binning = frame.header.binning || 1;
  const where = binning > 1 ? `binned row ${row}, column ${col} (1/${binning} resolution)` : `row ${row}, column ${col}`;
  $("readout").textContent = `${where}: ${v.toPrecision(5)} ${frame.header.unit} (${frame.header.quantity})`;
}

function setAngle(degrees, from) {
  const a = ((degrees % 360) + 360) % 360;
  if (from === "slider" || from === "drag") moved();
  state.view.angle_deg = a;
  if (from !== "slider") $("angle").value = a;
  if (from !== "number") $("angle-value").value = a.toFixed(2);
  send();
}

function hello(message) {
  $("file").textContent = message.file;
  $("slice-controls").hidden = message.kind !== "scan";
  Object.assign(state.view, message.view);
  if (state.view.angle_deg === null) { $("angle").disabled = $("angle-value").disabled = true; }
  else { $("angle").value = state.view.angle_deg; $("angle-value").value = state.view.angle_deg; }
  $("output").innerHTML = message.outputs.map((o) => `<option value="${o}">${o.replace("_", " ")}</option>`).join("");
  $("output").value = state.view.output;
  $("material").innerHTML = message.materials.map((m, i) => `<option value="${i}">${m}</option>`).join("");
  $("noise").checked = state.view.noise;
  $("seed").value = state.view.seed;
  $("controls").innerHTML = "";
  for (const c of message.controls) {
    const label = document.createElement("label");
    label.textContent = `${c.label} `;
    if (c.unit) { const u = document.createElement("span"); u.className = "unit"; u.textContent = c.unit; label.append(u); }
    if (c.kind === "choice") {
      const select = document.createElement("select");
      select.dataset.key = c.key;
      select.innerHTML = c.choices.map((v) => `<option value="${v}">${v}</option>`).join("");
      select.value = c.value;
      select.addEventListener("change", () => { state.edits[c.key] = select.value; send(); });
      label.append(select);
      $("controls").append(label);
      continue;
    }
    const slider = Object.assign(document.createElement("input"), { type: "range", min: c.min, max: c.max, step: c.step });
    const number = Object.assign(document.createElement("input"), { type: "number", step: c.step });
    number.dataset.key = slider.dataset.key = c.key;
    slider.value = number.value = c.value;
    const change = (raw, other) => {
      const v = c.kind === "integer" ? parseInt(raw, 10) : parseFloat(raw);
      if (Number.isNaN(v)) return;
      other.value = raw;
      state.edits[c.key] = v;
      send();
    };
    slider.addEventListener("input", () => { moved(); change(slider.value, number); });
    number.addEventListener("change", () => change(number.value, slider));
    const pair = document.createElement("span");
    pair.className = "pair";
    pair.append(slider, number);
    label.append(pair);
    $("controls").append(label);
  }
  send();
}

async function save(what) {
  const response = await fetch(`save/${what}${query}`, {
    method: "POST", headers: { "Content-Type": "application/json" },
    body: JSON.stringify({ edits: state.edits, view: state.view }),
  });
  if (!response.ok) {
    const text = await response.text();
    let message = text;
    try { message = JSON.parse(text).error; } catch (e) { /* plain text */ }
    $("error").textContent = message;
    $("error").hidden = false;
    return;
  }
  const link = Object.assign(document.createElement("a"), { href: URL.createObjectURL(await response.blob()), download: what });
  document.body.append(link);
  link.click();
  link.remove();
}

async function quickSlice() {
  $("slice").disabled = true;
  $("slice-caption").textContent = "reconstructing...";
  $("slice-figure").hidden = false;
  try {
    const response = await fetch(`slice${query}`, {
      method: "POST", headers: { "Content-Type": "application/json" },
      body: JSON.stringify({ edits: state.edits, view: state.view }),
    });
    if (!response.ok) throw new Error(JSON.parse(await response.text()).error);
    const buffer = await response.arrayBuffer(), cut = decodeFrame(buffer), h = cut.header;
    const [rows, cols] = h.shape, n = rows * cols;
    const labels = new Uint16Array(buffer, buffer.byteLength - 2 * n, n);
    const sorted = Array.from(cut.levels).sort((a, b) => a - b);
    const lo = value(cut, sorted[Math.floor(0.01 * n)]), hi = value(cut, sorted[Math.floor(0.99 * n)]);
    const canvas = $("slice-image"), image = new ImageData(cols, rows), px = image.data;
    const colour = (k) => (k > 0 ? h.palette[(k - 1) % h.palette.length] : null);  // slices.png's; air clear
    for (let i = 0; i < n; i++) {
      let g = Math.round(255 * (value(cut, cut.levels[i]) - lo) / Math.max(hi - lo, 1e-12));
      g = Math.min(255, Math.max(0, g));
      const c = colour(labels[i]);
      for (let k = 0; k < 3; k++) px[4 * i + k] = c ? Math.round(0.65 * g + 0.35 * c[k]) : g;  // slices.png's overlay
      px[4 * i + 3] = 255;
    }
    canvas.width = cols;
    canvas.height = rows;
    canvas.getContext("2d").putImageData(image, 0, 0);
    $("slice-caption").textContent = `z = ${h.z_mm.toFixed(3)} mm: ${h.views} views of ${h.detector_shape.join(" × ")} ` +
      `px, ${h.voxel_mm.toPrecision(3)} mm voxels, ${h.seconds.toFixed(1)} s; grey ${lo.toPrecision(3)} to ` +
      `${hi.toPrecision(3)} 1/cm`;
    $("slice-legend").innerHTML = Object.entries(h.names).filter(([k]) => k !== "0").map(([k, name]) => {
      const c = colour(Number(k));
      return `<span><i style="background: rgb(${c.join(",")})"></i>${k} ${name}</span>`;
    }).join(" ");
    preview.slice = { header: h, labels: Array.from(labels) };
  } catch (error) {
    $("slice-caption").textContent = "";
    $("error").textContent = String(error.message || error);
    $("error").hidden = false;
  } finally {
    $("slice").disabled = false;
  }
}

function start() {
  socket = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/frames${query}`);
  socket.binaryType = "arraybuffer";
  socket.addEventListener("message", received);
  socket.addEventListener("close", () => { $("error").textContent = "the preview server closed the connection"; $("error").hidden = false; });
  $("angle").addEventListener("input", () => setAngle(parseFloat($("angle").value), "slider"));
  $("angle-value").addEventListener("change", () => setAngle(parseFloat($("angle-value").value), "number"));
  $("output").addEventListener("change", () => {
    state.view.output = $("output").value;
    $("material-row").hidden = state.view.output !== "path_length";
    win.auto = true;
    send();
  });
  $("material").addEventListener("change", () => { state.view.material = parseInt($("material").value, 10); win.auto = true; send(); });
  $("noise").addEventListener("change", () => { state.view.noise = $("noise").checked; send(); });
  $("seed").addEventListener("change", () => { state.view.seed = parseInt($("seed").value, 10) || 0; send(); });
  $("level").addEventListener("input", fromWindowSliders);
  $("window").addEventListener("input", fromWindowSliders);
  $("auto").addEventListener("click", () => { win.auto = true; autoWindow(); paint(); histogram(); });
  $("save-settings").addEventListener("click", () => save("settings.toml"));
  $("slice").addEventListener("click", quickSlice);
  $("save-view").addEventListener("click", () => { save("view.tif"); save("view.png"); });
  const canvas = $("image");
  let drag = null;
  canvas.addEventListener("pointerdown", (e) => { drag = e.clientX; canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener("pointerup", () => { drag = null; });
  canvas.addEventListener("pointermove", (e) => {
    readout(e);
    if (drag === null || state.view.angle_deg === null) return;
    const step = (e.clientX - drag) * 0.5;  // half a degree per screen pixel
    drag = e.clientX;
    if (step) setAngle(state.view.angle_deg + step, "drag");
  });
}

start();
