// ax12emu live view: frames from /ws, drawn on canvases by hand; controls posted to /api/control.
"use strict";

const HISTORY_S = 60;          // the longest plot window kept
const LOG_KEEP = 400;          // lines kept in the page's log
const LOG_REDRAW_MS = 200;     // how often the log is redrawn when it changed
const cards = new Map();       // servo slot -> {el, dial, plots, fields, history}
let logLines = [];
let knownIns = new Set();
let lastFrame = null;

function signed(v) { return (v & 0x400) ? -(v & 0x3ff) : v; }
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
const FIELDS = [
  ["position", (s) => `${s.registers.present_position} → ${s.registers.goal_position}`],
  ["speed", (s) => signed(s.registers.present_speed)],
  ["load", (s) => signed(s.registers.present_load)],
  ["voltage", (s) => `${(s.registers.present_voltage / 10).toFixed(1)} V`],
  ["temperature", (s) => `${s.registers.present_temperature} °C`],
  ["torque", (s) => s.registers.torque_enable ? "on" : "off"],
  ["LED", (s) => s.registers.led ? "on" : "off"],
  ["limits", (s) => s.wheel_mode ? "wheel mode" : `${s.registers.cw_angle_limit}..${s.registers.ccw_angle_limit}`],
  ["moving", (s) => s.registers.moving ? "yes" : "no"],
];
const ERROR_BITS = ["input_voltage", "angle_limit", "overheating", "range", "checksum", "overload", "instruction"];

function makeCard(servo) {
  const node = $("card-template").content.firstElementChild.cloneNode(true);
  node.id = `servo-${servo.slot}`;
  node.dataset.slot = servo.slot;
  const fields = node.querySelector(".fields");
  const cells = {};
  for (const [name] of FIELDS) {
    const row = fields.insertRow();
    row.insertCell().textContent = name;
    cells[name] = row.insertCell();
  }
  const bits = node.querySelector(".bits");
  const bitEls = {};
  for (const name of ERROR_BITS) {
    const span = document.createElement("span");
    span.textContent = name;
    bits.appendChild(span);
    bitEls[name] = span;
  }
  node.querySelectorAll("button[data-act]").forEach((b) => b.addEventListener("click", () => servoAction(node, b.dataset.act)));
  $("cards").appendChild(node);
  const card = {el: node, dial: node.querySelector(".dial"), plots: [...node.querySelectorAll(".plot")], cells, bitEls, history: []};
  cards.set(servo.slot, card);
  return card;
}

function servoAction(node, act) {
  const slot = Number(node.dataset.slot);
  const id = Number(node.dataset.id);
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
  control(messages[act]);
}

// The AX-12's 0..1023 covers 300 degrees; 512 points up, the 60-degree dead band down.
function dialAngle(position) { return (-90 - 150 + position * 300 / 1023) * Math.PI / 180; }

function drawDial(canvas, servo) {
  const ctx = canvas.getContext("2d");
  const w = canvas.width, h = canvas.height, cx = w / 2, cy = h / 2, r = Math.min(w, h) / 2 - 8;
  const reg = servo.registers;
  ctx.clearRect(0, 0, w, h);
  ctx.lineWidth = 6;
  ctx.strokeStyle = "#e0e0e0";
  ctx.beginPath(); ctx.arc(cx, cy, r, dialAngle(0), dialAngle(1023)); ctx.stroke();
  if (!servo.wheel_mode) {
    ctx.strokeStyle = "#90caf9";
    ctx.beginPath(); ctx.arc(cx, cy, r, dialAngle(reg.cw_angle_limit), dialAngle(reg.ccw_angle_limit)); ctx.stroke();
  }
  const needle = (pos, color, width, len) => {
    const a = dialAngle(pos);
    ctx.strokeStyle = color; ctx.lineWidth = width;
    ctx.beginPath(); ctx.moveTo(cx, cy); ctx.lineTo(cx + Math.cos(a) * r * len, cy + Math.sin(a) * r * len); ctx.stroke();
  };
  needle(reg.goal_position, "#e53935", 2, 0.95);
  needle(reg.present_position, "#263238", 4, 0.8);
  ctx.fillStyle = "#263238";
  ctx.font = "12px sans-serif"; ctx.textAlign = "center";
  ctx.fillText(String(reg.present_position), cx, cy + r * 0.55);
  canvas.dataset.present = reg.present_position;
  canvas.dataset.goal = reg.goal_position;
}

