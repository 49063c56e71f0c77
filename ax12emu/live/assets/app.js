// ax12emu live view: frames from /ws, drawn on canvases by hand; controls posted to /api/control.
"use strict";

const HISTORY_S = 60;          // the longest plot window kept
const LOG_KEEP = 400;          // lines kept in the page's log
const LOG_REDRAW_MS = 200;     // how often the log is redrawn when it changed
const cards = new Map();       // "protocol/slot" -> {el, dial, plots, cells, bitEls, history, labels}
let logLines = [];
let knownIns = new Set();
let lastFrame = null;

const $ = (id) => document.getElementById(id);

function say(text, ok) {
  const m = $("message");
  m.textContent = text;
  m.className = ok ? "ok" : "";
}

async function control(message) {
  try {
    const r = await fetch("/api/control", {method: "POST", headers: {"Content-Type": "application/json"}, body: JSON.stringify(message)});
    const body = await r.json();
    if (r.ok) say(body.log, true); else say(`${r.status}: ${body.error}`, false);
  } catch (e) {
    say(`control failed: ${e}`, false);
  }
}

// -- cards ----------------------------------------------------------------------------------
// Every servo, AX-12 or X series, comes with its readings (position, goal, velocity, current or
// load, PWM, voltage, temperature: register, raw value, value in its unit), so one card fits all.
function readings(servo) {
  const out = {};
  for (const r of servo.readings) out[r.name] = r;
  return out;
}
function shown(r) {
  if (!r) return "–";
  return r.value === null ? String(r.raw) : `${+r.value.toFixed(2)} ${r.unit} (${r.raw})`;
}
function degrees(r) { return r && r.value !== null ? ` (${r.value.toFixed(1)}°)` : ""; }
const yesNo = (v) => v ? "yes" : "no";

const FIELDS = [
  ["position", (s, r) => `${r.position.raw}${degrees(r.position)} → ${r.goal.raw}${degrees(r.goal)}`],
  ["mode", (s) => s.mode + (s.limits ? ` ${s.limits[0]}..${s.limits[1]}` : "")],
  ["velocity", (s, r) => shown(r.velocity)],
  ["current", (s, r) => shown(r.current)],
  ["load", (s, r) => shown(r.load)],
  ["PWM", (s, r) => shown(r.pwm)],
  ["voltage", (s, r) => shown(r.voltage)],
  ["temperature", (s, r) => shown(r.temperature)],
  ["baud", (s) => s.baud_bps === null ? "–" : `${s.baud_bps.toLocaleString("en-US", {maximumFractionDigits: 0})} bps` + ("baud_rate" in s.registers ? ` (${s.registers.baud_rate})` : "")],
  ["torque", (s) => s.registers.torque_enable ? "on" : "off"],
  ["LED", (s) => "led" in s.registers ? (s.registers.led ? "on" : "off") : "–"],
  ["moving", (s) => yesNo(s.registers.moving)],
  ["errors", (s) => "hardware_error_status" in s.registers ? `Hardware Error Status 0x${s.alarms.toString(16).padStart(2, "0")}` : `status 0x${s.alarms.toString(16).padStart(2, "0")}`],
];

// A mixed wire has one ID per protocol: the card is keyed and named by both.
function cardKey(servo) { return `${servo.protocol}/${servo.slot}`; }
function cardId(servo, mixed) { return mixed ? `servo-${servo.slot}-p${servo.protocol.replace(".", "")}` : `servo-${servo.slot}`; }

