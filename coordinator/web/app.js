// bmtree's web view: long-polls /state and draws the run (no library, nothing from the network).
"use strict";
// a node's box: W wide, up to three lines of text, centred (the name on up to two, then kind and
// status; a failed node's reason, cut to a line, replaces the name's second one), GX between rows,
// GY between depths
const W = 240, H = 52, GX = 12, GY = 44, PAD = 6, LINE = 14, FONT = "12px sans-serif";
const QUIET_MS = 5000; // the view follows the run only when the user has not scrolled it for this long
const SAID_MS = 6000; // the run's answer to a button is shown this long (and only while the same run is)
const $ = (id) => document.getElementById(id);
let version = -1, mode = null, last = null, shownNodes = "", gone = false;
let boxes = {}, depths = {}, focused = null, rootId = null, culprit = null, userScrolled = 0, ours = null, replayMeta = {};

function el(tag, attrs, text) {
  const e = document.createElementNS("http://www.w3.org/2000/svg", tag);
  for (const k in attrs) e.setAttribute(k, attrs[k]);
  if (text !== undefined) e.textContent = text;
  return e;
}

const measure = (() => {
  const ctx = document.createElement("canvas").getContext("2d");
  ctx.font = FONT;
  return (t) => ctx.measureText(t).width;
})();
const wrapped = new Map();

function wrap(text, width, lines) {
  // up to `lines` lines of at most `width` px, broken at spaces (inside a word only when it must);
  // what does not fit ends the last line with "…"
  const memo = text + "\u0000" + width + "\u0000" + lines;
  if (wrapped.has(memo)) return wrapped.get(memo);
  const out = [];
  let rest = String(text).replace(/\s+/g, " ").trim();
  while (rest && out.length < lines) {
    if (measure(rest) <= width) { out.push(rest); rest = ""; break; }
    let lo = 1, hi = rest.length; // the longest prefix that fits
    while (lo < hi) { const mid = (lo + hi + 1) >> 1; if (measure(rest.slice(0, mid)) <= width) lo = mid; else hi = mid - 1; }
    if (out.length === lines - 1) {
      let n = lo;
      while (n > 1 && measure(rest.slice(0, n).trimEnd() + "…") > width) n--;
      out.push(rest.slice(0, n).trimEnd() + "…");
      rest = "";
      break;
    }
    const space = rest.lastIndexOf(" ", lo);
    const cut = space > lo / 3 ? space : lo;
    out.push(rest.slice(0, cut).trimEnd());
    rest = rest.slice(cut).trimStart();
  }
  if (wrapped.size > 5000) wrapped.clear();
  wrapped.set(memo, out);
  return out;
}

// a run's status as people read it: py_trees' INVALID of a run stopped by Ctrl-C is INTERRUPTED
const statusWord = (st) => (st === "INVALID" ? "INTERRUPTED" : st);
// a node's name as shown: an include's with the values its arguments had (fetch_item(item="milk"))
const nameOf = (s, n) => (s.labels || {})[String(n.id)] || n.name;

function label(s, i) {
  // "was SUCCESS" / "was FAILURE": its last outcome, drawn faded, after py_trees reset it (a
  // selector clears the children it moved past, a stopped tree its finished nodes); the server says
  // each node's (`words`: the watch's own, also INTERRUPTED for the top node of a tree with cleanup)
  if (s.words) return s.words[String(i)] || "";
  const st = s.status[String(i)] || "INVALID";
  if (st !== "INVALID") return st;
  if (s.halted.indexOf(i) >= 0) return "HALTED";
  const was = (s.last || {})[String(i)];
  return was ? "was " + was : "";
}

const failedLabel = (st) => st === "FAILURE" || st === "was FAILURE";

// where a running loop or wait is (the server's words, `progress`): "item 2 of 3", "attempt 2", and
// with "{s}" the seconds since `since` (or until `until`) at the run's time `now`: "waited 3.2 s"
function fillProgress(p, now) {
  const text = String(p.text || "");
  if (text.indexOf("{s}") < 0) return text;
  const secs = p.until !== undefined && p.until !== null ? Number(p.until) - now : now - Number(p.since || now);
  return text.replace("{s}", Math.max(0, secs).toFixed(1) + " s");
}
// the run's time now: its last state's, moved on by the page's clock while the run goes
const nowOf = (s) => (mode === "replay" || s.end || gone ? s.t : anchor[0] + (Date.now() - anchor[1]) / 1000);

