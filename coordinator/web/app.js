// bmtree's web view: long-polls /state and draws the run (no library, nothing from the network).
"use strict";
const W = 170, H = 38, GX = 10, GY = 40;
const $ = (id) => document.getElementById(id);
let version = -1, mode = null, last = null, shownNodes = "";

function el(tag, attrs, text) {
  const e = document.createElementNS("http://www.w3.org/2000/svg", tag);
  for (const k in attrs) e.setAttribute(k, attrs[k]);
  if (text !== undefined) e.textContent = text;
  return e;
}

function label(s, i) {
  // "was SUCCESS" / "was FAILURE": its last outcome, drawn faded, after py_trees reset it (a
  // selector clears the children it moved past, a stopped tree its finished nodes)
  const st = s.status[String(i)] || "INVALID";
  if (st !== "INVALID") return st;
  if (s.halted.indexOf(i) >= 0) return "HALTED";
  const was = (s.last || {})[String(i)];
  return was ? "was " + was : "";
}

function layout(nodes) {
  // leaves take the next column; a parent sits above the middle of its children
  const kids = {}, pos = {};
  let roots = [], col = 0;
  for (const n of nodes) {
    if (n.parent === null || n.parent === undefined) roots.push(n.id);
    else (kids[n.parent] = kids[n.parent] || []).push(n.id);
  }
  function place(i, depth) {
    const ks = kids[i] || [];
    if (!ks.length) { pos[i] = [col++, depth]; return; }
    ks.forEach((k) => place(k, depth + 1));
    pos[i] = [(pos[ks[0]][0] + pos[ks[ks.length - 1]][0]) / 2, depth];
  }
  roots.forEach((r) => place(r, 0));
  return { pos, kids, cols: col };
}

function drawTree(s) {
  const g = $("graph");
  g.textContent = "";
  if (!s.nodes.length) return;
  const { pos, kids, cols } = layout(s.nodes);
  let depth = 0;
  for (const k in pos) depth = Math.max(depth, pos[k][1]);
  // depth goes right, siblings go down: a behaviour tree reads like an outline
  const svg = el("svg", { width: (depth + 1) * (W + GY) + GX, height: cols * (H + GX) + GX, id: "tree" });
  const xy = (i) => [GX + pos[i][1] * (W + GY), GX + pos[i][0] * (H + GX)];
  for (const n of s.nodes) {
    for (const k of kids[n.id] || []) {
      const [x1, y1] = xy(n.id), [x2, y2] = xy(k);
      const cls = label(s, k) === "RUNNING" ? "edge RUNNING" : "edge";
      svg.appendChild(el("path", { class: cls, d: `M${x1 + W},${y1 + H / 2} C${x1 + W + GY / 2},${y1 + H / 2} ${x2 - GY / 2},${y2 + H / 2} ${x2},${y2 + H / 2}` }));
    }
  }
  for (const n of s.nodes) {
    const [x, y] = xy(n.id), st = label(s, n.id);
    const grp = el("g", { class: "node " + st.replace(" ", "-"), "data-name": n.name, "data-status": st || "IDLE" });
    grp.appendChild(el("rect", { x, y, width: W, height: H, rx: 6 }));
    const name = n.name.length > 22 ? n.name.slice(0, 21) + "…" : n.name;
    grp.appendChild(el("text", { x: x + 6, y: y + 15 }, name));
    grp.appendChild(el("text", { x: x + 6, y: y + 32, fill: "#555" }, (n.kind || n.shape) + (st ? " · " + st : "")));
    const tip = el("title", {}, n.name + (s.feedback[String(n.id)] ? ": " + s.feedback[String(n.id)] : ""));
    grp.appendChild(tip);
    svg.appendChild(grp);
  }
  g.appendChild(svg);
}

function rows(id, items, cells) {
  const t = $(id);
  t.textContent = "";
  if (!items.length) { const r = t.insertRow(); r.insertCell().textContent = "none"; return; }
  for (const it of items) {
    const r = t.insertRow();
    for (const c of cells(it)) r.insertCell().textContent = c;
  }
}

const js = (v) => JSON.stringify(v);
const sec = (v) => (Number(v) || 0).toFixed(2) + "s";

