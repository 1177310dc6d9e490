// The softshell web app: a list of the server's geometries with upload (`/`), and the view of one
// geometry (`/?geometry=ID`): its limit surface from the server's render table, following every
// client through the events stream, acted on through holds (one per hand, named per tab).
import { ApiError, Client, LimitSurface, parseObj, rows3 } from './client.js';
import { View, vec } from './view.js';

// The access token of a server started with --auth-token-file: opened as /#token=TOKEN (a
// fragment never goes to the server nor into its logs), kept in this tab's sessionStorage and
// taken out of the address bar, sent as the Authorization header.
function accessToken() {
  const fragment = new URLSearchParams(location.hash.slice(1));
  const given = fragment.get('token');
  if (given !== null) {
    fragment.delete('token');
    const rest = fragment.toString();
    history.replaceState(null, '', location.pathname + location.search + (rest ? '#' + rest : ''));
    if (given) sessionStorage.setItem('softshell.token', given);
    else sessionStorage.removeItem('softshell.token');
  }
  return sessionStorage.getItem('softshell.token') || '';
}
const client = new Client('', { token: accessToken() });
const root = document.getElementById('root');
const params = new URLSearchParams(location.search);
// One name per page (a browser tab, or a frame): the prefix of its hold ids. A reload is a new
// participant; the old one's holds are deleted on pagehide or end with their lease.
const tab = `tab-${Math.random().toString(36).slice(2, 10)}`;

// The SDK's material presets (sdk/core/src/material.cpp): E (Pa), nu, yield strength (Pa).
const PRESETS = {
  aluminium: [6.9e10, 0.33, 2.76e8], steel: [2.0e11, 0.3, 2.35e8], copper: [1.17e11, 0.34, 7.0e7], titanium: [1.1e11, 0.34, 8.8e8],
  glass: [7.0e10, 0.22, 4.0e7], abs: [2.3e9, 0.35, 4.0e7], polycarbonate: [2.4e9, 0.37, 6.0e7], wood: [1.1e10, 0.3, 4.0e7],
  cardboard: [3.0e9, 0.3, 1.0e7], rubber: [5.0e6, 0.49, 1.5e7], silicone: [1.0e6, 0.49, 5.0e6],
};

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k.startsWith('on')) e.addEventListener(k.slice(2), v);
    else if (v !== false && v !== undefined) e.setAttribute(k, v === true ? '' : v);
  }
  for (const c of children) e.append(c);
  return e;
}

function message(err) {
  if (err instanceof ApiError && err.status === 401) {
    return `${err.message} (401 ${err.code}): open this page as ${location.origin}/#token=TOKEN with the server's token`;
  }
  return err instanceof ApiError ? `${err.message} (${err.status} ${err.code})` : String(err?.message ?? err);
}

// ---------------------------------------------------------------------------------------------
// The list of geometries, with upload

