// softshell client: the HTTP API of PROTOCOL.md (v1 and v2: holds, events) and the render-table
// extension, for browsers and Node 18+ (ES module, no dependencies). (One file of ~660 lines on
// purpose: a page imports one module with no build step.)
//
//   import { Client, LimitSurface } from './client.js';
//   const c = new Client('http://127.0.0.1:8080');
//   const table = await c.renderTable(id, 2);          // once per geometry and level
//   const surface = new LimitSurface(table);
//   const frame = surface.evaluate(rest);              // x = S P, normals from the du/dv stencils
//   const sub = c.events(id, { onResult: r => surface.evaluate(r.positions) });
//
// Values: control positions travel as flat Float64Arrays (x0, y0, z0, x1, ...); requests and hold
// bodies are objects in PROTOCOL.md's JSON request layout; ids are 32-hex-digit strings. Errors are
// thrown as ApiError carrying the server's status, short code and message.

const JSON_TYPE = 'application/json';
const BINARY_TYPE = 'application/octet-stream';

export class ApiError extends Error {
  constructor(status, code, message) {
    super(message);
    this.name = 'ApiError';
    this.status = status;
    this.code = code;
  }
}

// ---------------------------------------------------------------------------------------------
// Binary codecs (little-endian, PROTOCOL.md)

class Writer {
  constructor(bytes) {
    this.buf = new ArrayBuffer(bytes);
    this.view = new DataView(this.buf);
    this.at = 0;
  }
  u32(v) {
    if (!Number.isInteger(v) || v < 0 || v > 0xffffffff) throw new RangeError(`not a u32: ${v}`);
    this.view.setUint32(this.at, v, true);
    this.at += 4;
  }
  f32(v) {
    if (!Number.isFinite(v)) throw new RangeError(`not a finite number: ${v}`);
    this.view.setFloat32(this.at, v, true);
    this.at += 4;
  }
}

class Reader {
  constructor(buf, what) {
    this.view = buf instanceof DataView ? buf : new DataView(buf instanceof ArrayBuffer ? buf : buf.buffer, buf.byteOffset ?? 0, buf.byteLength);
    this.at = 0;
    this.what = what;
  }
  need(bytes) {
    if (this.at + bytes > this.view.byteLength) throw new RangeError(`${this.what}: the body ends early (${this.view.byteLength} bytes)`);
  }
  u32() {
    this.need(4);
    const v = this.view.getUint32(this.at, true);
    this.at += 4;
    return v;
  }
  f32() {
    this.need(4);
    const v = this.view.getFloat32(this.at, true);
    this.at += 4;
    return v;
  }
  end() {
    if (this.at !== this.view.byteLength) throw new RangeError(`${this.what}: ${this.view.byteLength - this.at} trailing bytes`);
  }
}

function flat3(list, what) {
  if (list instanceof Float64Array || list instanceof Float32Array) return list;
  const out = new Float64Array(list.length * 3);
  list.forEach((p, i) => {
    if (!Array.isArray(p) || p.length !== 3) throw new TypeError(`${what}[${i}] must be [x, y, z]`);
    out.set(p, 3 * i);
  });
  return out;
}

/** Rows [[x, y, z], ...] of a flat array. */
export function rows3(flat) {
  const out = [];
  for (let i = 0; i < flat.length; i += 3) out.push([flat[i], flat[i + 1], flat[i + 2]]);
  return out;
}

/** Binary upload body: every face a quad; `material` {youngs_modulus, poisson_ratio, thickness}. */
export function encodeGeometryBinary({ vertices, faces, material }) {
  const v = flat3(vertices, 'vertices');
  const n = v.length / 3;
  const w = new Writer(20 + 12 * n + 16 * faces.length);
  w.u32(n);
  w.u32(faces.length);
  w.f32(material.youngs_modulus);
  w.f32(material.poisson_ratio);
  w.f32(material.thickness);
  for (const x of v) w.f32(x);
  faces.forEach((f, i) => {
    if (f.length !== 4) throw new RangeError(`face ${i} has ${f.length} corners: the binary layout carries quads only (use JSON)`);
    for (const k of f) w.u32(k);
  });
  return w.buf;
}