function culpritOf(s) {
  // the leaf whose failure ended the run: a replay knows it (where `replay --failure` goes), once it
  // happened; live, the node the end's reason starts with ("look for it: vision.find_object ...")
  const f = replayMeta.failure;
  if (mode === "replay") return f && s.t >= f.t - 1e-6 ? f.node : null;
  const why = s.end && s.end.status === "FAILURE" ? String(s.end.reason || "") : "";
  let best = null, len = 0;
  for (const n of s.nodes) {
    if (why && n.name.length > len && (why.startsWith(n.name + ":") || why.startsWith(n.name + " ("))) { best = n.id; len = n.name.length; }
  }
  return best;
}

function layout(nodes) {
  // leaves take the next row; a parent sits level with the middle of its children
  const kids = {}, pos = {}, roots = [];
  let col = 0;
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
  return { pos, kids, cols: col, root: roots.length ? roots[0] : null };
}

function drawTree(s) {
  const g = $("graph");
  if (!s.nodes.length) { g.textContent = ""; boxes = {}; return; }
  const { pos, kids, cols, root } = layout(s.nodes);
  rootId = root;
  let depth = 0;
  for (const k in pos) depth = Math.max(depth, pos[k][1]);
  // depth goes right, siblings go down: a behaviour tree reads like an outline
  // a killed run, or one whose node does not answer the watch now: what runs is only what it was when last seen
  const stale = (s.end && s.end.status === "UNFINISHED") || !!s.silent;
  const svg = el("svg", { width: (depth + 1) * (W + GY) + GX, height: cols * (H + GX) + GX, id: "tree",
    class: stale ? "stale" : "" });
  const xy = (i) => [GX + pos[i][1] * (W + GY), GX + pos[i][0] * (H + GX)];
  boxes = {};
  depths = {};
  for (const n of s.nodes) {
    depths[n.id] = pos[n.id][1];
    for (const k of kids[n.id] || []) {
      const [x1, y1] = xy(n.id), [x2, y2] = xy(k);
      const cls = label(s, k) === "RUNNING" ? "edge RUNNING" : "edge";
      svg.appendChild(el("path", { class: cls, d: `M${x1 + W},${y1 + H / 2} C${x1 + W + GY / 2},${y1 + H / 2} ${x2 - GY / 2},${y2 + H / 2} ${x2},${y2 + H / 2}` }));
    }
  }
  const now = nowOf(s);
  const breaks = s.breaks || [];
  for (const n of s.nodes) {
    const [x, y] = xy(n.id), st = label(s, n.id);
    boxes[n.id] = [x, y];
    const feedback = s.feedback[String(n.id)] || "";
    const why = failedLabel(st) ? feedback : "";
    // steering: held at a breakpoint (RUNNING, not started), an outcome forced by control
    const note = (s.notes || {})[String(n.id)] || "";
    const cls = "node " + st.replace(" ", "-") + (n.id === culprit && failedLabel(st) ? " culprit" : "")
      + (note === "held at breakpoint" ? " held" : note === "forced" ? " forced" : "");
    const grp = el("g", { class: cls, "data-name": n.name, "data-status": st || "IDLE", "data-id": n.id,
      "data-note": note, "data-break": breaks.indexOf(n.id) >= 0 ? "1" : "" });
    grp.appendChild(el("rect", { x, y, width: W, height: H, rx: 6 }));
    if (breaks.indexOf(n.id) >= 0) { // a breakpoint is set on it
      const dot = el("circle", { cx: x + W - 9, cy: y + 9, r: 5, class: "bp" });
      dot.appendChild(el("title", {}, "breakpoint: the run pauses before it starts"));
      grp.appendChild(dot);
    }
    // a for_each's element, a retry's attempt, how long a wait has waited ("item 2 of 4", "attempt 2"):
    // a line of its own, as a failed node's reason
    const prog = st === "RUNNING" ? (s.progress || {})[String(n.id)] : null;
    const extra = why || prog;
    const name = wrap(nameOf(s, n), W - 2 * PAD - (breaks.indexOf(n.id) >= 0 ? 14 : 0), extra ? 1 : 2);
    const y0 = y + Math.round((H - (name.length + (extra ? 2 : 1)) * LINE) / 2) + 11; // the lines centred in the box
    name.forEach((line, k) => grp.appendChild(el("text", { x: x + PAD, y: y0 + k * LINE, class: "name" }, line)));
    const kind = (n.kind || n.shape) + (st ? " · " + st : "") + (note ? " (" + note + ")" : "");
    grp.appendChild(el("text", { x: x + PAD, y: y0 + name.length * LINE, fill: "#555", class: "kind" },
      wrap(kind, W - 2 * PAD, 1)[0]));
    if (why) grp.appendChild(el("text", { x: x + PAD, y: y0 + 2 * LINE, class: "reason" }, wrap(why, W - 2 * PAD, 1)[0]));
    else if (prog) {
      const line = el("text", { x: x + PAD, y: y0 + 2 * LINE, class: "progress" }, fillProgress(prog, now));
      line.dataset.progress = JSON.stringify(prog);
      grp.appendChild(line);
    }
    grp.appendChild(el("title", {}, nameOf(s, n) + (note ? " (" + note + ")" : "") + (feedback ? ": " + feedback : "")));
    svg.appendChild(grp);
  }
  const old = g.firstChild;
  if (old) g.replaceChild(svg, old); else g.appendChild(svg);
}