async function listPage() {
  document.title = 'softshell: geometries';
  const tbody = el('tbody');
  const error = el('p', { class: 'error', id: 'upload-error', role: 'alert' });
  const note = el('p', { class: 'note', id: 'upload-note' });
  const file = el('input', { type: 'file', accept: '.obj', id: 'obj-file' });
  const preset = el('select', { id: 'preset' }, el('option', { value: 'custom' }, 'custom E, ν, t'),
    ...Object.keys(PRESETS).map((k) => el('option', { value: k, selected: k === 'aluminium' }, k)));
  const E = el('input', { id: 'E', type: 'number', value: 6.9e10, step: 'any' });
  const nu = el('input', { id: 'nu', type: 'number', value: 0.33, step: 'any' });
  const t = el('input', { id: 't', type: 'number', value: 0.001, step: 'any' });
  preset.addEventListener('change', () => {
    const p = PRESETS[preset.value];
    if (p) [E.value, nu.value] = p;
  });
  const drop = el('div', { class: 'drop', id: 'drop' }, 'Drop an OBJ file here, or ', file);

  async function upload(f) {
    error.textContent = '';
    note.textContent = `uploading ${f.name} ...`;
    try {
      const text = await f.text();
      let mesh;
      try {
        mesh = parseObj(text);
      } catch (err) {
        throw new Error(`${f.name}: ${err.message}`);
      }
      const material = { youngs_modulus: Number(E.value), poisson_ratio: Number(nu.value), thickness: Number(t.value) };
      const up = await client.upload({ ...mesh, material });
      note.textContent = `${f.name}: ${up.created ? 'uploaded' : 'already there'} as ${up.geom_id}`;
      await refresh();
    } catch (err) {
      note.textContent = '';
      error.textContent = message(err);
    }
  }
  file.addEventListener('change', () => file.files[0] && upload(file.files[0]));
  drop.addEventListener('dragover', (e) => { e.preventDefault(); drop.classList.add('over'); });
  drop.addEventListener('dragleave', () => drop.classList.remove('over'));
  drop.addEventListener('drop', (e) => {
    e.preventDefault();
    drop.classList.remove('over');
    const f = e.dataTransfer.files[0];
    if (f) upload(f);
  });

  root.replaceChildren(el('main', { class: 'list' },
    el('h1', {}, 'softshell'),
    el('table', { id: 'geometries' }, el('thead', {}, el('tr', {}, ...['geometry', 'namespace', 'vertices', 'faces', 'status', 'results'].map((h) => el('th', {}, h)))), tbody),
    el('h2', {}, 'Upload a control mesh'),
    el('div', { class: 'form' }, el('label', {}, 'material ', preset), el('label', {}, 'E (Pa) ', E), el('label', {}, 'ν ', nu), el('label', {}, 't (m) ', t)),
    drop, note, error));

  async function refresh() {
    try {
      const list = await client.geometries();
      tbody.replaceChildren(...list.map((g) => el('tr', {},
        el('td', {}, el('a', { href: `/?geometry=${g.geom_id}` }, g.geom_id.slice(0, 12) + '…')),
        el('td', {}, g.namespace), el('td', {}, String(g.vertices)), el('td', {}, String(g.faces)),
        el('td', { class: g.status }, g.status === 'precomputing' ? `precomputing ${Math.round(100 * (g.progress ?? 0))}%` : g.status + (g.error ? `: ${g.error}` : '')),
        el('td', {}, String(g.results)))));
      if (!list.length) tbody.replaceChildren(el('tr', {}, el('td', { colspan: 6 }, 'no geometries yet')));
    } catch (err) {
      error.textContent = message(err);
    }
  }
  await refresh();
  setInterval(refresh, 1000);
}

// ---------------------------------------------------------------------------------------------
// The view of one geometry

