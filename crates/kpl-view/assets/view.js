// The KPL view page: draws what /api/frame says is there at a time, over /api/scene, and lists
// /api/situations. No build step: plain script, served by `kpl` from its binary.
'use strict';

const $ = (id) => document.getElementById(id);
const canvas = $('map');
const ctx = canvas.getContext('2d');

const view = {
  state: null,
  scene: null,
  frame: null,
  situations: [],
  t: null, // the time shown; null: the latest
  follow: true, // a live run: show the latest
  playing: false,
  hidden: new Set(),
  selected: null, // index of the selected situation
  cx: 0, cy: 0, scale: 1, // map centre (metres) and pixels per metre
  fitted: false,
};

// What the page drew last, for tests and curious users: window.kplView.drawn.
window.kplView = { drawn: null, situations: 0, setView: (cx, cy, scale) => { Object.assign(view, { cx, cy, scale, fitted: true }); draw(); } };

async function get(path) {
  const response = await fetch(path, { cache: 'no-store' });
  if (!response.ok) throw new Error(`${path}: ${response.status}`);
  return response.json();
}

// Times are shown from the start of what the view holds (a wall-clock run's times are UNIX times).
function seconds(t) {
  const start = view.state && view.state.start !== null ? view.state.start : 0;
  return ((t - start) / 1e6).toFixed(1) + ' s';
}

function resize() {
  const ratio = window.devicePixelRatio || 1;
  canvas.width = canvas.clientWidth * ratio;
  canvas.height = canvas.clientHeight * ratio;
  ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
}

function bounds() {
  if (view.scene && view.scene.bounds) return view.scene.bounds;
  const points = [];
  for (const level of (view.frame ? view.frame.levels : [])) for (const o of level.objects) points.push([o.x, o.y]);
  if (!points.length) return null;
  const xs = points.map((p) => p[0]), ys = points.map((p) => p[1]);
  return [[Math.min(...xs) - 20, Math.min(...ys) - 20], [Math.max(...xs) + 20, Math.max(...ys) + 20]];
}

function fit() {
  const b = bounds();
  if (!b) return false;
  const [[x0, y0], [x1, y1]] = b;
  const w = canvas.clientWidth, h = canvas.clientHeight;
  view.cx = (x0 + x1) / 2; view.cy = (y0 + y1) / 2;
  view.scale = Math.min(w / Math.max(x1 - x0, 1), h / Math.max(y1 - y0, 1)) * 0.95;
  view.fitted = true;
  return true;
}

function sx(x) { return (x - view.cx) * view.scale + canvas.clientWidth / 2; }
function sy(y) { return canvas.clientHeight / 2 - (y - view.cy) * view.scale; }

function polyline(points, close) {
  ctx.beginPath();
  points.forEach(([x, y], i) => (i ? ctx.lineTo(sx(x), sy(y)) : ctx.moveTo(sx(x), sy(y))));
  if (close) ctx.closePath();
}

function drawScene() {
  const scene = view.scene;
  if (!scene) return;
  ctx.lineCap = 'round'; ctx.lineJoin = 'round';
  for (const lane of scene.lanes) {
    ctx.strokeStyle = lane.connector ? '#34373e' : '#2d3037';
    ctx.lineWidth = Math.max(1, lane.width * view.scale);
    polyline(lane.shape); ctx.stroke();
  }
  ctx.strokeStyle = '#4a4f59'; ctx.lineWidth = 1;
  ctx.setLineDash([6, 6]);
  for (const lane of scene.lanes) if (!lane.connector) { polyline(lane.shape); ctx.stroke(); }
  ctx.setLineDash([]);
  for (const polygon of scene.occluders) {
    ctx.fillStyle = 'rgba(70, 60, 50, 0.55)'; ctx.strokeStyle = '#8c7a62'; ctx.lineWidth = 1.5;
    polyline(polygon, true); ctx.fill(); ctx.stroke();
  }
}