export function decodeGeometryBinary(buf) {
  const r = new Reader(buf, 'geometry');
  const n = r.u32();
  const m = r.u32();
  const material = { youngs_modulus: r.f32(), poisson_ratio: r.f32(), thickness: r.f32() };
  r.need(12 * n + 16 * m);
  const vertices = new Float64Array(3 * n);
  for (let i = 0; i < 3 * n; ++i) vertices[i] = r.f32();
  const faces = [];
  for (let f = 0; f < m; ++f) faces.push([r.u32(), r.u32(), r.u32(), r.u32()]);
  r.end();
  return { vertices, faces, material };
}

const JSON_ONLY = ['limit_constraints', 'surface_forces', 'surface_load', 'pressure', 'model'];

/** True if a request (JSON layout) has only fields of the binary layout. */
export function fitsBinaryRequest(request) {
  return JSON_ONLY.every((k) => request[k] === undefined || (Array.isArray(request[k]) && request[k].length === 0) ||
    (k === 'pressure' && request[k] === 0));
}

/** Binary deformation request (three u32 counts first). Throws for JSON-only fields. */
export function encodeRequestBinary(request) {
  if (!fitsBinaryRequest(request)) throw new TypeError('this request has JSON-only fields (limit_constraints, surface_forces, ...): send JSON');
  const vc = request.vertex_constraints ?? [];
  const lc = request.lagrange_constraints ?? [];
  const fc = request.forces ?? [];
  let bytes = 12 + 20 * vc.length + 16 * fc.length;
  for (const l of lc) bytes += 4 + 16 * l.indices.length + 12;
  const w = new Writer(bytes);
  w.u32(vc.length);
  w.u32(lc.length);
  w.u32(fc.length);
  for (const c of vc) for (const x of c.displacement ?? [0, 0, 0]) w.f32(x);
  for (const c of vc) {
    w.u32(c.mask ?? 7);
    w.u32(c.index);
  }
  for (const l of lc) {
    w.u32(l.indices.length);
    for (const i of l.indices) w.u32(i);
    for (const c of l.coefficients) for (const x of c) w.f32(x);
    for (const x of l.values ?? [0, 0, 0]) w.f32(x);
  }
  for (const f of fc) for (const x of f.force) w.f32(x);
  for (const f of fc) w.u32(f.index);
  return w.buf;
}

export function decodeRequestBinary(buf) {
  const r = new Reader(buf, 'request');
  const v = r.u32();
  const l = r.u32();
  const f = r.u32();
  r.need(20 * v);
  const disp = [];
  for (let i = 0; i < v; ++i) disp.push([r.f32(), r.f32(), r.f32()]);
  const vertex_constraints = disp.map((d) => ({ mask: r.u32(), index: r.u32(), displacement: d }));
  const lagrange_constraints = [];
  for (let i = 0; i < l; ++i) {
    const p = r.u32();
    r.need(16 * p + 12);
    const indices = [];
    for (let k = 0; k < p; ++k) indices.push(r.u32());
    const coefficients = [];
    for (let k = 0; k < p; ++k) coefficients.push([r.f32(), r.f32(), r.f32()]);
    lagrange_constraints.push({ indices, coefficients, values: [r.f32(), r.f32(), r.f32()] });
  }
  r.need(16 * f);
  const force = [];
  for (let i = 0; i < f; ++i) force.push([r.f32(), r.f32(), r.f32()]);
  const forces = force.map((F) => ({ index: r.u32(), force: F }));
  r.end();
  return { vertex_constraints, lagrange_constraints, forces };
}

/** Binary result: u32 res_id, n x (f32 x, y, z). */
export function encodeResultBinary({ res_id, positions }) {
  const p = flat3(positions, 'positions');
  const w = new Writer(4 + 4 * p.length);
  w.u32(res_id);
  for (const x of p) w.f32(x);
  return w.buf;
}