// following the run: the root on load, then the running (or failed) node whenever it changes, unless
// the user scrolled the graph in the last QUIET_MS
function focusOf(s) {
  const deepest = (want) => {
    let best = null, bd = -1;
    for (const n of s.nodes) if (want(n) && depths[n.id] > bd) { best = n.id; bd = depths[n.id]; }
    return best;
  };
  const running = deepest((n) => label(s, n.id) === "RUNNING");
  if (running !== null) return running;
  if (culprit !== null && failedLabel(label(s, culprit))) return culprit;
  const failed = deepest((n) => label(s, n.id) === "FAILURE" && s.feedback[String(n.id)]);
  return failed !== null ? failed : rootId;
}

function scrollGraph(left, top) {
  const g = $("graph");
  g.scrollLeft = Math.max(0, left);
  g.scrollTop = Math.max(0, top);
  ours = [g.scrollLeft, g.scrollTop]; // a scroll event at this place is ours, not the user's
}

function follow(s, force) {
  // force: the user asked for it (jump to the failure): the culprit, whatever else runs then
  const g = $("graph");
  const first = focused === null;
  const target = force && culprit !== null ? culprit : focusOf(s);
  if (target === null || !boxes[target]) return;
  if (!force && target === focused) return;
  if (!force && !first && Date.now() - userScrolled < QUIET_MS) return;
  focused = target;
  if (first && rootId !== null && boxes[rootId]) { // the root first, at the left, level with the middle
    scrollGraph(0, boxes[rootId][1] + H / 2 - g.clientHeight / 2);
  }
  const [x, y] = boxes[target], m = 16;
  let left = g.scrollLeft, top = g.scrollTop;
  if (x - m < left || x + W + m > left + g.clientWidth) left = Math.min(x - m, x + W + GY - g.clientWidth); // with its parents to its left
  if (y - m < top || y + H + m > top + g.clientHeight) top = y + H / 2 - g.clientHeight / 2;
  if (left !== g.scrollLeft || top !== g.scrollTop) scrollGraph(left, top);
}

(function watchUser() {
  const g = $("graph");
  const mark = () => { userScrolled = Date.now(); };
  for (const ev of ["wheel", "mousedown", "touchstart", "keydown"]) g.addEventListener(ev, mark, { passive: true });
  g.addEventListener("scroll", () => {
    if (ours && Math.abs(g.scrollLeft - ours[0]) <= 1 && Math.abs(g.scrollTop - ours[1]) <= 1) return;
    ours = null;
    mark();
  }, { passive: true });
})();

function rows(id, items, cells, cols) {
  // cells(item): the cells' texts, or [texts, the row's class]; cols: each column's class
  const t = $(id);
  t.textContent = "";
  if (!items.length) { const r = t.insertRow(); r.insertCell().textContent = "none"; return; }
  for (const it of items) {
    let c = cells(it), cls = "";
    if (c.length === 2 && Array.isArray(c[0])) [c, cls] = c;
    const r = t.insertRow();
    if (cls) r.className = cls;
    c.forEach((text, k) => { const d = r.insertCell(); d.textContent = text; if (cols[k]) d.className = cols[k]; });
  }
}

