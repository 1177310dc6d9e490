// The JavaScript client module against a real softshell-server: codecs both ways, geometries,
// results, limit combinations, render tables, stresses, holds and events with resume.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import {
  ApiError, Client, LimitSurface, decodeRequestBinary, decodeResultBinary, decodeRenderTableJson, encodeGeometryBinary,
  encodeRequestBinary, encodeResultBinary, decodeGeometryBinary, parseObj, rows3,
} from '../src/client.js';
import { assetMesh, grid, startServer, until } from './support/harness.js';

let server, client, gridId;

// A determined request on the 4 x 4 grid: corners pinned, a push in the middle scaled by k.
const pinnedPush = (k) => ({
  vertex_constraints: [0, 4, 20, 24].map((index) => ({ index, mask: 7, displacement: [0, 0, 0] })),
  forces: [{ index: 12, force: [0, 0, -0.25 * k] }],
});

before(async () => {
  server = await startServer();
  client = new Client(server.url);
  const up = await client.upload(grid(4));
  gridId = up.geom_id;
  await client.waitReady(gridId);
});
after(async () => server?.stop());

test('geometry codecs: binary and JSON uploads of the same values get the same id, and read back', async () => {
  const g = grid(4);
  const bin = encodeGeometryBinary(g);
  const decoded = decodeGeometryBinary(bin);
  assert.deepEqual(rows3(decoded.vertices), g.vertices);
  assert.deepEqual(decoded.faces, g.faces);
  assert.deepEqual(decoded.material, g.material);
  const a = await client.upload(g, { format: 'binary' });
  assert.equal(a.geom_id, gridId);
  assert.equal(a.created, false);
  const back = await client.geometry(gridId, { format: 'binary' });
  assert.deepEqual(rows3(back.vertices), g.vertices);
  const json = await client.geometry(gridId);
  assert.deepEqual(rows3(json.vertices), g.vertices);
  assert.equal(json.geom_id, gridId);
  const list = await client.geometries();
  assert.ok(list.some((e) => e.geom_id === gridId && e.status === 'ready'));
  assert.throws(() => encodeGeometryBinary({ ...g, faces: [[0, 1, 2]] }), /quads only/);
});

test('request and result codecs round-trip, and binary and JSON deformations agree', async () => {
  const req = { vertex_constraints: [{ index: 3, mask: 5, displacement: [0.5, 0, -1] }],
    lagrange_constraints: [{ indices: [1, 2], coefficients: [[0.5, 0.5, 0.5], [0.5, 0.5, 0.5]], values: [0, 0.25, 0] }],
    forces: [{ index: 7, force: [0, -10, 0] }] };
  assert.deepEqual(decodeRequestBinary(encodeRequestBinary(req)), req);
  assert.throws(() => encodeRequestBinary({ limit_constraints: [{ face: 0, u: 0, v: 0, displacement: [0, 0, 0] }] }), /JSON-only/);
  const r = { res_id: 9, positions: new Float64Array([1, 2, 3, 0.5, -0.25, 8]) };
  assert.deepEqual(decodeResultBinary(encodeResultBinary(r)), r);

  const viaJson = await client.deform(gridId, pinnedPush(1));
  const viaBinary = await client.deform(gridId, pinnedPush(1), { format: 'binary' });
  assert.equal(viaBinary.res_id, viaJson.res_id + 1);
  assert.equal(viaJson.positions.length, 25 * 3);
  for (let i = 0; i < viaJson.positions.length; ++i) assert.ok(Math.abs(viaJson.positions[i] - viaBinary.positions[i]) < 1e-6);
  assert.ok(viaJson.positions[3 * 12 + 2] < 0, 'the middle moves down');
  const stored = await client.result(gridId, viaJson.res_id, { format: 'binary' });
  assert.equal(stored.res_id, viaJson.res_id);
  assert.deepEqual(Array.from(stored.positions), Array.from(viaJson.positions, (x) => Math.fround(x)));
  const ids = await client.resultIds(gridId);
  assert.ok(ids.includes(viaBinary.res_id));
  const request = await client.resultRequest(gridId, viaJson.res_id);
  assert.equal(request.forces[0].index, 12);
});

test('latest_result: newest at once, a long poll woken by a new result, 204 when nothing comes', async () => {
  const newest = await client.latestResult(gridId, { have: 0 });
  assert.ok(newest.res_id >= 1);
  assert.equal(await client.latestResult(gridId, { have: newest.res_id, wait: 0 }), null);
  const waiting = client.latestResult(gridId, { have: newest.res_id, wait: 10 });
  const posted = await new Client(server.url).deform(gridId, pinnedPush(3));
  assert.equal((await waiting).res_id, posted.res_id);
});