function drawObject(o, colour, level, highlight) {
  const l = Math.max(o.length * view.scale, 6), w = Math.max(o.width * view.scale, 3);
  ctx.save();
  ctx.translate(sx(o.x), sy(o.y));
  ctx.rotate(-o.heading);
  ctx.lineWidth = 1.5;
  if (o.branch_of) { ctx.setLineDash([3, 2]); ctx.strokeStyle = '#f03ddc'; } else { ctx.strokeStyle = colour; }
  if (o.measured) { ctx.fillStyle = colour; ctx.fillRect(-l / 2, -w / 2, l, w); ctx.strokeStyle = '#0008'; }
  ctx.strokeRect(-l / 2, -w / 2, l, w);
  ctx.restore();
  ctx.setLineDash([]);
  const speed = Math.hypot(o.vx, o.vy);
  if (speed > 0.1) {
    ctx.strokeStyle = colour; ctx.lineWidth = 1;
    ctx.beginPath(); ctx.moveTo(sx(o.x), sy(o.y)); ctx.lineTo(sx(o.x + o.vx), sy(o.y + o.vy)); ctx.stroke();
  }
  if (highlight) {
    ctx.strokeStyle = '#fff'; ctx.lineWidth = 2;
    ctx.beginPath(); ctx.arc(sx(o.x), sy(o.y), Math.max(0.7 * l, 14), 0, 2 * Math.PI); ctx.stroke();
  }
  ctx.fillStyle = colour;
  ctx.font = '11px system-ui, sans-serif';
  ctx.fillText(o.label, sx(o.x) + l / 2 + 3, sy(o.y) - 4 + 12 * level);
}

function draw() {
  resize();
  const w = canvas.clientWidth, h = canvas.clientHeight;
  ctx.clearRect(0, 0, w, h);
  if (!view.fitted) fit();
  drawScene();
  const frame = view.frame;
  const drawn = { t: frame ? frame.t : null, levels: {}, valid: {}, points: {} };
  const positions = [];
  if (frame) {
    if (frame.footprint) {
      ctx.strokeStyle = '#f5d01a'; ctx.lineWidth = 2; ctx.setLineDash([10, 6]);
      polyline(frame.footprint, true); ctx.stroke(); ctx.setLineDash([]);
    }
    for (const p of frame.points) {
      ctx.fillStyle = 'rgba(235, 235, 235, 0.85)';
      for (const [x, y] of p.points) { ctx.beginPath(); ctx.arc(sx(x), sy(y), 2, 0, 2 * Math.PI); ctx.fill(); }
      drawn.points[p.stream] = p.points.length;
    }
    const selected = view.selected !== null ? view.situations[view.selected] : null;
    const marked = new Set(selected ? selected.objects.map((o) => o[1]) : []);
    for (const level of frame.levels) {
      if (view.hidden.has(level.stream)) continue;
      for (const o of level.objects) {
        drawObject(o, level.colour, level.level, marked.has(o.id));
        if (marked.has(o.id)) positions.push([o.x, o.y]);
      }
      drawn.levels[level.stream] = level.objects.length;
      drawn.valid[level.stream] = level.valid;
    }
  }
  window.kplView.drawn = drawn;
  window.kplView.marked = positions;
}

function renderLevels() {
  const body = $('levels').querySelector('tbody');
  body.innerHTML = '';
  for (const level of (view.frame ? view.frame.levels : [])) {
    const c = level.counters;
    const row = document.createElement('tr');
    row.innerHTML = `<td><input type="checkbox" ${view.hidden.has(level.stream) ? '' : 'checked'}></td>`
      + `<td><span class="swatch" style="background:${level.colour}"></span> ${level.stream}</td>`
      + [c.objects, c.measured, c.predicted, c.branches, c.symbols, c.gaps].map((n) => `<td>${n}</td>`).join('');
    row.querySelector('input').addEventListener('change', (e) => {
      if (e.target.checked) view.hidden.delete(level.stream); else view.hidden.add(level.stream);
      draw();
    });
    body.appendChild(row);
  }
  const points = view.frame ? view.frame.points.map((p) => `${p.stream}: ${p.points.length} percepts`) : [];
  $('points').textContent = points.join(', ');
}