export function decodeResultBinary(buf) {
  const r = new Reader(buf, 'result');
  const res_id = r.u32();
  const bytes = r.view.byteLength - 4;
  if (bytes % 12 !== 0) throw new RangeError(`result: ${bytes} bytes of positions is not a multiple of 12`);
  const positions = new Float64Array(bytes / 4);
  for (let i = 0; i < positions.length; ++i) positions[i] = r.f32();
  return { res_id, positions };
}

/** A JSON result ({res_id, positions: [[x, y, z], ...], holds?}) with flat positions. */
export function decodeResultJson(obj) {
  const o = typeof obj === 'string' ? JSON.parse(obj) : obj;
  return { ...o, positions: flat3(o.positions, 'positions') };
}

export function encodeResultJson({ res_id, positions, ...rest }) {
  return JSON.stringify({ res_id, positions: rows3(positions), ...rest });
}

export function decodeLimitCombBinary(buf, point = {}) {
  const r = new Reader(buf, 'limit_comb');
  const p = r.u32();
  r.need(16 * p);
  const read = (f) => Array.from({ length: p }, f);
  const indices = read(() => r.u32());
  const position = read(() => r.f32());
  const du = read(() => r.f32());
  const dv = read(() => r.f32());
  r.end();
  return { ...point, indices, position, du, dv };
}

// ---------------------------------------------------------------------------------------------
// Render tables (GET /geometries/{id}/render?level=L, docs/api-notes.md)

/** Decodes the binary render table ("SSRT" v1) into typed arrays. */
export function decodeRenderTableBinary(buf) {
  const r = new Reader(buf, 'render table');
  r.need(32);
  const magic = String.fromCharCode(...new Uint8Array(r.view.buffer, r.view.byteOffset, 4));
  if (magic !== 'SSRT') throw new RangeError('render table: not an SSRT body');
  r.at = 4;
  const version = r.u32();
  if (version !== 1) throw new RangeError(`render table: version ${version} is not supported`);
  const level = r.u32(), control_points = r.u32(), vertices = r.u32(), nq = r.u32(), nw = r.u32();
  r.u32(); // flags
  const total = 32 + 4 * (vertices + 1) + 16 * nw + 32 * nq + 24 * nq;
  if (r.view.byteLength !== total) throw new RangeError(`render table: ${r.view.byteLength} bytes, the header says ${total}`);
  // Copies into aligned typed arrays (the body may sit at any offset; little-endian hosts only
  // would allow views, DataView reads keep it portable).
  const base = r.view.byteOffset;
  const bytes = new Uint8Array(r.view.buffer, base, total);
  let at = 32;
  const take = (Type, count) => {
    const out = new Type(count);
    new Uint8Array(out.buffer).set(bytes.subarray(at, at + 4 * count));
    at += 4 * count;
    return out;
  };
  const offsets = take(Uint32Array, vertices + 1);
  const indices = take(Uint32Array, nw);
  const position = take(Float32Array, nw);
  const du = take(Float32Array, nw);
  const dv = take(Float32Array, nw);
  const q = take(Uint32Array, 8 * nq);
  const triangles = take(Uint32Array, 6 * nq);
  const quads = { vertices: new Uint32Array(4 * nq), root_face: new Uint32Array(nq), subface: new Uint32Array(nq),
    path: new Uint32Array(nq), depth: new Uint8Array(nq), rotation: new Uint8Array(nq) };
  for (let i = 0; i < nq; ++i) {
    quads.vertices.set(q.subarray(8 * i, 8 * i + 4), 4 * i);
    quads.root_face[i] = q[8 * i + 4];
    quads.subface[i] = q[8 * i + 5];
    quads.path[i] = q[8 * i + 6];
    quads.depth[i] = q[8 * i + 7] & 0xff;
    quads.rotation[i] = (q[8 * i + 7] >> 8) & 0xff;
  }
  return { level, control_points, vertices, stencils: { offsets, indices, position, du, dv }, quads, triangles };
}