async function viewPage(id) {
  document.title = `softshell: ${id.slice(0, 8)}`;
  const canvas = el('canvas', { id: 'view' });
  const status = el('div', { class: 'status', id: 'status' });
  const warn = el('div', { class: 'warn', id: 'warning', role: 'alert' });
  const legend = el('div', { class: 'legend', id: 'legend' });
  const level = el('select', { id: 'level', title: 'tessellation level' }, ...[1, 2, 3, 4].map((l) => el('option', { value: l, selected: l === Number(params.get('level') ?? 2) }, `level ${l}`)));
  const shading = params.get('color') ?? 'none';
  const color = el('select', { id: 'color' }, ...[['none', 'plain'], ['displacement', 'displacement'], ['von_mises', 'von Mises']]
    .map(([v, label]) => el('option', { value: v, selected: v === shading }, label)));
  const ghost = el('input', { type: 'checkbox', id: 'ghost', checked: params.get('ghost') === '1' });
  const floor = el('input', { type: 'checkbox', id: 'floor' });
  const push = el('input', { type: 'checkbox', id: 'push-mode', title: 'drag pushes (a surface force) instead of grabbing; Shift does the same' });
  const undo = el('button', { id: 'undo', disabled: true }, '↶');
  const redo = el('button', { id: 'redo', disabled: true }, '↷');
  root.replaceChildren(el('div', { class: 'app' },
    el('header', {}, el('a', { href: '/', class: 'home' }, 'softshell'), level, color,
      el('label', {}, ghost, 'rest'), el('label', {}, floor, 'floor'), el('label', {}, push, 'push'), undo, redo),
    el('div', { class: 'stage' }, canvas, legend, warn), status));

  const view = new View(canvas);
  view.onFrame = () => { state.drawnResId = state.shownResId; };
  view.showGhost = ghost.checked;
  const state = {
    id, geometry: null, material: null, yieldStrength: 0, surface: null, rest: null, restSurface: null,
    control: null, resId: 0, holders: 0, latency: null, connection: 'connecting', error: '',
    pins: [], dragging: null, stress: null, undo: [], redo: [], history: [], moveToScreen: [], latencies: [], shownResId: 0, drawnResId: 0,
  };
  // For tests and tools: the page's state and its picking, readable from outside.
  window.softshell = { state, view, client, tab, pickAt: (x, y) => pick(x, y), ready: false };

  function showStatus() {
    const lat = state.latency === null ? '–' : `${state.latency.toFixed(1)} ms`;
    status.textContent = `result ${state.resId} · latency ${lat} · ${state.holders} holding · ${state.connection}` + (state.error ? ` · ${state.error}` : '');
  }
  function fail(err) {
    state.error = message(err);
    showStatus();
  }

  try {
    state.geometry = await client.geometry(id);
  } catch (err) {
    root.replaceChildren(el('main', { class: 'list' }, el('h1', {}, 'softshell'), el('p', { class: 'error', role: 'alert' }, message(err)), el('a', { href: '/' }, 'all geometries')));
    return;
  }
  state.rest = state.geometry.vertices;
  state.control = state.rest;
  const m = state.geometry.material;
  state.material = m;
  for (const [name, [E, nu, y]] of Object.entries(PRESETS)) {
    if (Math.abs(E - m.youngs_modulus) <= 1e-6 * E && Math.abs(nu - m.poisson_ratio) < 1e-9) { state.yieldStrength = y; state.preset = name; }
  }
  // Size of the object and of a typical bending force (for push magnitudes).
  let lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < state.rest.length; i += 3) for (let a = 0; a < 3; ++a) { lo[a] = Math.min(lo[a], state.rest[i + a]); hi[a] = Math.max(hi[a], state.rest[i + a]); }
  state.size = vec.norm(vec.sub(hi, lo));
  view.camera.fit(lo, hi);

  async function loadLevel(l) {
    const table = await client.renderTable(id, l);
    state.surface = new LimitSurface(table);
    state.restSurface = new LimitSurface(table);
    const rest = state.restSurface.evaluate(state.rest);
    state.restPositions = Float64Array.from(rest.positions);
    // Per vertex: (face, subface, u, v) (from the quads' corner parameters), for the floor.
    const q = table.quads;
    state.vertexPoint = new Array(table.vertices);
    for (let k = 0; k < q.root_face.length; ++k) {
      const c = state.surface.quadCornerParams(k);
      for (let i = 0; i < 4; ++i) {
        const v = q.vertices[4 * k + i];
        if (!state.vertexPoint[v]) state.vertexPoint[v] = { face: q.root_face[k], subface: q.subface[k], u: c[i][0], v: c[i][1] };
      }
    }
    view.setTopology(table.triangles, table.vertices);
    view.setGhost(rest.positions, rest.normals);
    state.stress = null;
    showShape();
  }

  // Draws the current control positions: x = S P, normals from the du/dv stencils.
  function showShape() {
    if (!state.surface) return;
    const { positions, normals } = state.surface.evaluate(state.control);
    view.setShape(positions, normals);
    state.shownResId = state.resId;
    const n = state.surface.vertexCount;
    let maxDisp = 0;
    const disp = new Float32Array(n);
    for (let i = 0; i < n; ++i) {
      disp[i] = Math.hypot(positions[3 * i] - state.restPositions[3 * i], positions[3 * i + 1] - state.restPositions[3 * i + 1], positions[3 * i + 2] - state.restPositions[3 * i + 2]);
      maxDisp = Math.max(maxDisp, disp[i]);
    }
    state.maxDisplacement = maxDisp;
    const warnings = [];
    if (maxDisp > 0.05 * state.size) warnings.push(`displacements reach ${(100 * maxDisp / state.size).toFixed(0)}% of the object's size: the linear model is out of range (rotations stretch it)`);
    if (color.value === 'displacement') {
      view.colored = true;
      view.setValues(disp, maxDisp || 1);
      legend.replaceChildren(el('span', {}, 'displacement'), el('div', { class: 'ramp' }), el('span', {}, `0 – ${maxDisp.toPrecision(3)} m`));
    } else if (color.value === 'von_mises') {
      view.colored = true;
      if (state.stress && state.stress.res_id === state.resId && state.stress.level === Number(level.value)) {
        const vm = Float32Array.from(state.stress.von_mises);
        const max = state.stress.max.von_mises ?? Math.max(...vm);
        view.setValues(vm, max || 1);
        legend.replaceChildren(el('span', {}, 'von Mises'), el('div', { class: 'ramp' }), el('span', {}, `0 – ${(max / 1e6).toPrecision(3)} MPa`));
        if (state.stress.exceeds_yield) warnings.push(`the material yields (von Mises ${(max / 1e6).toPrecision(3)} MPa > yield strength ${(state.yieldStrength / 1e6).toPrecision(3)} MPa): the linear elastic model does not hold`);
      } else {
        requestStresses();
      }
    } else {
      view.colored = false;
      legend.replaceChildren();
    }
    if (color.value === 'von_mises' && !state.yieldStrength) warnings.push('yield strength unknown (the material is no preset): yielding is not flagged');
    warn.textContent = warnings.join(' · ');
    view.pins = state.pins.map((p) => positionAt(p));
    showStatus();
  }

  let stressTimer = null;
  function requestStresses() {
    clearTimeout(stressTimer);
    stressTimer = setTimeout(async () => {
      if (!state.resId) return;
      const resId = state.resId, l = Number(level.value);
      try {
        const s = await client.stresses(id, resId, { level: l, yield_strength: state.yieldStrength || undefined });
        s.level = l;
        s.max.von_mises = Math.max(s.max.von_mises_top ?? 0, s.max.von_mises_bottom ?? 0, s.max.von_mises ?? 0);
        state.stress = s;
        if (state.resId === resId) showShape();
      } catch (err) {
        fail(err);
      }
    }, 120);
  }

  // A new result (from the events stream, or the answer to one of our own requests).
  function onResult(r) {
    // The answer to our own PUT and the event stream bring the same result: draw it once.
    if (r.res_id <= state.resId && state.resId > 0) return;
    state.resId = r.res_id;
    state.control = r.positions;
    if (r.holds) {
      const clients = new Set(Object.keys(r.holds).map((h) => h.replace(/-[^-]*$/, '')));
      state.holders = clients.size;
    } else {
      state.holders = 0;
    }
    if (!state.history.includes(r.res_id)) state.history.push(r.res_id);
    showShape();
  }

  // --- picking (paper Section 5.1): rendered triangle -> root face + quadtree path -> (face, u, v)
  function pick(x, y) {
    if (!state.surface) return null;
    const ray = view.camera.ray(x, y, canvas.clientWidth, canvas.clientHeight);
    const hit = state.surface.intersect(ray.origin, ray.direction);
    if (!hit) return { ray, hit: null };
    return { ray, hit, point: state.surface.surfacePoint(hit.triangle, hit.barycentric), position: vec.add(ray.origin, vec.scale(ray.direction, hit.t)) };
  }

  // Exact limit position (and tangents) at a surface point for control positions P, from the
  // server's limit stencil of that point.
  const combs = new Map();
  async function stencil(p) {
    const key = `${p.face}/${p.subface}/${p.u}/${p.v}`;
    if (!combs.has(key)) combs.set(key, await client.limitComb(id, p));
    return combs.get(key);
  }
  function apply(comb, weights, P) {
    const out = [0, 0, 0];
    comb.indices.forEach((j, k) => { for (let a = 0; a < 3; ++a) out[a] += comb[weights][k] * P[3 * j + a]; });
    return out;
  }
  function positionAt(pin) { return apply(pin.comb, 'position', state.control); }
  // A limit constraint holding point `comb` at `target` with its tangent plane as shown now
  // (position and tangents relative to the rest shape).
  function clamp(comb, p, target) {
    return {
      face: p.face, subface: p.subface, u: p.u, v: p.v,
      displacement: vec.sub(target, apply(comb, 'position', state.rest)),
      du_displacement: vec.sub(apply(comb, 'du', state.control), apply(comb, 'du', state.rest)),
      dv_displacement: vec.sub(apply(comb, 'dv', state.control), apply(comb, 'dv', state.rest)),
    };
  }

  // --- holds ------------------------------------------------------------------------------------
  // One PUT in flight per hold; a newer body waits and replaces any older waiting one.
  const senders = new Map();
  // `at`: when the pointer event behind this body happened (for the pointer-to-screen times).
  function sendHold(name, body, at = performance.now()) {
    const holdId = `${tab}-${name}`;
    let s = senders.get(holdId);
    if (!s) senders.set(holdId, (s = { busy: false, next: undefined, renew: null }));
    s.next = body;
    s.at = at;
    clearInterval(s.renew);
    if (body !== null) s.renew = setInterval(() => { if (!s.busy) { s.next = s.last; pump(holdId, s); } }, 3000);
    pump(holdId, s);
  }
  async function pump(holdId, s) {
    if (s.busy || s.next === undefined) return;
    const body = s.next;
    const at = s.at;
    s.next = undefined;
    s.busy = true;
    const start = performance.now();
    try {
      const r = body === null ? await client.deleteHold(id, holdId) : await client.putHold(id, holdId, body, { ttl: 10, wait: 10 });
      s.last = body;
      state.latency = performance.now() - start;
      state.latencies.push(state.latency);
      if (state.latencies.length > 500) state.latencies.shift();
      state.error = '';
      if (!r.pending) {
        onResult(r);
        // Pointer event to the first frame on screen that shows its answer (or a newer result).
        const record = () => {
          state.moveToScreen.push(performance.now() - at);
          if (state.moveToScreen.length > 500) state.moveToScreen.shift();
        };
        if (state.drawnResId >= r.res_id) requestAnimationFrame(record);
        else view.afterFrame(record, false);
      } else {
        showStatus();
      }
    } catch (err) {
      if (!(body === null && err.status === 404)) fail(err);
    } finally {
      s.busy = false;
      pump(holdId, s);
    }
  }
  function sendPins() {
    view.pins = state.pins.map((p) => positionAt(p));
    view.dirty = true;
    if (!state.pins.length) return sendHold('pins', null);
    sendHold('pins', { limit_constraints: state.pins.map((p) => clamp(p.comb, p.point, positionAt(p))) });
  }
  // The floor: every face with limit points within a tolerance of the plane under the object
  // keeps one of them (the one nearest the centroid of its touching points) where it is shown, as
  // the SDK's floor_contact does.
  function sendFloor() {
    if (!floor.checked) { view.floorY = null; view.dirty = true; return sendHold('floor', null); }
    const X = state.surface.positions;
    let minY = Infinity;
    for (let i = 1; i < X.length; i += 3) minY = Math.min(minY, X[i]);
    view.floorY = minY;
    const tol = 5e-3 * state.size;  // 0.5% of the size: a cow stands on four hooves, not one
    const byFace = new Map();
    for (let i = 0; i < state.surface.vertexCount; ++i) {
      if (X[3 * i + 1] - minY > tol) continue;
      const f = state.vertexPoint[i].face;
      if (!byFace.has(f)) byFace.set(f, []);
      byFace.get(f).push(i);
    }
    const constraints = [];
    for (const verts of byFace.values()) {
      const c = [0, 0, 0];
      for (const i of verts) for (let a = 0; a < 3; ++a) c[a] += X[3 * i + a] / verts.length;
      let best = verts[0], bd = Infinity;
      for (const i of verts) {
        const d = Math.hypot(X[3 * i] - c[0], X[3 * i + 1] - c[1], X[3 * i + 2] - c[2]);
        if (d < bd) { bd = d; best = i; }
      }
      const p = state.vertexPoint[best];
      const r = state.restPositions;
      constraints.push({ face: p.face, subface: p.subface, u: p.u, v: p.v,
        displacement: [X[3 * best] - r[3 * best], X[3 * best + 1] - r[3 * best + 1], X[3 * best + 2] - r[3 * best + 2]] });
    }
    sendHold('floor', { limit_constraints: constraints });
  }

  // --- pointer interaction --------------------------------------------------------------------------
  // One pointer on the background orbits (two pan/zoom, the wheel zooms, right or middle button
  // pans); on the object a drag grabs (or pushes with Shift / the push switch); a click pins or
  // unpins.
  const pointers = new Map();
  let gesture = null;
  canvas.addEventListener('contextmenu', (e) => e.preventDefault());
  canvas.addEventListener('pointerdown', async (e) => {
    canvas.setPointerCapture(e.pointerId);
    pointers.set(e.pointerId, { x: e.offsetX, y: e.offsetY });
    if (pointers.size === 2) {
      if (gesture?.hand) release(gesture);
      gesture = { kind: 'pinch' };
      return;
    }
    if (pointers.size > 2) return;
    const picked = e.button === 0 ? pick(e.offsetX, e.offsetY) : null;
    if (!picked?.hit) {
      gesture = { kind: e.button === 0 && !e.ctrlKey ? 'orbit' : 'pan', x: e.offsetX, y: e.offsetY };
      return;
    }
    gesture = { kind: 'object', x0: e.offsetX, y0: e.offsetY, t0: performance.now(), picked, pushing: e.shiftKey || push.checked, moved: false, hand: null };
    const g = gesture;
    g.comb = stencil(picked.point).catch((err) => { fail(err); return null; });
  });
  canvas.addEventListener('pointermove', async (e) => {
    const prev = pointers.get(e.pointerId);
    if (!prev || !gesture) return;
    const x = e.offsetX, y = e.offsetY;
    if (gesture.kind === 'pinch' && pointers.size === 2) {
      const [a, b] = [...pointers.values()];
      const d0 = Math.hypot(a.x - b.x, a.y - b.y);
      pointers.set(e.pointerId, { x, y });
      const [c, d] = [...pointers.values()];
      const d1 = Math.hypot(c.x - d.x, c.y - d.y);
      if (d1 > 0) view.camera.zoom(d0 / d1);
      view.camera.pan((x - prev.x) / 2, (y - prev.y) / 2, canvas.clientHeight);
      view.dirty = true;
      return;
    }
    pointers.set(e.pointerId, { x, y });
    if (gesture.kind === 'orbit') {
      view.camera.orbit(x - gesture.x, y - gesture.y);
      gesture.x = x; gesture.y = y;
      view.dirty = true;
    } else if (gesture.kind === 'pan') {
      view.camera.pan(x - gesture.x, y - gesture.y, canvas.clientHeight);
      gesture.x = x; gesture.y = y;
      view.dirty = true;
    } else if (gesture.kind === 'object') {
      if (!gesture.moved && Math.hypot(x - gesture.x0, y - gesture.y0) < 4) return;
      gesture.moved = true;
      const at = performance.now();
      const comb = await gesture.comb;
      if (!comb || gesture.released) return;
      moveHand(gesture, x, y, comb, at);
    }
  });
  // The grabbed point follows the pointer in the plane through it facing the camera; a push's
  // force grows with the drag's length, along the view direction.
  function moveHand(g, x, y, comb, at) {
    const ray = view.camera.ray(x, y, canvas.clientWidth, canvas.clientHeight);
    const p = g.picked.point;
    if (!g.hand) {
      markUndo();
      g.hand = { start: apply(comb, 'position', state.control), normal: view.camera.basis().forward };
      g.t0 = performance.now();
    }
    if (g.pushing) {
      const m = state.material;
      const D = (m.youngs_modulus * m.thickness ** 3) / (12 * (1 - m.poisson_ratio ** 2));
      const magnitude = (20 * D / state.size) * Math.min(1, Math.hypot(x - g.x0, y - g.y0) / 200);
      sendHold('hand', { surface_forces: [{ face: p.face, subface: p.subface, u: p.u, v: p.v, force: vec.scale(g.hand.normal, magnitude) }] }, at);
      return;
    }
    const n = g.hand.normal;
    const denom = vec.dot(ray.direction, n);
    if (Math.abs(denom) < 1e-9) return;
    const t = vec.dot(vec.sub(g.hand.start, ray.origin), n) / denom;
    const target = vec.add(ray.origin, vec.scale(ray.direction, t));
    if (!g.clamp) g.clamp = clamp(comb, p, g.hand.start);  // tangents as shown when grabbed
    sendHold('hand', { limit_constraints: [{ ...g.clamp, displacement: vec.sub(target, apply(comb, 'position', state.rest)) }] }, at);
  }
  function release(g) {
    g.released = true;
    if (g.hand) sendHold('hand', null);
  }
  const end = async (e) => {
    pointers.delete(e.pointerId);
    const g = gesture;
    if (!g) return;
    if (g.kind === 'object') {
      if (!g.moved) await togglePin(g);
      else release(g);
    }
    if (pointers.size === 0) gesture = null;
  };
  canvas.addEventListener('pointerup', end);
  canvas.addEventListener('pointercancel', end);
  canvas.addEventListener('wheel', (e) => {
    e.preventDefault();
    view.camera.zoom(Math.exp(e.deltaY * 0.001));
    view.dirty = true;
  }, { passive: false });

  async function togglePin(g) {
    const comb = await g.comb;
    if (!comb) return;
    markUndo();
    // A click near a pin (on screen) removes it.
    const near = state.pins.findIndex((pin) => vec.norm(vec.sub(positionAt(pin), g.picked.position)) < 0.02 * state.size);
    if (near >= 0) state.pins.splice(near, 1);
    else state.pins.push({ point: g.picked.point, comb });
    sendPins();
  }

  // --- undo / redo through the result history: a stored result's request, posted again -------
  function markUndo() {
    if (state.resId) state.undo.push(state.resId);
    state.redo = [];
    undo.disabled = !state.undo.length;
    redo.disabled = true;
  }
  async function restore(resId) {
    try {
      const request = await client.resultRequest(id, resId);
      onResult(await client.deform(id, request));
    } catch (err) {
      fail(err);
    }
  }
  undo.addEventListener('click', async () => {
    const target = state.undo.pop();
    if (target === undefined) return;
    state.redo.push(state.resId);
    undo.disabled = !state.undo.length;
    redo.disabled = false;
    await restore(target);
  });
  redo.addEventListener('click', async () => {
    const target = state.redo.pop();
    if (target === undefined) return;
    state.undo.push(state.resId);
    undo.disabled = false;
    redo.disabled = !state.redo.length;
    await restore(target);
  });

  // --- controls -----------------------------------------------------------------------------------------
  level.addEventListener('change', () => loadLevel(Number(level.value)).catch(fail));
  color.addEventListener('change', showShape);
  ghost.addEventListener('change', () => { view.showGhost = ghost.checked; view.dirty = true; });
  floor.addEventListener('change', () => { markUndo(); sendFloor(); });
  window.addEventListener('resize', () => { view.dirty = true; });
  window.addEventListener('pagehide', () => {
    // Let go of everything this tab holds (the leases would end it within 10 s anyway).
    for (const [holdId, s] of senders) {
      if (s.last) fetch(`/geometries/${id}/holds/${holdId}`, { method: 'DELETE', keepalive: true, headers: client.authHeaders() }).catch(() => {});
    }
  });

  await loadLevel(Number(level.value));
  // Follow every client: the newest result at once, then each new one (reconnecting by itself).
  client.events(id, {
    onResult,
    onState: (s) => { state.connection = s === 'open' ? 'live' : s; showStatus(); },
  });
  window.softshell.ready = true;
  showStatus();
}

const geometry = params.get('geometry');
(geometry ? viewPage(geometry.toLowerCase()) : listPage()).catch((err) => {
  root.replaceChildren(el('p', { class: 'error', role: 'alert' }, message(err)));
});
