// The cas_async view: a live run or a replay, drawn from the protocol in docs/live.md.
// No library, no network beyond this page's own server.
"use strict";

(() => {
  const HEADER = 40;
  const UNKNOWN = 0xffffffff;
  const OTHER = "#7f7f7f";
  const FLASH_MS = 1200;
  const LOG_LIMIT = 200;

  const $ = (id) => document.getElementById(id);
  const canvas = $("world");
  const ctx = canvas.getContext("2d");

  const state = {
    hello: null,
    mode: null,
    connected: false,
    frame: null,       // the latest frame received
    drawn: null,       // what the last draw showed (for automation)
    frames: 0,
    skipped: 0,
    lastSeq: -1,
    ended: null,
    events: [],        // live: every event seen; replay: the hello's
    flashes: [],
    colors: {},
    groupOf: new Map(),
    view: null,        // {scale, x0, y0}: canvas px = x0 + x * scale, y0 - y * scale
    playing: false,
    speed: 1,
    replayT: 0,
    pending: false,
    requested: -1,
  };

  // -- the protocol ----------------------------------------------------------------

  function decodeFrame(buffer) {
    const view = new DataView(buffer);
    const magic = String.fromCharCode(...new Uint8Array(buffer, 0, 4));
    if (magic !== "CASF" || view.getUint16(4, true) !== 1) throw new Error("not a frame");
    const n = view.getUint32(20, true);
    const m = view.getUint32(32, true);
    const measures = [];
    for (let k = 0; k < m; k++) measures.push(view.getFloat64(HEADER + 8 * k, true));
    const at = HEADER + 8 * m;
    const xy = new Float64Array(2 * n);
    for (let k = 0; k < 2 * n; k++) xy[k] = view.getFloat64(at + 8 * k, true);
    const flags = new Uint8Array(buffer.slice(at + 16 * n, at + 17 * n));
    return {
      final: (view.getUint16(6, true) & 1) === 1,
      t: view.getFloat64(8, true),
      seq: view.getUint32(16, true),
      done: view.getUint32(24, true),
      detail: view.getUint32(28, true),
      measures, xy, flags, n,
    };
  }

  function connect() {
    const scheme = location.protocol === "https:" ? "wss://" : "ws://";
    const socket = new WebSocket(scheme + location.host + "/ws");
    socket.binaryType = "arraybuffer";
    state.socket = socket;
    socket.onopen = () => { state.connected = true; status("connected", true); };
    socket.onclose = () => {
      state.connected = false;
      status(state.ended ? "run ended" : "disconnected", false);
    };
    socket.onmessage = (message) => {
      if (typeof message.data === "string") onText(JSON.parse(message.data));
      else onFrame(decodeFrame(message.data));
    };
  }

  function onText(message) {
    if (message.type === "hello") onHello(message);
    else if (message.type === "events") {
      for (const event of message.events) addEvent(event, true);
      if (message.dropped) addLog(null, `${message.dropped} events skipped`);
    } else if (message.type === "end") onEnd(message);
    else if (message.type === "error") addLog(null, `server: ${message.message}`);
  }

  function onFrame(frame) {
    if (state.lastSeq >= 0 && frame.seq > state.lastSeq + 1 && state.mode === "live") {
      state.skipped += frame.seq - state.lastSeq - 1;
    }
    state.lastSeq = frame.seq;
    state.frame = frame;
    state.frames += 1;
    if (state.mode === "replay") {
      state.pending = false;
      if (!state.playing && frame.t !== state.replayT) { setTime(frame.t, false); replayLog(frame.t); }
    }
    redraw();
  }

  function onHello(hello) {
    state.hello = hello;
    state.mode = hello.mode;
    state.colors = hello.colors || {};
    state.groupOf = new Map();
    for (const group of hello.groups) for (const id of group.robots) state.groupOf.set(id, group.name);
    $("mode").textContent = hello.mode === "live" ? "LIVE" : "REPLAY";
    $("mode").className = "badge " + hello.mode;
    $("title").textContent = `${hello.app} · ${hello.scenario.split("/").pop()} · seed ${hello.seed}`;
    document.title = `${hello.app}: ${hello.mode}`;
    buildLegend(hello);
    if (hello.mode === "replay") {
      state.events = hello.events.slice();
      const scrubber = $("scrubber");
      scrubber.max = String(hello.times.length ? hello.times[hello.times.length - 1] : 0);
      $("controls").classList.remove("hidden");
      state.ended = hello.end;
    } else {
      $("controls").classList.add("hidden");
    }
    fit();
    resize();
  }

  function onEnd(end) {
    state.ended = end;
    const when = end.makespan != null ? `at t = ${fmt(end.makespan)} s` : `t = ${fmt(end.t)} s`;
    banner(`run ${end.status.replace("_", " ")} ${when}`);
    redraw();
  }

  // -- events ----------------------------------------------------------------------

  function addEvent(event, live) {
    if (live) state.events.push(event);
    const text = describe(event);
    if (text) addLog(event.t, text);
    if (live) state.flashes.push({ event, until: performance.now() + FLASH_MS });
  }

  function describe(event) {
    const h = state.hello;
    const noun = h ? h.noun : "item";
    if (event.type === "exchange") {
      const who = event.from != null ? `: robot ${event.from} → robot ${event.to}` : "";
      return `${noun}${event.item != null ? " " + event.item : ""} handed over${who}` +
        (event.count != null ? ` (#${event.count})` : "");
    }
    if (event.type === "delivered") {
      const by = event.by != null ? ` by robot ${event.by}` : "";
      return `${noun}${event.item != null ? " " + event.item : ""} ${h ? h.verb : "done"}${by}` +
        (event.count != null ? ` (${event.count}${h ? " of " + h.target : ""})` : "");
    }
    if (event.type === "progress" && h && h.kind !== "items") {  // no item events: the counts
      const before = state.tally || { done: 0, detail: 0 };
      state.tally = { done: event.done, detail: event.detail };
      if (event.done > before.done) return `${noun} ${h.verb} (${event.done} of ${h.target})`;
      if (event.detail > before.detail) return `${h.detail}: ${event.detail}`;
    }
    return "";
  }

  function addLog(t, text) {
    const list = $("events");
    const item = document.createElement("li");
    if (t != null) {
      const stamp = document.createElement("span");
      stamp.className = "t";
      stamp.textContent = `${fmt(t)} s`;
      item.appendChild(stamp);
    }
    item.appendChild(document.createTextNode(text));
    list.insertBefore(item, list.firstChild);
    while (list.childElementCount > LOG_LIMIT) list.removeChild(list.lastChild);
  }

  function replayLog(t) {
    const list = $("events");
    list.replaceChildren();
    state.tally = null;
    const shown = state.events.filter((e) => e.t <= t).slice(-50);
    for (const event of shown) { const text = describe(event); if (text) addLog(event.t, text); }
  }

  // -- drawing ---------------------------------------------------------------------

  function colorOf(name) { return state.colors[name] || OTHER; }

  function resize() {
    const dpr = window.devicePixelRatio || 1;
    const rect = canvas.getBoundingClientRect();
    canvas.width = Math.max(1, Math.round(rect.width * dpr));
    canvas.height = Math.max(1, Math.round(rect.height * dpr));
    if (!state.view) fit();
    redraw();
  }

  function fit() {
    const h = state.hello;
    if (!h) return;
    const dpr = window.devicePixelRatio || 1;
    const rect = canvas.getBoundingClientRect();
    const width = Math.max(1, rect.width * dpr), height = Math.max(1, rect.height * dpr);
    const w = h.world.width || 1, hh = h.world.height || 1;
    const margin = 24 * dpr;
    const scale = Math.min((width - 2 * margin) / w, (height - 2 * margin) / hh);
    state.view = {
      scale,
      x0: (width - w * scale) / 2,
      y0: (height + hh * scale) / 2,
    };
    redraw();
  }

  const X = (x) => state.view.x0 + x * state.view.scale;
  const Y = (y) => state.view.y0 - y * state.view.scale;

  let scheduled = false;
  function redraw() {
    if (scheduled) return;
    scheduled = true;
    requestAnimationFrame(() => { scheduled = false; draw(); });
  }

  function draw() {
    const h = state.hello;
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.clearRect(0, 0, canvas.width, canvas.height);
    if (!h || !state.view) return;
    const dpr = window.devicePixelRatio || 1;
    const s = state.view.scale;
    ctx.fillStyle = "#ffffff";
    ctx.strokeStyle = "#9a9a9a";
    ctx.lineWidth = dpr;
    ctx.fillRect(X(0), Y(h.world.height), h.world.width * s, h.world.height * s);
    ctx.strokeRect(X(0), Y(h.world.height), h.world.width * s, h.world.height * s);
    drawScene(h.scene, s, dpr);
    const frame = state.frame;
    const robots = [];
    if (frame) {
      const radius = Math.min(8, Math.max(3, 0.15 * s / dpr)) * dpr;
      for (let k = 0; k < frame.n; k++) {
        const id = h.robots[k];
        const group = state.groupOf.get(id);
        const color = group ? colorOf(group) : OTHER;
        const px = X(frame.xy[2 * k]), py = Y(frame.xy[2 * k + 1]);
        const carrying = (frame.flags[k] & 1) === 1;
        if (carrying) {
          ctx.beginPath();
          ctx.arc(px, py, radius + 2.5 * dpr, 0, 2 * Math.PI);
          ctx.strokeStyle = "#1d1d1f";
          ctx.lineWidth = 2 * dpr;
          ctx.stroke();
        }
        ctx.beginPath();
        ctx.arc(px, py, radius, 0, 2 * Math.PI);
        ctx.fillStyle = color;
        ctx.fill();
        robots.push({ id, x: frame.xy[2 * k], y: frame.xy[2 * k + 1], px, py, color, carrying, group });
      }
      drawFlashes(frame, radius);
    }
    state.drawn = frame ? { t: frame.t, seq: frame.seq, robots, radius: robots.length ? Math.min(8, Math.max(3, 0.15 * s / dpr)) * dpr : 0 } : null;
    hud(frame);
  }

  function drawScene(scene, s, dpr) {
    const labels = s / dpr > 25;
    for (const shape of scene.shapes) {
      const color = colorOf(shape.kind);
      ctx.save();
      ctx.strokeStyle = color;
      ctx.fillStyle = color;
      ctx.lineWidth = 1.5 * dpr;
      if (shape.shape === "disc") {
        ctx.beginPath();
        ctx.arc(X(shape.x), Y(shape.y), shape.radius * s, 0, 2 * Math.PI);
        ctx.globalAlpha = 0.18; ctx.fill();
        ctx.globalAlpha = 0.9; ctx.stroke();
      } else if (shape.shape === "rect") {
        ctx.translate(X(shape.x), Y(shape.y));
        ctx.rotate(-shape.angle);
        ctx.globalAlpha = 0.35;
        ctx.fillRect(-shape.width * s / 2, -shape.height * s / 2, shape.width * s, shape.height * s);
        ctx.globalAlpha = 0.9;
        ctx.strokeRect(-shape.width * s / 2, -shape.height * s / 2, shape.width * s, shape.height * s);
      } else if (shape.shape === "polyline") {
        ctx.beginPath();
        shape.points.forEach(([x, y], k) => (k ? ctx.lineTo(X(x), Y(y)) : ctx.moveTo(X(x), Y(y))));
        ctx.setLineDash([6 * dpr, 4 * dpr]);
        ctx.globalAlpha = 0.6;
        ctx.stroke();
      } else if (shape.shape === "spot") {
        const r = 3 * dpr;
        ctx.beginPath();
        ctx.moveTo(X(shape.x) - r, Y(shape.y) - r); ctx.lineTo(X(shape.x) + r, Y(shape.y) + r);
        ctx.moveTo(X(shape.x) - r, Y(shape.y) + r); ctx.lineTo(X(shape.x) + r, Y(shape.y) - r);
        ctx.stroke();
      }
      ctx.restore();
      if (labels && shape.label) {
        const [x, y] = shape.shape === "polyline" ? shape.points[0] : [shape.x, shape.y];
        ctx.fillStyle = "#333";
        ctx.font = `${11 * dpr}px system-ui, sans-serif`;
        ctx.fillText(shape.label, X(x) + 6 * dpr, Y(y) - 6 * dpr);
      }
    }
  }

  function drawFlashes(frame, radius) {
    const now = performance.now();
    state.flashes = state.flashes.filter((flash) => flash.until > now);
    if (!state.flashes.length) return;
    const row = new Map(state.hello.robots.map((id, k) => [id, k]));
    const at = (id) => (row.has(id) ? [X(frame.xy[2 * row.get(id)]), Y(frame.xy[2 * row.get(id) + 1])] : null);
    for (const { event, until } of state.flashes) {
      const alpha = Math.max(0, (until - now) / FLASH_MS);
      ctx.save();
      ctx.globalAlpha = alpha;
      ctx.strokeStyle = "#1d1d1f";
      ctx.lineWidth = 2;
      if (event.type === "exchange" && event.from != null) {
        const a = at(event.from), b = at(event.to);
        if (a && b) {
          ctx.beginPath(); ctx.moveTo(...a); ctx.lineTo(...b); ctx.stroke();
          ctx.beginPath(); ctx.arc(b[0], b[1], radius * 2.2, 0, 2 * Math.PI); ctx.stroke();
        }
      } else if (event.type === "delivered" && event.by != null) {
        const a = at(event.by);
        if (a) {
          ctx.strokeStyle = "#1e7b34";
          ctx.beginPath(); ctx.arc(a[0], a[1], radius * (1.5 + 3 * (1 - alpha)), 0, 2 * Math.PI); ctx.stroke();
        }
      }
      ctx.restore();
    }
    redraw();  // the flashes fade
  }

  function hud(frame) {
    const h = state.hello;
    $("clock").textContent = frame ? `t = ${fmt(frame.t)} s` : "t = –";
    if (!frame) return;
    $("progress").textContent = `${frame.done} / ${h.target} ${h.noun}s ${h.verb}`;
    $("detail").textContent = frame.detail === UNKNOWN ? "" : `${frame.detail} ${h.detail}`;
    $("measures").textContent = h.measures
      .map((name, k) => `${name} = ${Number.isFinite(frame.measures[k]) ? frame.measures[k].toFixed(3) : "–"}`)
      .join("  ");
    const rate = state.mode === "live" ? ` · ${state.skipped} skipped` : "";
    $("frames").textContent = `frame ${frame.seq} · ${state.frames} received${rate}`;
  }

  function buildLegend(hello) {
    const legend = $("legend");
    legend.replaceChildren();
    const add = (name, kind, count) => {
      const item = document.createElement("li");
      const swatch = document.createElement("span");
      swatch.className = "swatch " + kind;
      if (kind !== "ring") swatch.style.background = colorOf(name);
      item.appendChild(swatch);
      item.appendChild(document.createTextNode(count != null ? `${name} (${count})` : name));
      legend.appendChild(item);
    };
    for (const group of hello.groups) add(group.name, "", group.robots.length);
    const kinds = [...new Set(hello.scene.shapes.map((shape) => shape.kind).filter(Boolean))];
    for (const kind of kinds) if (!hello.groups.some((g) => g.name === kind)) add(kind, "square");
    add(`carrier (holds a ${hello.noun})`, "ring");
  }

  // -- replay ----------------------------------------------------------------------

  function setTime(t, request) {
    state.replayT = t;
    $("scrubber").value = String(t);
    const end = state.hello && state.hello.times.length ? state.hello.times[state.hello.times.length - 1] : 0;
    $("time").textContent = `${fmt(t)} / ${fmt(end)} s`;
    if (request) ask(t);
  }

  function ask(t) {
    if (!state.connected || state.pending) return;
    state.pending = true;
    state.requested = t;
    state.socket.send(JSON.stringify({ type: "seek", t }));
  }

  let lastTick = null;
  function tick(now) {
    if (state.playing && state.hello) {
      const times = state.hello.times;
      const end = times.length ? times[times.length - 1] : 0;
      if (lastTick != null) {
        const before = state.replayT;
        const t = Math.min(end, before + ((now - lastTick) / 1000) * state.speed);
        for (const event of state.events) if (event.t > before && event.t <= t) addEvent(event, false);
        setTime(t, true);
        if (t >= end) play(false);
      }
      lastTick = now;
    } else {
      lastTick = null;
    }
    if (!state.pending && state.mode === "replay" && state.frame && state.connected) {
      const want = indexAt(state.replayT);
      if (want !== state.frame.seq) ask(state.replayT);
    }
    requestAnimationFrame(tick);
  }

  function indexAt(t) {
    const times = state.hello.times;
    let lo = 0, hi = times.length;
    while (lo < hi) { const mid = (lo + hi) >> 1; if (times[mid] <= t) lo = mid + 1; else hi = mid; }
    return Math.max(0, lo - 1);
  }

  function play(on) {
    state.playing = on;
    $("play").textContent = on ? "pause" : "play";
    if (on && state.hello && state.replayT >= state.hello.times[state.hello.times.length - 1]) setTime(0, true);
  }

  // -- the page's controls ---------------------------------------------------------

  function status(text, ok) {
    const element = $("status");
    element.textContent = text;
    element.className = "status" + (ok ? " ok" : "");
  }

  function banner(text) {
    const element = $("banner");
    element.textContent = text;
    element.classList.remove("hidden");
  }

  function fmt(t) { return t == null ? "–" : Number(t).toFixed(t < 100 ? 2 : 1); }

  $("play").addEventListener("click", () => play(!state.playing));
  $("speed").addEventListener("change", (e) => { state.speed = Number(e.target.value); });
  $("scrubber").addEventListener("input", (e) => {
    setTime(Number(e.target.value), false);
    replayLog(state.replayT);
    state.pending = false;
    ask(state.replayT);
  });
  $("fit").addEventListener("click", fit);
  window.addEventListener("resize", resize);

  let drag = null;
  canvas.addEventListener("pointerdown", (e) => {
    drag = { x: e.clientX, y: e.clientY };
    canvas.classList.add("dragging");
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag || !state.view) return;
    const dpr = window.devicePixelRatio || 1;
    state.view.x0 += (e.clientX - drag.x) * dpr;
    state.view.y0 += (e.clientY - drag.y) * dpr;
    drag = { x: e.clientX, y: e.clientY };
    redraw();
  });
  canvas.addEventListener("pointerup", () => { drag = null; canvas.classList.remove("dragging"); });
  canvas.addEventListener("wheel", (e) => {
    if (!state.view) return;
    e.preventDefault();
    const dpr = window.devicePixelRatio || 1;
    const rect = canvas.getBoundingClientRect();
    const cx = (e.clientX - rect.left) * dpr, cy = (e.clientY - rect.top) * dpr;
    const factor = Math.exp(-e.deltaY * 0.0015);
    state.view.x0 = cx - (cx - state.view.x0) * factor;
    state.view.y0 = cy - (cy - state.view.y0) * factor;
    state.view.scale *= factor;
    redraw();
  }, { passive: false });

  // For automation (the tests, a person in the console): what was drawn, and the controls.
  window.casView = {
    state() {
      const rect = canvas.getBoundingClientRect();
      return {
        mode: state.mode,
        connected: state.connected,
        ended: state.ended,
        frames: state.frames,
        skipped: state.skipped,
        events: state.events.length,
        replayT: state.replayT,
        playing: state.playing,
        pending: state.pending,
        dpr: window.devicePixelRatio || 1,
        canvas: { left: rect.left, top: rect.top, width: canvas.width, height: canvas.height },
        frame: state.frame && { t: state.frame.t, seq: state.frame.seq, done: state.frame.done,
          detail: state.frame.detail, measures: state.frame.measures, final: state.frame.final },
        drawn: state.drawn,
      };
    },
    seek(t) { setTime(t, false); replayLog(t); state.pending = false; ask(t); },
    play() { play(true); },
    pause() { play(false); },
    speed(x) { state.speed = x; },
  };

  connect();
  resize();
  requestAnimationFrame(tick);
})();