/** The JSON render table with typed arrays (weights stay double precision). */
export function decodeRenderTableJson(obj) {
  const o = typeof obj === 'string' ? JSON.parse(obj) : obj;
  const s = o.stencils, q = o.quads;
  return {
    level: o.level, control_points: o.control_points, vertices: o.vertices,
    stencils: { offsets: Uint32Array.from(s.offsets), indices: Uint32Array.from(s.indices), position: Float64Array.from(s.position),
      du: Float64Array.from(s.du), dv: Float64Array.from(s.dv) },
    quads: { vertices: Uint32Array.from(q.vertices), root_face: Uint32Array.from(q.root_face), subface: Uint32Array.from(q.subface),
      path: Uint32Array.from(q.path), depth: Uint8Array.from(q.depth), rotation: Uint8Array.from(q.rotation) },
    triangles: Uint32Array.from(o.triangles),
  };
}

/**
 * The limit surface of a render table: positions and normals for any control positions, and the
 * (face, subface, u, v) of a point on a rendered triangle (the SDK's Tessellation::surface_point).
 */
export class LimitSurface {
  constructor(table) {
    this.table = table;
    this.vertexCount = table.vertices;
    this.triangleCount = table.triangles.length / 3;
    this.positions = new Float64Array(3 * table.vertices);
    this.normals = new Float32Array(3 * table.vertices);
  }

  /** x = S P and n = (S_u P) x (S_v P) / |.| for flat control positions P (#V x 3). */
  evaluate(control) {
    const { offsets, indices, position, du, dv } = this.table.stencils;
    if (control.length !== 3 * this.table.control_points) {
      throw new RangeError(`expected ${this.table.control_points} control points, got ${control.length / 3}`);
    }
    const X = this.positions, N = this.normals;
    for (let i = 0, n = this.vertexCount; i < n; ++i) {
      let x = 0, y = 0, z = 0, ux = 0, uy = 0, uz = 0, vx = 0, vy = 0, vz = 0;
      for (let k = offsets[i], end = offsets[i + 1]; k < end; ++k) {
        const j = 3 * indices[k];
        const px = control[j], py = control[j + 1], pz = control[j + 2];
        const w = position[k], a = du[k], b = dv[k];
        x += w * px; y += w * py; z += w * pz;
        ux += a * px; uy += a * py; uz += a * pz;
        vx += b * px; vy += b * py; vz += b * pz;
      }
      X[3 * i] = x; X[3 * i + 1] = y; X[3 * i + 2] = z;
      const nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
      const len = Math.hypot(nx, ny, nz);
      const s = len > 0 ? 1 / len : 0;
      N[3 * i] = nx * s; N[3 * i + 1] = ny * s; N[3 * i + 2] = nz * s;
    }
    return { positions: X, normals: N };
  }

  /** (u, v) of quad q's four vertices in its (sub-)face (Tessellation::quad_corner_params). */
  quadCornerParams(q) {
    const { path, depth, rotation } = this.table.quads;
    let u0 = 0, v0 = 0, u1 = 1, v1 = 1;
    for (let i = 0; i < depth[q]; ++i) {
      const hu = 0.5 * (u1 - u0), hv = 0.5 * (v1 - v0);
      const c = (path[q] >>> (2 * i)) & 3;
      if (c === 1 || c === 2) u0 += hu; else u1 -= hu;
      if (c === 2 || c === 3) v0 += hv; else v1 -= hv;
    }
    const rect = [[u0, v0], [u1, v0], [u1, v1], [u0, v1]];
    return [0, 1, 2, 3].map((i) => rect[(i + rotation[q]) % 4]);
  }

  /** The surface point (paper Section 5.1) of barycentric weights [b0, b1, b2] on triangle t. */
  surfacePoint(t, bary) {
    if (!(t >= 0 && t < this.triangleCount)) throw new RangeError(`triangle ${t} is out of range`);
    const q = t >> 1;
    const c = this.quadCornerParams(q);
    const tri = t % 2 === 0 ? [0, 1, 2] : [0, 2, 3];
    let u = 0, v = 0;
    for (let i = 0; i < 3; ++i) {
      u += bary[i] * c[tri[i]][0];
      v += bary[i] * c[tri[i]][1];
    }
    const clamp = (x) => Math.min(1, Math.max(0, x));
    return { face: this.table.quads.root_face[q], subface: this.table.quads.subface[q], u: clamp(u), v: clamp(v) };
  }