function makeCard(servo, frame, mixed) {
  const node = $("card-template").content.firstElementChild.cloneNode(true);
  node.id = cardId(servo, mixed);
  node.dataset.slot = servo.slot;
  node.dataset.protocol = servo.protocol;
  node.dataset.mixed = mixed ? "1" : "";
  const fields = node.querySelector(".fields");
  const cells = {};
  for (const [name] of FIELDS) {
    const row = fields.insertRow();
    row.insertCell().textContent = name;
    cells[name] = row.insertCell();
  }
  const bits = node.querySelector(".bits");
  const bitEls = {};
  for (const name of servo.alarm_bits) {
    const span = document.createElement("span");
    span.textContent = name;
    bits.appendChild(span);
    bitEls[name] = span;
  }
  const choices = node.querySelector("[data-field=alarm]");
  for (const name of frame.alarm_choices[servo.protocol]) choices.appendChild(Object.assign(document.createElement("option"), {textContent: name}));
  const volts = readings(servo).voltage;
  if (volts && volts.value !== null) node.querySelector("[data-field=volts]").value = volts.value;
  node.querySelectorAll("button[data-act]").forEach((b) => b.addEventListener("click", () => servoAction(node, b.dataset.act)));
  $("cards").appendChild(node);
  const card = {el: node, dial: node.querySelector(".dial"), plots: [...node.querySelectorAll(".plot")], cells, bitEls, history: []};
  cards.set(cardKey(servo), card);
  return card;
}

function servoAction(node, act) {
  const slot = Number(node.dataset.slot);
  const id = Number(node.dataset.id);
  // Only a mixed wire needs the protocol: there an ID may be taken once per protocol.
  const on = node.dataset.mixed ? {protocol: Number(node.dataset.protocol)} : {};
  const field = (name) => node.querySelector(`[data-field=${name}]`).value;
  const messages = {
    vanish: {action: "vanish", slot}, reappear: {action: "reappear", slot},
    stall: {action: "stall", slot}, release: {action: "release", slot},
    alarm: {action: "alarm", slot, bits: field("alarm")}, clear_alarm: {action: "clear_alarm", slot},
    external_torque: {action: "external_torque", id, nm: Number(field("nm"))},
    external_torque_off: {action: "external_torque", id, nm: 0},
    temperature: {action: "temperature", id, celsius: Number(field("celsius"))},
    temperature_off: {action: "temperature", id, celsius: null},
    voltage: {action: "voltage", id, volts: Number(field("volts"))},
    voltage_off: {action: "voltage", id, volts: null},
  };
  control({...messages[act], ...on});
}

// The goal register's span covers the model's range (AX-12: 0..1023 over 300 degrees, 1023 at the end, the
// dead band down; X series: 4096 counts a whole turn, 4096 back at 0); the middle points up.  Extended
// positions wrap.  dial.counts: the counts over range_deg, as the snapshot's degrees take them.
function dialAngle(position, dial) {
  const span = dial.max + 1;
  const wrapped = ((position % span) + span) % span;
  return (-90 - dial.range_deg / 2 + wrapped * dial.range_deg / dial.counts) * Math.PI / 180;
}

function drawDial(canvas, servo, r) {
  const ctx = canvas.getContext("2d");
  const w = canvas.width, h = canvas.height, cx = w / 2, cy = h / 2, radius = Math.min(w, h) / 2 - 8;
  const dial = servo.dial || {max: 1023, range_deg: 300, counts: 1023};
  const present = r.position.raw, goal = r.goal.raw;
  ctx.clearRect(0, 0, w, h);
  ctx.lineWidth = 6;
  ctx.strokeStyle = "#e0e0e0";
  ctx.beginPath(); ctx.arc(cx, cy, radius, dialAngle(0, dial), dialAngle(0, dial) + dial.range_deg * Math.PI / 180); ctx.stroke();
  if (servo.limits) {
    ctx.strokeStyle = "#90caf9";
    ctx.beginPath(); ctx.arc(cx, cy, radius, dialAngle(servo.limits[0], dial), dialAngle(servo.limits[1], dial)); ctx.stroke();
  }
  const needle = (pos, color, width, len) => {
    const a = dialAngle(pos, dial);
    ctx.strokeStyle = color; ctx.lineWidth = width;
    ctx.beginPath(); ctx.moveTo(cx, cy); ctx.lineTo(cx + Math.cos(a) * radius * len, cy + Math.sin(a) * radius * len); ctx.stroke();
  };
  needle(goal, "#e53935", 2, 0.95);
  needle(present, "#263238", 4, 0.8);
  ctx.fillStyle = "#263238";
  ctx.font = "12px sans-serif"; ctx.textAlign = "center";
  ctx.fillText(String(present), cx, cy + radius * 0.55);
  canvas.dataset.present = present;
  canvas.dataset.goal = goal;
}