// a value as compact JSON; a float JSON has no number for comes as {"$numberDouble": "NaN"} ("Infinity",
// "-Infinity": runstream.to_json) and is shown bare, NaN, Infinity, -Infinity, as the terminal shows it
const NONFINITE = "$numberDouble", NONFINITE_TEXTS = ["NaN", "Infinity", "-Infinity"];
function js(v) {
  if (Array.isArray(v)) return "[" + v.map(js).join(",") + "]";
  if (v === null || typeof v !== "object") return JSON.stringify(v);
  const keys = Object.keys(v);
  if (keys.length === 1 && keys[0] === NONFINITE && NONFINITE_TEXTS.indexOf(v[NONFINITE]) >= 0) return v[NONFINITE];
  return "{" + keys.map((k) => JSON.stringify(k) + ":" + js(v[k])).join(",") + "}";
}
const sec = (v) => (Number(v) || 0).toFixed(2) + "s";
const pad2 = (n) => String(n).padStart(2, "0");
function wall(epoch, withDate) {
  const d = new Date(epoch * 1000);
  const time = pad2(d.getHours()) + ":" + pad2(d.getMinutes()) + ":" + pad2(d.getSeconds());
  return withDate ? d.getFullYear() + "-" + pad2(d.getMonth() + 1) + "-" + pad2(d.getDate()) + " " + time : time;
}

// a control command as the terminal says it (runevents.control_line): "force 'grasp' FAILURE", then who
// sent it and the answer, "refused: …" when the run refused it
function controlWords(c) {
  const args = c.args && typeof c.args === "object" ? c.args : {};
  return [String(c.command || "?")].concat(Object.keys(args).map((k) => k === "node" || k === "key"
    ? "'" + String(args[k]) + "'" : typeof args[k] === "string" ? args[k] : js(args[k]))).join(" ");
}
const controlAnswer = (c) => "by " + (c.by || "?") + ": " + (c.ok === false ? "refused: " : "") + (c.answer || "");

function noticeClass(e) {
  const what = String(e.what || "");
  const down = /_down$/.test(what) || what === "cleanup_failed" || what === "run_silent";
  return "notice" + (down ? " down" : /_back$/.test(what) || what === "run_answers" ? " back" : "");
}

// a notice is about the ROS graph (the master went away...), or about the tree's cleanup
// (or, the watch's own, about the run's node not answering it)
const noticeOf = (e) => (e.what === "cleanup" || e.what === "cleanup_failed" ? "cleanup"
  : e.what === "run_silent" || e.what === "run_answers" ? "watch" : "ROS graph");

function graphAlert(s) {
  // what of the ROS graph is down now (a *_down notice not followed by its *_back), for the header
  const down = {};
  for (const e of s.events) {
    const m = e.type === "notice" && /^(.*)_(down|back)$/.exec(String(e.what || ""));
    if (m) down[m[1]] = m[2] === "down" ? e.t : undefined;
  }
  const names = { blackboard: "Blackboard node", master: "ROS master" };
  return Object.keys(down).filter((k) => down[k] !== undefined)
    .map((k) => (names[k] || k) + " down since " + sec(down[k])).join("; ");
}

function drawTitle(s) {
  const t = s.tree || {};
  const name = t.name || "(waiting for a run)";
  $("title").textContent = name;
  $("mode").hidden = mode !== "replay";
  $("mode").textContent = "REPLAY";
  const started = typeof t.started === "number" && t.started > 0 ? t.started : null;
  $("run").textContent = t.run ? "run " + t.run + (started ? ", started " + wall(started, true) : "") : "";
  const status = s.end ? " · " + statusWord(s.end.status) : (mode === "replay" ? "" : " · live");
  document.title = t.name ? name + " · " + (mode === "replay" ? "replay" : "watch") + " of run " + (t.run || "?")
    + (started ? " (" + wall(started, true) + ")" : "") + status + " — bmtree" : "bmtree";
}

