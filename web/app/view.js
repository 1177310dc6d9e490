// The 3D view: plain WebGL2. Draws a LimitSurface (positions and normals computed from the render
// table), lit, coloured by a per-vertex scalar through a colour map, with an optional translucent
// ghost of the rest shape, a floor grid and pin markers; an orbit camera (orbit, zoom, pan).

const VS = `#version 300 es
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in float a_value;
uniform mat4 u_view, u_proj;
out vec3 v_normal, v_world;
out float v_value;
void main() {
  v_normal = a_normal;
  v_world = a_position;
  v_value = a_value;
  gl_Position = u_proj * u_view * vec4(a_position, 1.0);
}`;

const FS = `#version 300 es
precision highp float;
in vec3 v_normal, v_world;
in float v_value;
uniform vec3 u_eye, u_base;
uniform float u_alpha, u_range;
uniform int u_colored;
out vec4 o_color;
// A compact viridis approximation (polynomial fit).
vec3 viridis(float t) {
  t = clamp(t, 0.0, 1.0);
  const vec3 c0 = vec3(0.2777, 0.0054, 0.3341), c1 = vec3(0.1051, 1.4046, 1.3846), c2 = vec3(-0.3309, 0.2148, 0.0951),
             c3 = vec3(-4.6342, -5.7991, -19.3324), c4 = vec3(6.2283, 14.1799, 56.6906), c5 = vec3(4.7764, -13.7451, -65.3530),
             c6 = vec3(-5.4355, 4.6459, 26.3124);
  return c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * (c5 + t * c6)))));
}
void main() {
  vec3 n = normalize(v_normal);
  vec3 view = normalize(u_eye - v_world);
  if (dot(n, view) < 0.0) n = -n;  // two-sided
  vec3 key = normalize(vec3(0.4, 0.8, 0.5)), fill = normalize(vec3(-0.6, 0.2, -0.4));
  vec3 albedo = u_colored == 1 ? viridis(u_range > 0.0 ? v_value / u_range : 0.0) : u_base;
  float diffuse = max(dot(n, key), 0.0) * 0.75 + max(dot(n, fill), 0.0) * 0.25;
  float spec = pow(max(dot(n, normalize(key + view)), 0.0), 48.0) * 0.25;
  o_color = vec4(albedo * (0.22 + diffuse) + vec3(spec), u_alpha);
}`;

const LINE_VS = `#version 300 es
layout(location = 0) in vec3 a_position;
uniform mat4 u_view, u_proj;
uniform float u_point;
void main() { gl_Position = u_proj * u_view * vec4(a_position, 1.0); gl_PointSize = u_point; }`;
const LINE_FS = `#version 300 es
precision mediump float;
uniform vec4 u_color;
out vec4 o_color;
void main() { o_color = u_color; }`;

function compile(gl, vs, fs) {
  const p = gl.createProgram();
  for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
    const s = gl.createShader(type);
    gl.shaderSource(s, src);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error('shader: ' + gl.getShaderInfoLog(s));
    gl.attachShader(p, s);
  }
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error('program: ' + gl.getProgramInfoLog(p));
  const uniforms = {};
  for (let i = 0, n = gl.getProgramParameter(p, gl.ACTIVE_UNIFORMS); i < n; ++i) {
    const name = gl.getActiveUniform(p, i).name;
    uniforms[name] = gl.getUniformLocation(p, name);
  }
  return { program: p, uniforms };
}

// --- small vector and matrix helpers (column-major 4x4, as WebGL expects) ---------------------
export const vec = {
  sub: (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]],
  add: (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]],
  scale: (a, s) => [a[0] * s, a[1] * s, a[2] * s],
  dot: (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2],
  cross: (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]],
  norm: (a) => Math.hypot(a[0], a[1], a[2]),
  unit: (a) => { const n = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / n, a[1] / n, a[2] / n]; },
};

function lookAt(eye, target, up) {
  const f = vec.unit(vec.sub(target, eye));
  const s = vec.unit(vec.cross(f, up));
  const u = vec.cross(s, f);
  return new Float32Array([s[0], u[0], -f[0], 0, s[1], u[1], -f[1], 0, s[2], u[2], -f[2], 0,
    -vec.dot(s, eye), -vec.dot(u, eye), vec.dot(f, eye), 1]);
}

function perspective(fovy, aspect, near, far) {
  const f = 1 / Math.tan(fovy / 2);
  return new Float32Array([f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) / (near - far), -1, 0, 0, (2 * far * near) / (near - far), 0]);
}