const PLOTS = {
  position: {lines: [["pos", "#263238"], ["goal", "#e53935"]], range: (hist, card) => spanOf(hist, ["pos", "goal"], card.positionMax)},
  speed: {lines: [["speed", "#1565c0"]], range: (hist) => symmetric(hist, "speed")},
  load: {lines: [["load", "#6a1b9a"]], range: (hist) => symmetric(hist, "load")},
};

// Positions past the goal register's span (extended position mode) widen the plot.
function spanOf(hist, keys, max) {
  let lo = 0, hi = max;
  for (const p of hist) for (const k of keys) { lo = Math.min(lo, p[k]); hi = Math.max(hi, p[k]); }
  return [lo, hi];
}

function symmetric(hist, key) {
  let m = 16;
  for (const p of hist) m = Math.max(m, Math.abs(p[key]));
  return [-m, m];
}

function drawPlot(canvas, card, now, windowS) {
  const hist = card.history;
  const spec = PLOTS[canvas.dataset.kind];
  const ctx = canvas.getContext("2d");
  const w = canvas.width, h = canvas.height;
  const [lo, hi] = spec.range(hist, card);
  ctx.clearRect(0, 0, w, h);
  ctx.fillStyle = "#999"; ctx.font = "10px sans-serif"; ctx.textAlign = "left";
  ctx.fillText(`${card.labels[canvas.dataset.kind]} (${lo}..${hi}), last ${windowS} s`, 4, 10);
  const x = (t) => w - (now - t) / windowS * w;
  const y = (v) => h - 2 - (v - lo) / (hi - lo) * (h - 14);
  let points = 0;
  for (const [key, color] of spec.lines) {
    ctx.strokeStyle = color; ctx.lineWidth = 1.5; ctx.beginPath();
    let first = true;
    for (const p of hist) {
      if (now - p.t > windowS) continue;
      if (first) { ctx.moveTo(x(p.t), y(p[key])); first = false; } else ctx.lineTo(x(p.t), y(p[key]));
      points++;
    }
    ctx.stroke();
  }
  const last = hist[hist.length - 1];
  if (last) {
    canvas.dataset.last = JSON.stringify({pos: last.pos, goal: last.goal, speed: last.speed, load: last.load});
  }
  canvas.dataset.points = points;
}

function updateCard(card, servo, frame) {
  const node = card.el;
  const r = readings(servo);
  node.dataset.id = servo.id;
  node.querySelector(".name").textContent = `ID ${servo.id}` + (servo.id !== servo.slot ? ` (slot ${servo.slot})` : "");
  node.querySelector(".model").textContent = `${servo.model} · protocol ${servo.protocol} · ${servo.profile}`;
  for (const [name, show] of FIELDS) card.cells[name].textContent = show(servo, r);
  for (const name in card.bitEls) card.bitEls[name].className = servo.alarm_names.includes(name) ? "set" : "";
  const faults = node.querySelector(".faults");
  faults.replaceChildren(...servo.faults.map((text) => Object.assign(document.createElement("span"), {textContent: text})));
  node.classList.toggle("alarm", servo.alarm_names.length > 0 || servo.faults.length > 0);
  // The load plot shows the current where the servo senses it (X series), else its load.
  const effort = r.current || r.load || {raw: 0, name: "load"};
  const velocity = r.velocity || {raw: 0, name: "velocity"};
  card.labels = {position: "position", speed: velocity.name + " (raw)", load: effort.name + " (raw)"};
  card.positionMax = servo.dial ? servo.dial.max : 1023;
  card.history.push({t: frame.wall_s, pos: r.position.raw, goal: r.goal.raw, speed: velocity.raw, load: effort.raw});
  while (card.history.length && frame.wall_s - card.history[0].t > HISTORY_S) card.history.shift();
  drawDial(card.dial, servo, r);
  const windowS = Number($("window-s").value);
  for (const plot of card.plots) drawPlot(plot, card, frame.wall_s, windowS);
}