  /**
   * The nearest triangle hit by the ray origin + t dir (t >= 0) on the current positions, with
   * barycentric weights, or null. Watertight enough for picking; O(#triangles).
   */
  intersect(origin, dir, only = null) {
    const X = this.positions, T = this.table.triangles;
    let best = null;
    const test = (t) => {
      const a = 3 * T[3 * t], b = 3 * T[3 * t + 1], c = 3 * T[3 * t + 2];
      const e1x = X[b] - X[a], e1y = X[b + 1] - X[a + 1], e1z = X[b + 2] - X[a + 2];
      const e2x = X[c] - X[a], e2y = X[c + 1] - X[a + 1], e2z = X[c + 2] - X[a + 2];
      const px = dir[1] * e2z - dir[2] * e2y, py = dir[2] * e2x - dir[0] * e2z, pz = dir[0] * e2y - dir[1] * e2x;
      const det = e1x * px + e1y * py + e1z * pz;
      if (det === 0) return;
      const inv = 1 / det;
      const sx = origin[0] - X[a], sy = origin[1] - X[a + 1], sz = origin[2] - X[a + 2];
      const u = (sx * px + sy * py + sz * pz) * inv;
      if (u < 0 || u > 1) return;
      const qx = sy * e1z - sz * e1y, qy = sz * e1x - sx * e1z, qz = sx * e1y - sy * e1x;
      const v = (dir[0] * qx + dir[1] * qy + dir[2] * qz) * inv;
      if (v < 0 || u + v > 1) return;
      const d = (e2x * qx + e2y * qy + e2z * qz) * inv;
      if (d < 0 || (best && d >= best.t)) return;
      best = { triangle: t, t: d, barycentric: [1 - u - v, u, v] };
    };
    if (only !== null) test(only);
    else for (let t = 0; t < this.triangleCount; ++t) test(t);
    return best;
  }
}

// ---------------------------------------------------------------------------------------------
// OBJ (v and f lines; what the upload form reads)