const PLOTS = {
  position: {lines: [["pos", "#263238"], ["goal", "#e53935"]], range: () => [0, 1023]},
  speed: {lines: [["speed", "#1565c0"]], range: (hist) => symmetric(hist, "speed")},
  load: {lines: [["load", "#6a1b9a"]], range: (hist) => symmetric(hist, "load")},
};

function symmetric(hist, key) {
  let m = 16;
  for (const p of hist) m = Math.max(m, Math.abs(p[key]));
  return [-m, m];
}

function drawPlot(canvas, hist, now, windowS) {
  const spec = PLOTS[canvas.dataset.kind];
  const ctx = canvas.getContext("2d");
  const w = canvas.width, h = canvas.height;
  const [lo, hi] = spec.range(hist);
  ctx.clearRect(0, 0, w, h);
  ctx.fillStyle = "#999"; ctx.font = "10px sans-serif"; ctx.textAlign = "left";
  ctx.fillText(`${canvas.dataset.kind} (${lo}..${hi}), last ${windowS} s`, 4, 10);
  const x = (t) => w - (now - t) / windowS * w;
  const y = (v) => h - 2 - (v - lo) / (hi - lo) * (h - 14);
  let shown = 0;
  for (const [key, color] of spec.lines) {
    ctx.strokeStyle = color; ctx.lineWidth = 1.5; ctx.beginPath();
    let first = true;
    for (const p of hist) {
      if (now - p.t > windowS) continue;
      if (first) { ctx.moveTo(x(p.t), y(p[key])); first = false; } else ctx.lineTo(x(p.t), y(p[key]));
      shown++;
    }
    ctx.stroke();
  }
  const last = hist[hist.length - 1];
  if (last) {
    canvas.dataset.last = JSON.stringify({pos: last.pos, goal: last.goal, speed: last.speed, load: last.load});
  }
  canvas.dataset.points = shown;
}

function updateCard(card, servo, frame) {
  const node = card.el;
  node.dataset.id = servo.id;
  node.querySelector(".name").textContent = `ID ${servo.id}` + (servo.id !== servo.slot ? ` (slot ${servo.slot})` : "");
  node.querySelector(".model").textContent = `${servo.model} · protocol ${servo.protocol} · ${servo.profile}`;
  for (const [name, show] of FIELDS) card.cells[name].textContent = show(servo);
  for (const name of ERROR_BITS) card.bitEls[name].className = servo.alarm_names.includes(name) ? "set" : "";
  const faults = node.querySelector(".faults");
  faults.replaceChildren(...servo.faults.map((text) => Object.assign(document.createElement("span"), {textContent: text})));
  node.classList.toggle("alarm", servo.alarm_names.length > 0 || servo.faults.length > 0);
  const reg = servo.registers;
  card.history.push({t: frame.wall_s, pos: reg.present_position, goal: reg.goal_position, speed: signed(reg.present_speed), load: signed(reg.present_load)});
  while (card.history.length && frame.wall_s - card.history[0].t > HISTORY_S) card.history.shift();
  drawDial(card.dial, servo);
  const windowS = Number($("window-s").value);
  for (const plot of card.plots) drawPlot(plot, card.history, frame.wall_s, windowS);
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
  for (const servo of frame.servos) {
    const card = cards.get(servo.slot) || makeCard(servo);
    updateCard(card, servo, frame);
  }
  const s = frame.stats;
  $("clock").textContent = `t = ${frame.sim_time_s.toFixed(3)} s ${frame.paused ? "(paused)" : ""}`;
  $("stats").textContent = `packets/s ${s.packets_per_s.toFixed(0)} · packets ${s.packets} · status errors ${s.status_errors} · checksum errors ${s.checksum_errors} · timeouts injected ${s.timeouts_injected} · corrupt injected ${s.corrupt_injected}`;
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