test('limit_comb in both formats, and errors carry the server message', async () => {
  const point = { face: 5, subface: 0, u: 0.25, v: 0.5 };
  const json = await client.limitComb(gridId, point);
  const bin = await client.limitComb(gridId, point, { format: 'binary' });
  assert.deepEqual(bin.indices, json.indices);
  json.position.forEach((w, k) => assert.ok(Math.abs(w - bin.position[k]) < 1e-6));
  assert.ok(Math.abs(json.position.reduce((a, b) => a + b, 0) - 1) < 1e-12);
  await assert.rejects(client.limitComb(gridId, { face: 99, u: 0.5, v: 0.5 }), (err) => err instanceof ApiError && err.status === 400 && /face/.test(err.message));
  await assert.rejects(client.status('00000000000000000000000000000000'), (err) => err.status === 404 && err.code === 'not_found');
  // A mesh the simulation cannot use: the server says why.
  await assert.rejects(client.upload({ vertices: [[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces: [[0, 1, 5]], material: grid().material }),
    (err) => err.status === 400 && /control point 5/.test(err.message));
});

test('render tables: binary and JSON give the same surface; picking maps triangles to (face, u, v)', async () => {
  const spot = assetMesh('catmark_nonquads.obj');
  const { geom_id: id } = await client.upload(spot);
  const bin = await client.renderTable(id, 2);
  const json = await client.renderTable(id, 2, { format: 'json' });
  assert.equal(bin.vertices, json.vertices);
  assert.deepEqual(Array.from(bin.triangles), Array.from(json.triangles));
  assert.deepEqual(Array.from(bin.quads.path), Array.from(json.quads.path));
  const rest = new Float64Array(spot.vertices.flat());
  const a = new LimitSurface(bin).evaluate(rest).positions;
  const b = Float64Array.from(new LimitSurface(json).evaluate(rest).positions);
  let size = 0, worst = 0;
  for (let i = 0; i < a.length; ++i) { worst = Math.max(worst, Math.abs(a[i] - b[i])); size = Math.max(size, Math.abs(b[i])); }
  assert.ok(worst < 1e-6 * size, `f32 and f64 stencils differ by ${worst}`);
  // A vertex of a quad maps to its own corner parameters.
  const s = new LimitSurface(json);
  const p = s.surfacePoint(0, [1, 0, 0]);
  const c = s.quadCornerParams(0)[0];
  assert.deepEqual([p.u, p.v], c);
  assert.equal(p.face, json.quads.root_face[0]);
  assert.throws(() => s.surfacePoint(1e9, [1, 0, 0]), /out of range/);
  assert.deepEqual(decodeRenderTableJson(JSON.stringify({ ...jsonLayout(json) })).quads.depth.length, json.quads.depth.length);
  await assert.rejects(client.renderTable(id, 9), (err) => err.status === 400);
});

function jsonLayout(t) {
  const arr = (x) => Array.from(x);
  return { level: t.level, control_points: t.control_points, vertices: t.vertices,
    stencils: Object.fromEntries(Object.entries(t.stencils).map(([k, v]) => [k, arr(v)])),
    quads: Object.fromEntries(Object.entries(t.quads).map(([k, v]) => [k, arr(v)])), triangles: arr(t.triangles) };
}

test('stresses at the render vertices of a level', async () => {
  const r = await client.deform(gridId, pinnedPush(2));
  const s = await client.stresses(gridId, r.res_id, { level: 2, yield_strength: 1e3 });
  const table = await client.renderTable(gridId, 2);
  assert.equal(s.von_mises.length, table.vertices);
  assert.ok(s.max.von_mises_top > 0 || s.max.von_mises_bottom > 0);
  const points = await client.stresses(gridId, r.res_id, { points: [{ face: 5, subface: 0, u: 0.5, v: 0.5 }] });
  assert.equal(points.von_mises.length, 1);
});

test('OBJ parsing', () => {
  const m = parseObj('# c\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\nf -4/1/1 -3 -2\n');
  assert.deepEqual(m.faces, [[0, 1, 2, 3], [0, 1, 2]]);
  assert.throws(() => parseObj('v 0 0\n'), /line 1/);
  assert.throws(() => parseObj('v 0 0 0\nf 1 x 2\n'), /line 2/);
});

// --- v2: holds and events ----------------------------------------------------------------------

// A hold that determines the grid alone: a clamped point (position and tangents) moved up.
const clampAt = (dz) => ({ limit_constraints: [{ face: 5, subface: 0, u: 0.5, v: 0.5, displacement: [0, 0, dz],
  du_displacement: [0, 0, 0], dv_displacement: [0, 0, 0] }] });

test('holds: put, renew, list, read, release', async () => {
  const put = await client.putHold(gridId, 'node-hand', clampAt(0.01), { ttl: 30 });
  assert.ok(put.res_id > 0);
  assert.equal(put.holds['node-hand'], 1);
  const renewed = await client.putHold(gridId, 'node-hand', clampAt(0.01), { ttl: 30 });
  assert.equal(renewed.holds['node-hand'], 1, 'the same body renews without a new version');
  const moved = await client.putHold(gridId, 'node-hand', clampAt(0.02), { ttl: 30 });
  assert.equal(moved.holds['node-hand'], 2);
  const list = await client.holds(gridId);
  assert.deepEqual(list.holds.map((h) => h.hold_id), ['node-hand']);
  assert.equal(list.state, 'solved');
  const one = await client.hold(gridId, 'node-hand');
  assert.equal(one.version, 2);
  assert.equal(one.request.limit_constraints[0].displacement[2], 0.02);
  const pending = await client.putHold(gridId, 'node-hand', clampAt(0.03), { wait: 0 });
  assert.equal(pending.pending, true);
  const released = await client.deleteHold(gridId, 'node-hand');
  assert.ok(released.res_id > moved.res_id);
  assert.ok(released.positions.every((x, i) => Math.abs(x - grid(4).vertices.flat()[i]) < 1e-9), 'back to the rest shape');
  await assert.rejects(client.deleteHold(gridId, 'node-hand'), (err) => err.status === 404);
  await assert.rejects(client.putHold(gridId, 'bad id!', clampAt(0)), (err) => err.status === 400);
});

test('events: the newest at once, each new one, resume after a reconnect', async (t) => {
  const start = await client.latestResult(gridId);
  const got = [];
  const states = [];
  const sub = client.events(gridId, { onResult: (r) => got.push(r), onState: (s) => states.push(s) });
  t.after(() => sub.close());
  await until(() => got.length >= 1, { what: 'the newest result' });
  assert.equal(got[0].res_id, start.res_id);
  const a = await client.deform(gridId, pinnedPush(4));
  await until(() => got.some((r) => r.res_id === a.res_id), { what: 'a new result' });
  const found = got.find((r) => r.res_id === a.res_id);
  assert.deepEqual(Array.from(found.positions), Array.from(a.positions));
  sub.close();
  // Missed while away: the resumed stream starts after the last id it had.
  const b = await client.deform(gridId, pinnedPush(5));
  const c = await client.deform(gridId, pinnedPush(6));
  const resumed = [];
  const sub2 = client.events(gridId, { have: a.res_id, onResult: (r) => resumed.push(r) });
  t.after(() => sub2.close());
  await until(() => resumed.some((r) => r.res_id === c.res_id), { what: 'the resumed stream' });
  assert.ok(resumed.every((r) => r.res_id > a.res_id));
  assert.ok(b.res_id < c.res_id);
  // Last-Event-ID takes precedence over have (what EventSource sends when it reconnects).
  const res = await fetch(`${server.url}/geometries/${gridId}/events?have=0`, { headers: { 'Last-Event-ID': String(c.res_id) } });
  const reader = res.body.getReader();
  const pushed = await client.deform(gridId, pinnedPush(7));
  let text = '';
  while (!text.includes(`id: ${pushed.res_id}`)) text += new TextDecoder().decode((await reader.read()).value);
  assert.ok(!text.includes(`id: ${c.res_id}\n`), 'nothing older than Last-Event-ID');
  await reader.cancel();
  sub2.close();
  assert.ok(states.includes('open'));
});

test('events: a follower reconnects by itself when the server restarts on the same port', async (t) => {
  const own = await startServer();
  const c = new Client(own.url);
  const { geom_id: id } = await c.upload(grid(4));
  await c.waitReady(id);
  const first = await c.deform(id, pinnedPush(1));
  const got = [];
  const states = [];
  const sub = c.events(id, { onResult: (r) => got.push(r), onState: (s) => states.push(s), retryMs: 100 });
  t.after(() => sub.close());
  t.after(() => own.stop());
  await until(() => got.length === 1, { what: 'first event' });
  assert.equal(got[0].res_id, first.res_id);
  const port = new URL(own.url).port;
  await own.stop();
  await until(() => states.includes('reconnecting'), { what: 'reconnecting' });
  const again = await startServer(['--port', port]).catch(() => null);
  if (!again) { sub.close(); return; } // the port was taken meanwhile: nothing to check
  // A fresh server knows nothing: upload, and the follower, still retrying, sees result 1 again only
  // if it is newer than what it had, so post two.
  await c.upload(grid(4));
  await c.waitReady(id);
  await c.deform(id, pinnedPush(1));
  const second = await c.deform(id, pinnedPush(2));
  await until(() => got.some((r) => r.res_id === second.res_id), { what: 'events after the restart' });
  sub.close();
  await again.stop();
});