/** An orbit camera around `target`: yaw and pitch in radians, distance in mesh units. */
export class Camera {
  constructor() {
    this.target = [0, 0, 0];
    this.yaw = 0.6;
    this.pitch = 0.35;
    this.distance = 3;
    this.fovy = (45 * Math.PI) / 180;
  }
  fit(lo, hi) {
    this.target = vec.scale(vec.add(lo, hi), 0.5);
    this.size = vec.norm(vec.sub(hi, lo)) || 1;
    this.distance = (0.62 * this.size) / Math.tan(this.fovy / 2);
  }
  eye() {
    const c = Math.cos(this.pitch);
    return vec.add(this.target, vec.scale([c * Math.sin(this.yaw), Math.sin(this.pitch), c * Math.cos(this.yaw)], this.distance));
  }
  basis() {
    const f = vec.unit(vec.sub(this.target, this.eye()));
    const r = vec.unit(vec.cross(f, [0, 1, 0]));
    return { forward: f, right: r, up: vec.cross(r, f) };
  }
  /** The ray through canvas pixel (x, y) (CSS pixels from the top left) of a w x h canvas. */
  ray(x, y, w, h) {
    const { forward, right, up } = this.basis();
    const t = Math.tan(this.fovy / 2);
    const nx = ((2 * x) / w - 1) * t * (w / h), ny = (1 - (2 * y) / h) * t;
    return { origin: this.eye(), direction: vec.unit(vec.add(forward, vec.add(vec.scale(right, nx), vec.scale(up, ny)))) };
  }
  orbit(dx, dy) {
    this.yaw -= dx * 0.008;
    this.pitch = Math.max(-1.5, Math.min(1.5, this.pitch + dy * 0.008));
  }
  zoom(factor) { this.distance = Math.max(1e-3 * (this.size ?? 1), this.distance * factor); }
  pan(dx, dy, h) {
    const { right, up } = this.basis();
    const s = (2 * this.distance * Math.tan(this.fovy / 2)) / h;
    this.target = vec.add(this.target, vec.add(vec.scale(right, -dx * s), vec.scale(up, dy * s)));
  }
}

export class View {
  constructor(canvas) {
    this.canvas = canvas;
    const gl = canvas.getContext('webgl2', { antialias: true, preserveDrawingBuffer: true });
    if (!gl) throw new Error('this browser has no WebGL2');
    this.gl = gl;
    this.surfaceProgram = compile(gl, VS, FS);
    this.lineProgram = compile(gl, LINE_VS, LINE_FS);
    this.camera = new Camera();
    this.mesh = null;
    this.ghost = null;
    this.floorY = null;
    this.pins = [];
    this.showGhost = false;
    this.colored = false;
    this.range = 1;
    this.frames = 0;
    this.onFrame = null;
    this.dirty = true;
    this.afterFrames = [];
    this.lines = gl.createBuffer();
    const loop = () => {
      if (this.dirty) this.draw();
      requestAnimationFrame(loop);
    };
    requestAnimationFrame(loop);
  }

  /** Calls `f` once the next frame has been drawn (`redraw`: draw one even if nothing changed). */
  afterFrame(f, redraw = true) {
    this.afterFrames.push(f);
    if (redraw) this.dirty = true;
  }