// -- log ------------------------------------------------------------------------------------
function addLog(lines) {
  for (const line of lines) {
    logLines.push(line);
    if (line.ins && !knownIns.has(line.ins)) {
      knownIns.add(line.ins);
      $("filter-ins").appendChild(Object.assign(document.createElement("option"), {value: line.ins, textContent: line.ins}));
    }
  }
  if (logLines.length > LOG_KEEP) logLines = logLines.slice(-LOG_KEEP);
  logDirty = true;
}

// The log is redrawn a few times a second, not per frame: rebuilding hundreds of rows 25 times a
// second would cost the machine (and so, on a small one, the bus) more than the rest of the page.
let logDirty = false;
setInterval(() => { if (logDirty && !$("log-hold").checked) { logDirty = false; renderLog(); } }, LOG_REDRAW_MS);

function renderLog() {
  const idText = $("filter-id").value.trim();
  const ids = idText ? new Set(idText.split(/[ ,]+/).map(Number)) : null;
  const ins = $("filter-ins").value;
  const pre = $("log");
  const rows = [];
  for (const line of logLines) {
    if (ids && !ids.has(line.id)) continue;
    if (ins && line.ins !== ins) continue;
    const t = line.t === null ? "" : line.t.toFixed(6).padStart(12);
    const span = document.createElement("div");
    span.className = line.who;
    span.textContent = `${t}  ${line.who.padEnd(7)} ${line.text}`;
    rows.push(span);
  }
  pre.replaceChildren(...rows);
  pre.scrollTop = pre.scrollHeight;
}

// -- frames ---------------------------------------------------------------------------------
function onFrame(frame) {
  lastFrame = frame;
  const mixed = frame.protocols.length > 1;
  for (const servo of frame.servos) {
    const card = cards.get(cardKey(servo)) || makeCard(servo, frame, mixed);
    updateCard(card, servo, frame);
  }
  const s = frame.stats;
  $("clock").textContent = `t = ${frame.sim_time_s.toFixed(3)} s ${frame.paused ? "(paused)" : ""} · Protocol ${frame.protocols.join(" + ")}`;
  $("stats").textContent = `packets/s ${s.packets_per_s.toFixed(0)} · packets ${s.packets} · status errors ${s.status_errors} · checksum errors in the log ${s.checksum_errors} · timeouts injected ${s.timeouts_injected} · corrupt injected ${s.corrupt_injected}`;
  document.body.dataset.frames = frame.seq;
  if (frame.log.length) addLog(frame.log);
}

function connect() {
  const ws = new WebSocket(`ws://${location.host}/ws`);
  ws.onopen = () => { $("conn").textContent = "live"; $("conn").className = "badge on"; };
  ws.onclose = () => { $("conn").textContent = "disconnected"; $("conn").className = "badge off"; setTimeout(connect, 1000); };
  ws.onmessage = (event) => {
    const msg = JSON.parse(event.data);
    if (msg.type === "frame") onFrame(msg);
    else if (msg.type === "hello") { logLines = []; addLog(msg.log); }
  };
}

$("pause").addEventListener("click", () => control({action: "pause"}));
$("resume").addEventListener("click", () => control({action: "resume"}));
$("step").addEventListener("click", () => control({action: "step", seconds: Number($("step-s").value)}));
$("apply-reply-faults").addEventListener("click", () => control({action: "reply_faults", drop: Number($("drop").value), corrupt: Number($("corrupt").value), delay: Number($("delay").value)}));
$("clear-faults").addEventListener("click", () => control({action: "clear_faults"}));
for (const id of ["filter-id", "filter-ins", "log-hold"]) $(id).addEventListener("input", renderLog);
connect();