function draw(s) {
  last = s;
  $("title").textContent = (s.tree && s.tree.name) || "(waiting for a run)";
  $("clock").textContent = "t=" + sec(s.t) + "  tick " + s.n;
  $("paused").hidden = !s.paused;
  const r = $("result");
  r.className = s.end ? s.end.status : "";
  r.textContent = s.end ? "result: " + s.end.status + " in " + sec(s.end.duration) + (s.end.reason ? " (" + s.end.reason + ")" : "") : "";
  drawTree(s);
  if (s.t !== anchor[0]) anchor = [s.t, Date.now()];
  drawPending(s);
  rows("blackboard", Object.keys(s.blackboard).sort(), (k) => [k, js(s.blackboard[k])]);
  const ev = s.events.map((e) => e.type === "notice" ? [e.t, sec(e.t), "ROS graph", e.text]
    : [e.t, sec(e.t), e.module + "." + e.event, js(e.params)])
    .concat(s.control.map((c) => [c.t, sec(c.t), "control " + c.command + " " + js(c.args || {}), c.answer]));
  ev.sort((a, b) => a[0] - b[0]);
  rows("events", ev.slice(-30), (e) => e.slice(1));
  rows("calls", s.calls.slice(-40), (c) => [sec(c.started), c.target, c.status, sec(c.duration), c.error || ""]);
  const names = s.nodes.map((n) => n.name).join("\n");
  if (names !== shownNodes) {
    shownNodes = names;
    const sel = $("node");
    sel.textContent = "";
    for (const n of s.nodes) { const o = document.createElement("option"); o.textContent = n.name; sel.appendChild(o); }
  }
  $("controls").hidden = !s.steer || gone;
}

let anchor = [null, 0];
function drawPending(s) {
  // the run's time moves on between records, and while it is paused (its calls run on): count it on
  // here, as the terminal does (not in a replay or after the end)
  const now = mode === "replay" || s.end || gone ? s.t : s.t + (Date.now() - anchor[1]) / 1000;
  $("clock").textContent = "t=" + sec(now) + "  tick " + s.n;
  rows("pending", s.pending, (c) => [c.target, sec(now - c.t) + " / " + (c.timeout ? c.timeout + "s" : "-"), js(c.inputs)]);
}
setInterval(() => { if (last) drawPending(last); }, 500);

let gone = false;
function setGone(g) {
  // the watch has ended (with its run) or is unreachable: the page keeps the last state it got
  gone = g;
  $("gone").hidden = !g;
  if (last) $("controls").hidden = !last.steer || g;
}

async function poll() {
  for (;;) {
    try {
      const res = await fetch("state?since=" + version);
      const s = await res.json();
      version = s.version;
      if (gone) setGone(false);
      if (s.mode === "replay") { startReplay(s); return; }
      draw(s);
    } catch (e) {
      if (last && !gone) setGone(true);
      await new Promise((ok) => setTimeout(ok, 1000));
    }
  }
}

function startReplay(s) {
  mode = "replay";
  $("timeline").hidden = false;
  const scrub = $("scrub");
  scrub.max = s.duration;
  scrub.value = s.at;
  $("at").textContent = sec(s.at) + " of " + sec(s.duration);
  draw(s);
  scrub.addEventListener("input", async () => {
    const res = await fetch("state?at=" + scrub.value);
    const st = await res.json();
    $("at").textContent = sec(st.at) + " of " + sec(st.duration);
    draw(st);
  });
}

async function control(cmd) {
  const res = await fetch("control", { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(cmd) });
  const a = await res.json();
  $("answer").textContent = (a.ok ? "ok: " : "refused: ") + a.answer;
}

$("pause").onclick = () => control({ command: "pause" });
$("resume").onclick = () => control({ command: "resume" });
$("step").onclick = () => control({ command: "step" });
$("break").onclick = () => control({ command: "break", node: $("node").value });
$("clear").onclick = () => control({ command: "clear", node: $("node").value });
$("force-success").onclick = () => control({ command: "force", node: $("node").value, outcome: "SUCCESS" });
$("force-failure").onclick = () => control({ command: "force", node: $("node").value, outcome: "FAILURE" });
$("set").onclick = () => control({ command: "set", key: $("key").value, value: $("value").value });
poll();