  makeMesh(triangles, count) {
    const gl = this.gl;
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    const buffers = [0, 1, 2].map((loc) => {
      const b = gl.createBuffer();
      gl.bindBuffer(gl.ARRAY_BUFFER, b);
      gl.bufferData(gl.ARRAY_BUFFER, (loc === 2 ? 4 : 12) * count, gl.DYNAMIC_DRAW);
      gl.enableVertexAttribArray(loc);
      gl.vertexAttribPointer(loc, loc === 2 ? 1 : 3, gl.FLOAT, false, 0, 0);
      return b;
    });
    const ib = gl.createBuffer();
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, ib);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, triangles, gl.STATIC_DRAW);
    gl.bindVertexArray(null);
    return { vao, buffers, ib, indexCount: triangles.length, vertexCount: count, f32: new Float32Array(3 * count) };
  }

  /** New triangles (a new level): `triangles` Uint32Array, `count` vertices. */
  setTopology(triangles, count) {
    for (const m of [this.mesh, this.ghost]) if (m) this.dispose(m);
    this.mesh = this.makeMesh(triangles, count);
    this.ghost = this.makeMesh(triangles, count);
    this.dirty = true;
  }

  dispose(m) {
    const gl = this.gl;
    for (const b of m.buffers) gl.deleteBuffer(b);
    gl.deleteBuffer(m.ib);
    gl.deleteVertexArray(m.vao);
  }

  upload(m, positions, normals, values) {
    const gl = this.gl;
    m.f32.set(positions);
    gl.bindBuffer(gl.ARRAY_BUFFER, m.buffers[0]);
    gl.bufferSubData(gl.ARRAY_BUFFER, 0, m.f32);
    gl.bindBuffer(gl.ARRAY_BUFFER, m.buffers[1]);
    gl.bufferSubData(gl.ARRAY_BUFFER, 0, normals);
    if (values) {
      gl.bindBuffer(gl.ARRAY_BUFFER, m.buffers[2]);
      gl.bufferSubData(gl.ARRAY_BUFFER, 0, values);
    }
    this.dirty = true;
  }

  setShape(positions, normals) { this.upload(this.mesh, positions, normals, null); }
  setGhost(positions, normals) { this.upload(this.ghost, positions, normals, null); }
  setValues(values, range) {
    const gl = this.gl;
    gl.bindBuffer(gl.ARRAY_BUFFER, this.mesh.buffers[2]);
    gl.bufferSubData(gl.ARRAY_BUFFER, 0, values);
    this.range = range;
    this.dirty = true;
  }

  resize() {
    const dpr = Math.min(window.devicePixelRatio || 1, 2);
    const w = Math.max(1, Math.round(this.canvas.clientWidth * dpr)), h = Math.max(1, Math.round(this.canvas.clientHeight * dpr));
    if (this.canvas.width !== w || this.canvas.height !== h) {
      this.canvas.width = w;
      this.canvas.height = h;
      this.dirty = true;
    }
  }

  draw() {
    this.dirty = false;
    this.resize();
    const gl = this.gl;
    gl.viewport(0, 0, this.canvas.width, this.canvas.height);
    gl.clearColor(0.93, 0.94, 0.96, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    if (!this.mesh) return;
    const cam = this.camera;
    const size = cam.size ?? 1;
    const view = lookAt(cam.eye(), cam.target, [0, 1, 0]);
    const proj = perspective(cam.fovy, this.canvas.width / this.canvas.height, Math.max(1e-4 * size, cam.distance - 4 * size),
      cam.distance + 4 * size);
    gl.enable(gl.DEPTH_TEST);
    const sp = this.surfaceProgram;
    gl.useProgram(sp.program);
    gl.uniformMatrix4fv(sp.uniforms.u_view, false, view);
    gl.uniformMatrix4fv(sp.uniforms.u_proj, false, proj);
    gl.uniform3fv(sp.uniforms.u_eye, cam.eye());
    gl.uniform3fv(sp.uniforms.u_base, [0.85, 0.55, 0.3]);
    gl.uniform1f(sp.uniforms.u_range, this.range);
    gl.uniform1i(sp.uniforms.u_colored, this.colored ? 1 : 0);
    gl.uniform1f(sp.uniforms.u_alpha, 1);
    gl.disable(gl.BLEND);
    gl.bindVertexArray(this.mesh.vao);
    gl.drawElements(gl.TRIANGLES, this.mesh.indexCount, gl.UNSIGNED_INT, 0);
    // Lines and points: floor grid, pins.
    const lp = this.lineProgram;
    gl.useProgram(lp.program);
    gl.uniformMatrix4fv(lp.uniforms.u_view, false, view);
    gl.uniformMatrix4fv(lp.uniforms.u_proj, false, proj);
    gl.bindVertexArray(null);
    gl.bindBuffer(gl.ARRAY_BUFFER, this.lines);
    gl.enableVertexAttribArray(0);
    gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
    if (this.floorY !== null) {
      const g = [], n = 10, c = cam.target, half = 0.8 * size;
      for (let i = 0; i <= n; ++i) {
        const s = -half + (2 * half * i) / n;
        g.push(c[0] + s, this.floorY, c[2] - half, c[0] + s, this.floorY, c[2] + half, c[0] - half, this.floorY, c[2] + s, c[0] + half, this.floorY, c[2] + s);
      }
      gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(g), gl.STREAM_DRAW);
      gl.uniform4fv(lp.uniforms.u_color, [0.35, 0.4, 0.5, 1]);
      gl.drawArrays(gl.LINES, 0, g.length / 3);
    }
    if (this.pins.length) {
      gl.disable(gl.DEPTH_TEST);
      gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(this.pins.flat()), gl.STREAM_DRAW);
      gl.uniform1f(lp.uniforms.u_point, 9 * Math.min(window.devicePixelRatio || 1, 2));
      gl.uniform4fv(lp.uniforms.u_color, [0.85, 0.1, 0.15, 1]);
      gl.drawArrays(gl.POINTS, 0, this.pins.length);
      gl.enable(gl.DEPTH_TEST);
    }
    gl.disableVertexAttribArray(0);
    if (this.showGhost && this.ghost) {
      gl.useProgram(sp.program);
      gl.enable(gl.BLEND);
      gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA);
      gl.depthMask(false);
      gl.uniform1i(sp.uniforms.u_colored, 0);
      gl.uniform3fv(sp.uniforms.u_base, [0.3, 0.45, 0.8]);
      gl.uniform1f(sp.uniforms.u_alpha, 0.22);
      gl.bindVertexArray(this.ghost.vao);
      gl.drawElements(gl.TRIANGLES, this.ghost.indexCount, gl.UNSIGNED_INT, 0);
      gl.depthMask(true);
      gl.disable(gl.BLEND);
    }
    gl.bindVertexArray(null);
    this.frames += 1;
    this.onFrame?.();
    const after = this.afterFrames;
    this.afterFrames = [];
    // At the next frame's start this one has been composited: what "on screen" means here.
    if (after.length) requestAnimationFrame(() => { for (const f of after) f(); });
  }
}