// Every situation recognised so far; those recognised after the time shown are dimmed.
function renderSituations() {
  const list = $('situations');
  const shown = view.situations;
  const t = view.frame ? view.frame.t : null;
  const known = shown.filter((s) => t === null || s.available <= t).length;
  $('situation-count').textContent = known === shown.length ? `(${shown.length})` : `(${known} of ${shown.length} by now)`;
  window.kplView.situations = shown.length;
  const key = `${shown.length}/${known}/${view.selected}`;
  if (list.dataset.key === key) return;
  list.dataset.key = key;
  list.innerHTML = '';
  shown.forEach((s, index) => {
    const item = document.createElement('li');
    item.dataset.start = s.start;
    item.dataset.monitor = s.monitor;
    item.className = (index === view.selected ? 'selected' : '') + (t !== null && s.available > t ? ' later' : '');
    const who = s.objects.map(([k, v]) => `${k}=${v}`).join(' ');
    item.innerHTML = `<b>${s.monitor}</b> ${who} <span class="when">${seconds(s.start)}–${seconds(s.end)}</span>`;
    item.addEventListener('click', () => jump(index));
    list.appendChild(item);
  });
}

async function jump(index) {
  view.selected = index;
  view.follow = false;
  view.playing = false;
  view.t = view.situations[index].start;
  await showAt(view.t);
}

async function showAt(t) {
  view.frame = await get(t === null ? '/api/frame' : `/api/frame?t=${t}`);
  renderControls();
  renderLevels();
  renderSituations();
  draw();
}

function renderControls() {
  const s = view.state;
  if (!s) return;
  $('title').textContent = s.title;
  const mode = $('mode');
  mode.textContent = s.live ? (s.running ? 'live' : 'run ended') : 'recording';
  mode.className = 'badge' + (s.live && s.running ? ' live' : '');
  const slider = $('slider');
  if (s.start !== null) { slider.min = s.start; slider.max = s.end; }
  const t = view.frame ? view.frame.t : null;
  if (t !== null) { slider.value = t; $('clock').textContent = 't = ' + seconds(t); }
  $('live').className = view.follow ? 'on' : '';
  $('live').disabled = !s.live;
  $('play').textContent = view.playing ? '❚❚' : '▶';
}

async function tick() {
  try {
    view.state = await get('/api/state');
    if (view.playing) {
      const next = (view.t === null ? view.state.start : view.t) + 100000;
      if (next >= view.state.end) view.playing = false;
      view.t = Math.min(next, view.state.end);
    }
    if (view.follow && view.state.live) view.t = null;
    else if (view.t === null) view.t = view.state.live ? view.state.end : view.state.start;
    await showAt(view.t);
  } catch (e) {
    $('mode').textContent = 'not connected';
  }
}

async function refreshSituations() {
  try { view.situations = await get('/api/situations'); renderSituations(); } catch (e) { /* next time */ }
}

async function start() {
  view.state = await get('/api/state');
  view.scene = await get('/api/scene');
  view.follow = view.state.live;
  await refreshSituations();
  await tick();
  if (!fit()) view.fitted = false;
  draw();
  setInterval(tick, 100);
  setInterval(refreshSituations, 1000);
}

$('slider').addEventListener('input', (e) => { view.follow = false; view.t = Number(e.target.value); showAt(view.t); });
$('live').addEventListener('click', () => { view.follow = true; view.selected = null; view.t = null; });
$('play').addEventListener('click', () => { view.follow = false; view.playing = !view.playing; });
$('fit').addEventListener('click', () => { fit(); draw(); });
window.addEventListener('resize', draw);

let drag = null;
canvas.addEventListener('mousedown', (e) => { drag = [e.clientX, e.clientY]; });
window.addEventListener('mouseup', () => { drag = null; });
window.addEventListener('mousemove', (e) => {
  if (!drag) return;
  view.cx -= (e.clientX - drag[0]) / view.scale; view.cy += (e.clientY - drag[1]) / view.scale;
  drag = [e.clientX, e.clientY]; draw();
});
canvas.addEventListener('wheel', (e) => {
  e.preventDefault();
  const rect = canvas.getBoundingClientRect();
  const mx = e.clientX - rect.left, my = e.clientY - rect.top;
  const wx = (mx - canvas.clientWidth / 2) / view.scale + view.cx, wy = view.cy - (my - canvas.clientHeight / 2) / view.scale;
  view.scale *= Math.exp(-e.deltaY * 0.0015);
  view.cx = wx - (mx - canvas.clientWidth / 2) / view.scale; view.cy = wy + (my - canvas.clientHeight / 2) / view.scale;
  draw();
}, { passive: false });

start();