function draw(s) {
  const names = s.nodes.map((n) => n.name).join("\n");
  if (names !== shownNodes) focused = null; // another tree (or run): the root again
  last = s;
  culprit = culpritOf(s);
  drawTitle(s);
  $("clock").textContent = "t=" + sec(s.t) + "  tick " + s.n;
  $("paused").hidden = !s.paused;
  const r = $("result");
  r.className = s.end ? s.end.status : "";
  r.textContent = s.end ? "result: " + statusWord(s.end.status) + (s.end.status === "UNFINISHED" ? "" : " in " + sec(s.end.duration))
    + (s.end.reason ? " (" + s.end.reason + ")" : "") + (s.cleanup ? "; " + s.cleanup : "")
    + (Array.isArray(s.end.steered) && s.end.steered.length ? "; steered: " + s.end.steered.join("; ") : "") : "";
  // the run's node has not answered the watch for a while (its link down, its process stopped); the
  // watch says it again every second, its seconds counting
  $("stale").hidden = !s.silent || mode === "replay";
  $("stale").textContent = s.silent || "";
  const down = graphAlert(s);
  $("alert").hidden = !down;
  $("alert").textContent = down;
  // the watch's "now" (the last record's time moved on by its clock): a page opened during a long call
  // counted from that record's time, as if the call had only just started
  if (typeof s.now === "number") {
    if (s !== anchored) anchor = [s.now, Date.now()]; // each answer of the watch: its own now
  } else if (s.t !== anchor[0]) anchor = [s.t, Date.now()];
  anchored = s;
  drawTree(s);
  drawPending(s);
  const why = s.nodes.filter((n) => failedLabel(label(s, n.id)) && s.feedback[String(n.id)])
    .sort((a, b) => (b.id === culprit) - (a.id === culprit));
  $("whybox").hidden = !why.length;
  rows("why", why, (n) => [[nameOf(s, n), s.feedback[String(n.id)]], label(s, n.id) === "FAILURE" ? "failed" : ""], ["name", "val"]);
  rows("blackboard", Object.keys(s.blackboard).sort(), (k) => [k, js(s.blackboard[k])], ["key", "val"]);
  const ev = s.events.map((e) => e.type === "notice" ? [e.t, [[sec(e.t), noticeOf(e), e.text], noticeClass(e)]]
    : [e.t, [sec(e.t), e.module + "." + e.event, js(e.params)]])
    .concat(s.control.map((c) => [c.t, [[sec(c.t), "control " + controlWords(c), controlAnswer(c)],
      c.ok === false ? "failed" : ""]]));
  ev.sort((a, b) => a[0] - b[0]);
  rows("events", ev.slice(-30), (e) => e[1], ["num", "key", "val"]);
  const total = Math.max(Number(s.calls_total) || 0, s.calls.length);
  $("callsh").textContent = "call log" + (total > 40 ? " (the last 40 of " + total + ")" : "");
  rows("calls", s.calls.slice(-40), (c) => [[sec(c.started), c.target, c.status, sec(c.duration), c.error || ""],
    c.status === "succeeded" ? "" : "failed"], ["num", "name", "st", "num", "val"]);
  if (names !== shownNodes) {
    shownNodes = names;
    const sel = $("node");
    sel.textContent = "";
    // a name several nodes share says which one: NAME@ID (the run refuses a shared name)
    const seen = {};
    for (const n of s.nodes) seen[n.name] = (seen[n.name] || 0) + 1;
    for (const n of s.nodes) {
      const o = document.createElement("option");
      o.value = seen[n.name] > 1 ? n.name + "@" + n.id : n.name;
      o.textContent = seen[n.name] > 1 ? o.value + (n.line ? " (line " + n.line + ")" : "") : n.name;
      sel.appendChild(o);
    }
  }
  if ((s.tree || {}).run !== answeredRun) said(""); // an answer is about the run it was sent to
  $("controls").hidden = !s.steer || gone;
  follow(s, false);
}