/** Parses OBJ text into {vertices: [[x, y, z]], faces: [[a, b, ...]]} (0-based); throws with the line. */
export function parseObj(text) {
  const vertices = [], faces = [];
  text.split(/\r?\n/).forEach((raw, i) => {
    const line = raw.replace(/#.*/, '').trim();
    if (!line) return;
    const [kw, ...rest] = line.split(/\s+/);
    if (kw === 'v') {
      const p = rest.slice(0, 3).map(Number);
      if (p.length !== 3 || p.some((x) => !Number.isFinite(x))) throw new SyntaxError(`OBJ line ${i + 1}: a vertex needs three numbers`);
      vertices.push(p);
    } else if (kw === 'f') {
      faces.push(rest.map((tok) => {
        const k = parseInt(tok.split('/')[0], 10);
        if (!Number.isInteger(k) || k === 0) throw new SyntaxError(`OBJ line ${i + 1}: bad vertex reference '${tok}'`);
        return k < 0 ? vertices.length + k : k - 1;
      }));
    }
  });
  return { vertices, faces };
}

// ---------------------------------------------------------------------------------------------
// Server-Sent Events over fetch (Node, or browsers without EventSource)

async function* sseEvents(body) {
  const decoder = new TextDecoder();
  let buffer = '';
  let event = { id: null, event: 'message', data: [] };
  for await (const chunk of body) {
    buffer += decoder.decode(chunk, { stream: true });
    let nl;
    while ((nl = buffer.search(/\r\n|\n|\r/)) >= 0) {
      const line = buffer.slice(0, nl);
      buffer = buffer.slice(nl + (buffer.startsWith('\r\n', nl) ? 2 : 1));
      if (line === '') {
        if (event.data.length) yield { id: event.id, event: event.event, data: event.data.join('\n') };
        event = { id: null, event: 'message', data: [] };
        continue;
      }
      if (line.startsWith(':')) continue; // a comment (keep-alive)
      const colon = line.indexOf(':');
      const field = colon < 0 ? line : line.slice(0, colon);
      let value = colon < 0 ? '' : line.slice(colon + 1);
      if (value.startsWith(' ')) value = value.slice(1);
      if (field === 'data') event.data.push(value);
      else if (field === 'id') event.id = value;
      else if (field === 'event') event.event = value;
    }
  }
}

// ---------------------------------------------------------------------------------------------
// The client

function hex(id) {
  if (typeof id !== 'string' || !/^[0-9a-fA-F]{32}$/.test(id)) throw new TypeError(`not a geometry id: ${id}`);
  return id.toLowerCase();
}

function query(params) {
  const q = Object.entries(params).filter(([, v]) => v !== undefined && v !== null);
  return q.length ? '?' + q.map(([k, v]) => `${encodeURIComponent(k)}=${encodeURIComponent(v)}`).join('&') : '';
}

export class Client {
  /**
   * @param {string} base  server URL ('' = the page's own origin)
   * @param {{fetch?: Function, EventSource?: Function, token?: string}} options  implementations to
   *   use; `token`: the access token of a server started with --auth-token-file, sent as
   *   `Authorization: Bearer <token>` on every request and event stream
   */
  constructor(base = '', options = {}) {
    this.base = base.replace(/\/$/, '');
    this.token = options.token || '';
    this.fetch = options.fetch ?? globalThis.fetch.bind(globalThis);
    this.EventSource = options.EventSource === undefined ? globalThis.EventSource : options.EventSource;
    /** Milliseconds of the last request (from sending to the whole answer read). */
    this.lastLatencyMs = 0;
  }

  async request(method, path, { body, type, accept = JSON_TYPE, ok = [200, 201] } = {}) {
    const headers = { Accept: accept, ...this.authHeaders() };
    if (body !== undefined) headers['Content-Type'] = type;
    const start = performance.now();
    const res = await this.fetch(this.base + path, { method, headers, body });
    const data = res.status === 204 ? null : (res.headers.get('content-type') ?? '').startsWith(JSON_TYPE) ? await res.json() : await res.arrayBuffer();
    this.lastLatencyMs = performance.now() - start;
    if (!ok.includes(res.status)) {
      if (data && typeof data === 'object' && !(data instanceof ArrayBuffer) && data.error) throw new ApiError(res.status, data.error, data.message);
      throw new ApiError(res.status, 'http_' + res.status, `${method} ${path}: HTTP ${res.status}`);
    }
    return { status: res.status, data };
  }

  /** `{Authorization: 'Bearer <token>'}` with a token, else `{}` (for requests made outside the client). */
  authHeaders() { return this.token ? { Authorization: `Bearer ${this.token}` } : {}; }

  json(method, path, body, opts = {}) {
    return this.request(method, path, { body: body === undefined ? undefined : JSON.stringify(body), type: JSON_TYPE, ...opts });
  }

  // --- geometries ------------------------------------------------------------------------------
  async geometries() { return (await this.json('GET', '/geometries')).data; }
  async status(id) { return (await this.json('GET', `/geometries/${hex(id)}/status`)).data; }
  /** The mesh as uploaded: {vertices: Float64Array, faces, material, boundary, geom_id, namespace}. */
  async geometry(id, { format = 'json' } = {}) {
    if (format === 'binary') {
      return decodeGeometryBinary((await this.request('GET', `/geometries/${hex(id)}`, { accept: BINARY_TYPE })).data);
    }
    const g = (await this.json('GET', `/geometries/${hex(id)}`)).data;
    return { ...g, vertices: flat3(g.vertices, 'vertices') };
  }
  /** Uploads {vertices, faces, material[, boundary]}: {geom_id, status, created}. */
  async upload(geometry, { namespace, format = 'json' } = {}) {
    const path = '/geometries' + query({ namespace });
    if (format === 'binary') {
      const { status, data } = await this.request('POST', path, { body: encodeGeometryBinary(geometry), type: BINARY_TYPE, accept: BINARY_TYPE });
      const b = new Uint8Array(data);
      return { geom_id: Array.from(b, (x) => x.toString(16).padStart(2, '0')).join(''), status: 'precomputing', created: status === 201 };
    }
    const body = { ...geometry, vertices: geometry.vertices instanceof Float64Array ? rows3(geometry.vertices) : geometry.vertices };
    const { status, data } = await this.json('POST', path, body);
    return { ...data, created: status === 201 };
  }
  /** Waits until the precomputation is done (polling the status); returns the status entry. */
  async waitReady(id, { timeoutMs = 120000, intervalMs = 100, onProgress } = {}) {
    const end = performance.now() + timeoutMs;
    for (;;) {
      const s = await this.status(id);
      onProgress?.(s);
      if (s.status !== 'precomputing') return s;
      if (performance.now() > end) throw new Error(`geometry ${id} still precomputing after ${timeoutMs} ms`);
      await new Promise((r) => setTimeout(r, intervalMs));
    }
  }

  // --- results ---------------------------------------------------------------------------------
  async decodeResult(data) {
    return data instanceof ArrayBuffer ? decodeResultBinary(data) : decodeResultJson(data);
  }
  /** POSTs a deformation request (JSON layout object); binary when it fits and format = 'binary'. */
  async deform(id, request, { format = 'json', model } = {}) {
    const path = `/geometries/${hex(id)}/results` + query({ model });
    const binary = format === 'binary' && fitsBinaryRequest(request);
    const { data } = binary
      ? await this.request('POST', path, { body: encodeRequestBinary(request), type: BINARY_TYPE, accept: BINARY_TYPE })
      : await this.json('POST', path, request);
    return this.decodeResult(data);
  }
  async resultIds(id) { return (await this.json('GET', `/geometries/${hex(id)}/results`)).data.res_ids; }
  async result(id, resId, { format = 'json' } = {}) {
    const { data } = await this.request('GET', `/geometries/${hex(id)}/results/${resId}`, { accept: format === 'binary' ? BINARY_TYPE : JSON_TYPE });
    return this.decodeResult(data);
  }
  /** The request that produced a result (JSON layout). */
  async resultRequest(id, resId) { return (await this.json('GET', `/geometries/${hex(id)}/results/${resId}/request`)).data; }
  /** The newest result newer than `have`, waiting up to `wait` s; null on 204. */
  async latestResult(id, { have = 0, wait = 0, format = 'json' } = {}) {
    const { data } = await this.request('GET', `/geometries/${hex(id)}/latest_result` + query({ have, wait }),
      { accept: format === 'binary' ? BINARY_TYPE : JSON_TYPE, ok: [200, 204] });
    return data === null ? null : this.decodeResult(data);
  }
  async limitComb(id, { face, subface = 0, u, v }, { format = 'json' } = {}) {
    const path = `/geometries/${hex(id)}/limit_comb` + query({ u, v, 'face-index': face, subface });
    if (format === 'binary') return decodeLimitCombBinary((await this.request('GET', path, { accept: BINARY_TYPE })).data, { face, subface, u, v });
    return (await this.json('GET', path)).data;
  }
  /** Stresses of a result at the level-L render vertices ({level}) or at points ({points}). */
  async stresses(id, resId, { level, points, yield_strength } = {}) {
    const path = `/geometries/${hex(id)}/results/${resId}/stresses`;
    if (points) return (await this.json('POST', path, { points, ...(yield_strength ? { yield_strength } : {}) })).data;
    return (await this.json('GET', path + query({ level, yield_strength: yield_strength || undefined }))).data;
  }

  // --- render tables -----------------------------------------------------------------------------
  async renderTable(id, level, { format = 'binary' } = {}) {
    const path = `/geometries/${hex(id)}/render` + query({ level });
    if (format === 'binary') return decodeRenderTableBinary((await this.request('GET', path, { accept: BINARY_TYPE })).data);
    return decodeRenderTableJson((await this.json('GET', path)).data);
  }

  // --- holds (PROTOCOL.md v2) ----------------------------------------------------------------------
  /**
   * Creates or replaces a hold: the first result that includes it ({res_id, positions, holds}), or
   * {hold_id, version, pending: true} when the server answered 202 (wait = 0 or past `wait`).
   */
  async putHold(id, holdId, request, { ttl, wait, model, format = 'json' } = {}) {
    const path = `/geometries/${hex(id)}/holds/${encodeURIComponent(holdId)}` + query({ ttl, wait, model });
    const binary = format === 'binary' && fitsBinaryRequest(request);
    const { status, data } = binary
      ? await this.request('PUT', path, { body: encodeRequestBinary(request), type: BINARY_TYPE, accept: BINARY_TYPE, ok: [200, 202] })
      : await this.json('PUT', path, request, { ok: [200, 202] });
    if (status === 202) return { ...(data instanceof ArrayBuffer ? {} : data), pending: true };
    return this.decodeResult(data);
  }
  /** Releases a hold: the first result without it (or throws ApiError 409 when the rest is unsolvable). */
  async deleteHold(id, holdId) {
    const { data } = await this.json('DELETE', `/geometries/${hex(id)}/holds/${encodeURIComponent(holdId)}`);
    return this.decodeResult(data);
  }
  async holds(id) { return (await this.json('GET', `/geometries/${hex(id)}/holds`)).data; }
  async hold(id, holdId) { return (await this.json('GET', `/geometries/${hex(id)}/holds/${encodeURIComponent(holdId)}`)).data; }

  // --- events ----------------------------------------------------------------------------------------
  /**
   * Follows a geometry's results (GET .../events): `onResult({res_id, positions, holds})` for the
   * newest result newer than `have`, then for each new one. Reconnects by itself (resuming after
   * the last id it got) until `close()`. `onState('open' | 'reconnecting' | 'closed', error?)`.
   * Uses EventSource where there is one (browsers), else fetch streaming (Node); also fetch with a
   * token, since EventSource cannot send the Authorization header (the server takes no token in
   * the URL). A 401 ends the stream (`onState('closed', error)`): retrying cannot help.
   */
  events(id, { have = 0, onResult, onState, retryMs = 500, useEventSource = !!this.EventSource && !this.token } = {}) {
    const url = (h) => `${this.base}/geometries/${hex(id)}/events` + query({ have: h });
    let last = have;
    let closed = false;
    let source = null, abort = null, timer = null;
    const deliver = (id_, data) => {
      const r = decodeResultJson(data);
      if (r.res_id <= last) return; // ids only grow; a resumed stream starts after `last`
      last = r.res_id;
      onResult?.(r);
    };
    const retry = (err) => {
      if (closed) return;
      onState?.('reconnecting', err);
      timer = setTimeout(connect, retryMs);
    };
    const connect = async () => {
      if (closed) return;
      if (useEventSource) {
        // EventSource resends Last-Event-ID by itself after a network error, but gives up on an
        // HTTP error answer (503 while a server restarts): then a new one starts from `last`.
        source = new this.EventSource(url(last));
        source.addEventListener('open', () => onState?.('open'));
        source.addEventListener('result', (e) => deliver(e.lastEventId, e.data));
        source.addEventListener('error', (e) => {
          if (source.readyState === 2) { // CLOSED
            source.close();
            retry(e);
          } else {
            onState?.('reconnecting', e);
          }
        });
        return;
      }
      abort = new AbortController();
      try {
        const res = await this.fetch(url(last), { headers: { Accept: 'text/event-stream', ...this.authHeaders(), ...(last ? { 'Last-Event-ID': String(last) } : {}) }, signal: abort.signal });
        if (res.status !== 200) {
          const text = await res.text();
          let message = `events: HTTP ${res.status}`;
          try { message = JSON.parse(text).message ?? message; } catch { /* not JSON */ }
          throw new ApiError(res.status, 'http_' + res.status, message);
        }
        onState?.('open');
        for await (const ev of sseEvents(res.body)) {
          if (ev.event === 'result') deliver(ev.id, ev.data);
        }
        retry(new Error('the event stream ended'));
      } catch (err) {
        if (closed) return;
        if (err instanceof ApiError && err.status === 401) {
          closed = true;
          onState?.('closed', err);
        } else {
          retry(err);
        }
      }
    };
    connect();
    return {
      close() {
        closed = true;
        clearTimeout(timer);
        source?.close();
        abort?.abort();
        onState?.('closed');
      },
      get lastId() { return last; },
    };
  }
}