let anchor = [null, 0];
let anchored = null;
function drawPending(s) {
  // the run's time moves on between records, and while it is paused (its calls run on): count it on
  // here, as the terminal does (not in a replay or after the end)
  const now = nowOf(s);
  $("clock").textContent = "t=" + sec(now) + "  tick " + s.n;
  for (const t of document.querySelectorAll("#tree text.progress")) { // their seconds count on
    t.textContent = fillProgress(JSON.parse(t.dataset.progress), now);
  }
  if (answeredAt && Date.now() - answeredAt > SAID_MS) said("");
  $("pendingh").textContent = s.pending_title || "pending calls"; // during a cleanup: its calls
  // answered while the run was paused (its leaf takes it at the next tick), or of a run that is gone
  const note = (c) => (c.answered !== undefined && c.answered !== null ? " · answered " + (c.answer || "")
    : c.maybe_running ? " · may still be running" : "");
  const took = (c) => (c.answered !== undefined && c.answered !== null ? Number(c.answered) : now) - c.t;
  rows("pending", s.pending, (c) => [c.target, sec(took(c)) + " / " + (c.timeout ? c.timeout + "s" : "-") + note(c),
    js(c.inputs)], ["name", "num", "val"]);
}
setInterval(() => { if (last) drawPending(last); }, 500);

function setGone(g) {
  // the watch has ended (with its run) or is unreachable: the page keeps the last state it got
  gone = g;
  $("gone").hidden = !g;
  if (g) $("stale").hidden = true; // its seconds would stand still: the watch is what no longer answers
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
      mode = "live";
      draw(s);
    } catch (e) {
      if (last && !gone) setGone(true);
      await new Promise((ok) => setTimeout(ok, 1000));
    }
  }
}

function startReplay(s) {
  mode = "replay";
  replayMeta = s.replay || {};
  $("timeline").hidden = false;
  const scrub = $("scrub");
  const max = Math.ceil(Number(s.duration) * 100 - 1e-6) / 100; // the slider's steps reach the end
  scrub.max = max;
  scrub.value = max;
  const killed = $("killed");
  if (replayMeta.unfinished) {
    killed.hidden = false;
    killed.textContent = "UNFINISHED: its log has no end (killed?); last seen alive at " + sec(replayMeta.last_alive)
      + (s.tree && s.tree.started ? " (" + wall(s.tree.started + replayMeta.last_alive) + ")" : "");
  }
  const showAt = (st) => { $("at").textContent = sec(st.at) + " of " + sec(st.duration); };
  showAt(s);
  draw(s);
  let asked = 0;
  async function go(at, force) {
    const mine = ++asked; // answers can overtake each other: only the last one asked is drawn
    const res = await fetch("state?at=" + at);
    const st = await res.json();
    if (mine !== asked) return;
    showAt(st);
    draw(st);
    if (force) follow(st, true);
  }
  scrub.addEventListener("input", () => go(Number(scrub.value) >= max ? "end" : scrub.value, false));
  const f = replayMeta.failure;
  if (f) {
    const jump = $("jump");
    jump.hidden = false;
    jump.title = "'" + f.name + "' failed at " + sec(f.t) + ": " + f.message;
    jump.onclick = () => { scrub.value = f.t; userScrolled = 0; go(f.t, true); };
  }
}

// the run's answer to a button, shown SAID_MS and only while the run it was sent to is shown
let answeredAt = 0, answeredRun = null;
function said(text, run) {
  $("answer").textContent = text;
  answeredAt = text ? Date.now() : 0;
  if (text) answeredRun = run;
}

async function control(cmd) {
  const run = last && last.tree ? last.tree.run : null;
  const res = await fetch("control", { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(cmd) });
  const a = await res.json();
  if (!last || !last.tree || last.tree.run === run) said((a.ok ? "ok: " : "refused: ") + a.answer, run);
}

$("pause").onclick = () => control({ command: "pause" });
$("resume").onclick = () => control({ command: "resume" });
$("step").onclick = () => control({ command: "step" });
$("stop").onclick = () => { if (confirm("Stop the run? Root is halted, then its cleanup runs.")) control({ command: "stop" }); };
$("break").onclick = () => control({ command: "break", node: $("node").value });
$("clear").onclick = () => control({ command: "clear", node: $("node").value });
$("force-success").onclick = () => control({ command: "force", node: $("node").value, outcome: "SUCCESS" });
$("force-failure").onclick = () => control({ command: "force", node: $("node").value, outcome: "FAILURE" });
$("set").onclick = () => control({ command: "set", key: $("key").value, value: $("value").value });
poll();
