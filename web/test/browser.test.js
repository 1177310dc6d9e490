// The web app in real headless Chromium (Debian's, WebGL on SwiftShader) against a real
// softshell-server: it renders (pixels), follows other clients, pulls through holds, two pages
// see each other, its picking and limit positions agree with the SDK, and a bad upload shows the
// server's message. Screenshots go to docs/images (SOFTSHELL_SCREENSHOTS=0 skips them).
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { mkdirSync } from 'node:fs';
import { join } from 'node:path';
import { ApiError, Client, rows3 } from '../src/client.js';
import { appPage, assetMesh, canvasPixels, launchChromium, repo, sdkProbe, sleep, startServer, until, waitReady } from './support/harness.js';

let server, client, browser, id, rest, geometryJson;
const LEVEL = 2;

before(async () => {
  server = await startServer();
  client = new Client(server.url);
  const mesh = assetMesh('spot_control_mesh.obj');
  rest = mesh.vertices.flat();
  ({ geom_id: id } = await client.upload(mesh));
  await client.waitReady(id);
  geometryJson = await (await fetch(`${server.url}/geometries/${id}`)).json();
  browser = await launchChromium();
});
after(async () => {
  await browser?.close();
  await server?.stop();
});

const link = () => `${server.url}/?geometry=${id}&level=${LEVEL}`;

async function openView() {
  const p = await appPage(browser.context);
  await p.page.goto(link());
  await waitReady(p.page);
  if (process.env.SOFTSHELL_TEST_EVENTS !== '0') await until(() => p.page.evaluate(() => window.softshell.state.connection === 'live'), { what: 'the event stream' });
  return p;
}

// The canvas's position on the page, and a pixel (canvas coordinates) where the object is.
async function objectPixel(page) {
  return page.evaluate(() => {
    const c = document.getElementById('view');
    const r = c.getBoundingClientRect();
    for (const [fx, fy] of [[0.5, 0.5], [0.5, 0.6], [0.45, 0.55], [0.55, 0.45]]) {
      const x = Math.round(fx * r.width), y = Math.round(fy * r.height);
      if (window.softshell.pickAt(x, y)?.hit) return { x, y, left: r.left, top: r.top };
    }
    return null;
  });
}

// In-page snapshots of the canvas, compared in the page (no megabytes over the wire).
const snap = (page, name) => page.evaluate((n) => {
  const c = document.getElementById('view');
  const t = document.createElement('canvas');
  t.width = c.width; t.height = c.height;
  t.getContext('2d').drawImage(c, 0, 0);
  (window.__snaps ??= {})[n] = t.getContext('2d').getImageData(0, 0, c.width, c.height).data;
}, name);
const changed = (page, a, b) => page.evaluate(([x, y]) => {
  const p = window.__snaps[x], q = window.__snaps[y];
  if (!p || !q || p.length !== q.length) return 1;
  let n = 0;
  for (let i = 0; i < p.length; i += 4) if (Math.abs(p[i] - q[i]) + Math.abs(p[i + 1] - q[i + 1]) + Math.abs(p[i + 2] - q[i + 2]) > 24) n++;
  return n / (p.length / 4);
}, [a, b]);

async function drag(page, from, dx, dy, steps = 8) {
  await page.mouse.move(from.left + from.x, from.top + from.y);
  await page.mouse.down();
  for (let i = 1; i <= steps; ++i) {
    await page.mouse.move(from.left + from.x + (dx * i) / steps, from.top + from.y + (dy * i) / steps);
    await sleep(40);
  }
}

const holdsOf = async () => (await client.holds(id)).holds.map((h) => h.hold_id);

test('the page renders the object (pixels, not only the DOM) without console errors', async () => {
  const { page, errors } = await openView();
  const px = await canvasPixels(page);
  assert.ok(px.width > 100 && px.height > 100);
  assert.ok(px.nonBackground > 0.03, `the canvas shows the object (${(100 * px.nonBackground).toFixed(1)}% of its pixels)`);
  assert.ok(px.nonBackground < 0.9);
  assert.equal(await page.evaluate(() => window.softshell.view.gl.isContextLost()), false);
  const status = await page.textContent('#status');
  assert.match(status, /result \d+/);
  assert.deepEqual(errors, []);
  await page.close();
});

test('a result posted by another client shows within a second', async () => {
  const { page, errors } = await openView();
  await snap(page, 'before');
  // Another client clamps a point of the surface and moves it (a determined request).
  const request = { limit_constraints: [{ face: 10, subface: 0, u: 0.5, v: 0.5, displacement: [0, 0.08, 0], du_displacement: [0, 0, 0], dv_displacement: [0, 0, 0] }] };
  const posted = await client.deform(id, request);
  const t0 = Date.now();
  await until(() => page.evaluate((k) => window.softshell.state.resId === k, posted.res_id), { timeout: 1000, interval: 10, what: 'the result on the page' });
  const ms = Date.now() - t0;
  assert.ok(ms < 1000, `shown after ${ms} ms`);
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
  await snap(page, 'after');
  assert.ok(await changed(page, 'before', 'after') > 0.002, 'the picture changed');
  assert.deepEqual(errors, []);
  await page.close();
});

test('the limit positions the page draws agree with the SDK Tessellation to 1e-6 of the size', async () => {
  const { page } = await openView();
  const state = await page.evaluate(() => ({ positions: Array.from(window.softshell.state.surface.positions), control: Array.from(window.softshell.state.control) }));
  const sdk = sdkProbe({ geometry: geometryJson, level: LEVEL, positions: rows3(state.control) });
  assert.equal(state.positions.length, sdk.vertices.length);
  let worst = 0;
  for (let i = 0; i < sdk.vertices.length; ++i) worst = Math.max(worst, Math.abs(sdk.vertices[i] - state.positions[i]));
  console.log(`# limit positions: worst difference ${(worst / sdk.size).toExponential(2)} of the object size`);
  assert.ok(worst < 1e-6 * sdk.size, `worst ${worst} vs size ${sdk.size}`);
  await page.close();
});

test('picking: the page and the SDK Picker give the same (face, subface, u, v) for the same rays', async () => {
  const { page } = await openView();
  const picks = await page.evaluate(() => {
    const c = document.getElementById('view');
    const out = [];
    for (let i = 1; i < 12; ++i) for (let j = 1; j < 12; ++j) {
      const p = window.softshell.pickAt((i / 12) * c.clientWidth, (j / 12) * c.clientHeight);
      if (p?.hit) out.push({ ray: p.ray, triangle: p.hit.triangle, point: p.point });
    }
    return { picks: out, control: Array.from(window.softshell.state.control) };
  });
  assert.ok(picks.picks.length >= 10, `${picks.picks.length} pixels hit the object`);
  const sdk = sdkProbe({ geometry: geometryJson, level: LEVEL, positions: rows3(picks.control), rays: picks.picks.map((p) => p.ray) });
  let same = 0, worst = 0;
  picks.picks.forEach((p, k) => {
    const s = sdk.picks[k];
    assert.ok(s.hit, `the SDK hits too at pick ${k}`);
    if (s.triangle !== p.triangle) return; // a ray through a shared edge may take either side
    same++;
    assert.equal(p.point.face, s.face);
    assert.equal(p.point.subface, s.subface);
    worst = Math.max(worst, Math.abs(p.point.u - s.u), Math.abs(p.point.v - s.v));
  });
  console.log(`# picking: ${same}/${picks.picks.length} same triangle, worst (u, v) difference ${worst.toExponential(2)}`);
  assert.ok(same >= 0.95 * picks.picks.length);
  assert.ok(worst < 1e-5);
  await page.close();
});

test('a drag creates a hold and the server stores deformations; release deletes it', async () => {
  const { page, errors } = await openView();
  const at = await objectPixel(page);
  assert.ok(at, 'a pixel on the object');
  const tab = await page.evaluate(() => window.softshell.tab);
  const before = (await client.resultIds(id)).length;
  await drag(page, at, 0, -60);
  await until(async () => (await holdsOf()).includes(`${tab}-hand`), { what: 'the hold' });
  await until(async () => (await client.resultIds(id)).length > before, { what: 'stored deformations' });
  const held = await client.latestResult(id);
  assert.ok(held.holds?.[`${tab}-hand`] >= 1, 'the newest result includes the hand');
  const moved = held.positions.some((x, i) => Math.abs(x - rest[i]) > 1e-3);
  assert.ok(moved, 'the object is deformed');
  await page.mouse.up();
  await until(async () => !(await holdsOf()).includes(`${tab}-hand`), { what: 'the release' });
  const released = await until(async () => { const r = await client.latestResult(id); return !r.holds?.[`${tab}-hand`] && r; }, { what: 'the result without the hand' });
  assert.ok(released.positions.every((x, i) => Math.abs(x - rest[i]) < 1e-9), 'back to the rest shape');
  assert.match(await page.textContent('#status'), /latency \d+\.\d ms/);
  assert.deepEqual(errors, []);
  await page.close();
});

test('a click pins and unpins; the floor toggle holds the object; undo and redo step through the history', async () => {
  const { page, errors } = await openView();
  const tab = await page.evaluate(() => window.softshell.tab);
  // Start from a deformed shape posted by another client.
  const request = { limit_constraints: [{ face: 10, subface: 0, u: 0.5, v: 0.5, displacement: [0, 0.05, 0], du_displacement: [0, 0, 0], dv_displacement: [0, 0, 0] }] };
  const posted = await client.deform(id, request);
  await until(() => page.evaluate((k) => window.softshell.state.resId >= k, posted.res_id), { what: 'the posted result' });
  const at = await objectPixel(page);
  await page.mouse.click(at.left + at.x, at.top + at.y);
  await until(async () => (await holdsOf()).includes(`${tab}-pins`), { what: 'the pin hold' });
  const pinned = await until(async () => { const r = await client.latestResult(id); return r.holds?.[`${tab}-pins`] && r; }, { what: 'the pinned result' });
  // The pin holds the point where it was shown: the pinned shape differs from the posted one
  // (which the pin alone does not reproduce), and undo brings the posted shape back.
  await until(() => page.evaluate(() => !document.getElementById('undo').disabled), { what: 'undo enabled' });
  await page.click('#undo');
  const undone = await until(async () => { const r = await client.latestResult(id); return r.res_id > pinned.res_id && r; }, { what: 'the undo result' });
  undone.positions.forEach((x, i) => assert.ok(Math.abs(x - posted.positions[i]) < 1e-9, 'undo restores the posted shape'));
  assert.equal((await client.resultRequest(id, undone.res_id)).limit_constraints[0].face, 10);
  await page.click('#redo');
  const redone = await until(async () => { const r = await client.latestResult(id); return r.res_id > undone.res_id && r; }, { what: 'the redo result' });
  redone.positions.forEach((x, i) => assert.ok(Math.abs(x - pinned.positions[i]) < 1e-9, 'redo restores the pinned shape'));
  // Clicking the pin again removes it.
  await page.mouse.click(at.left + at.x, at.top + at.y);
  await until(async () => !(await holdsOf()).includes(`${tab}-pins`), { what: 'the unpin' });
  // The floor: one hold of limit points under the object, held where they are.
  await page.check('#floor');
  await until(async () => (await holdsOf()).includes(`${tab}-floor`), { what: 'the floor hold' });
  const floor = await client.hold(id, `${tab}-floor`);
  assert.ok(floor.request.limit_constraints.length >= 3, `${floor.request.limit_constraints.length} floor contacts`);
  await page.uncheck('#floor');
  await until(async () => !(await holdsOf()).includes(`${tab}-floor`), { what: 'the floor released' });
  assert.deepEqual(errors, []);
  await page.close();
});

test('two pages on the same link: a drag in one changes the picture in the other', async () => {
  const a = await openView();
  const b = await openView();
  await snap(b.page, 'before');
  const at = await objectPixel(a.page);
  await drag(a.page, at, 40, -50);
  const tab = await a.page.evaluate(() => window.softshell.tab);
  await until(() => b.page.evaluate((t) => !!window.softshell.state.holders && window.softshell.state.holders >= 1, tab), { what: 'the other page following' });
  await b.page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
  await snap(b.page, 'after');
  const diff = await changed(b.page, 'before', 'after');
  assert.ok(diff > 0.002, `page B changed ${(100 * diff).toFixed(2)}% of its pixels`);
  assert.match(await b.page.textContent('#status'), /1 holding/);
  await a.page.mouse.up();
  await until(async () => (await holdsOf()).length === 0, { what: 'the release' });
  assert.deepEqual(a.errors, []);
  assert.deepEqual(b.errors, []);
  await a.page.close();
  await b.page.close();
});

test('a phone-sized page: a touch drag pulls the object, two fingers zoom', async () => {
  const { page, errors } = await appPage(browser.context);
  await page.setViewportSize({ width: 390, height: 740 });
  await page.goto(link());
  await waitReady(page);
  await until(() => page.evaluate(() => window.softshell.state.connection === 'live'), { what: 'the event stream' });
  const header = await page.evaluate(() => document.querySelector('header').getBoundingClientRect().height);
  assert.ok(header < 120, `the controls fit (${header} px of header)`);
  const at = await objectPixel(page);
  const tab = await page.evaluate(() => window.softshell.tab);
  const cdp = await browser.context.newCDPSession(page);
  const touch = (type, points) => cdp.send('Input.dispatchTouchEvent', { type, touchPoints: points.map(([x, y], id) => ({ x, y, id })) });
  const x = at.left + at.x, y = at.top + at.y;
  await touch('touchStart', [[x, y]]);
  for (let i = 1; i <= 8; ++i) {
    await touch('touchMove', [[x, y - 6 * i]]);
    await sleep(40);
  }
  await until(async () => (await holdsOf()).includes(`${tab}-hand`), { what: 'the touch hold' });
  await touch('touchEnd', []);
  await until(async () => !(await holdsOf()).includes(`${tab}-hand`), { what: 'the release' });
  // Two fingers apart: the camera zooms in, no hold.
  const d0 = await page.evaluate(() => window.softshell.view.camera.distance);
  await touch('touchStart', [[150, 600], [240, 600]]);
  for (let i = 1; i <= 6; ++i) {
    await touch('touchMove', [[150 - 10 * i, 600], [240 + 10 * i, 600]]);
    await sleep(30);
  }
  await touch('touchEnd', []);
  const d1 = await page.evaluate(() => window.softshell.view.camera.distance);
  assert.ok(d1 < d0, `zoomed in (${d0} -> ${d1})`);
  assert.deepEqual(errors, []);
  await page.close();
});

test('an upload of a bad OBJ shows the server message', async () => {
  const { page } = await appPage(browser.context);
  await page.goto(`${server.url}/`);
  await page.waitForSelector('#geometries');
  // Three faces on one edge: non-manifold, which the server refuses.
  const obj = 'v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nf 1 2 3\nf 2 1 4\nf 1 2 5\n';
  let expected = '';
  try {
    await client.upload({ vertices: [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]], faces: [[0, 1, 2], [1, 0, 3], [0, 1, 4]],
      material: { youngs_modulus: 6.9e10, poisson_ratio: 0.33, thickness: 0.001 } });
  } catch (err) {
    assert.ok(err instanceof ApiError);
    expected = err.message;
  }
  assert.ok(expected.length > 10, 'the server refuses the mesh');
  await page.setInputFiles('#obj-file', { name: 'bad.obj', mimeType: 'text/plain', buffer: Buffer.from(obj) });
  await page.waitForFunction(() => document.getElementById('upload-error').textContent.length > 0);
  const shown = await page.textContent('#upload-error');
  assert.ok(shown.includes(expected), `shows "${shown}"`);
  await page.close();
});

test('a page served from another origin uses the API with --cors-origin (and cannot without it)', async () => {
  const http = await import('node:http');
  const site = http.createServer((req, res) => {
    res.writeHead(200, { 'Content-Type': 'text/html' });
    res.end('<!doctype html><title>elsewhere</title>');
  });
  await new Promise((r) => site.listen(0, '127.0.0.1', r));
  const origin = `http://127.0.0.1:${site.address().port}`;
  const open = await startServer(['--cors-origin', origin]);
  try {
    const c = new Client(open.url);
    const { geom_id: gid } = await c.upload(assetMesh('spot_control_mesh.obj'));
    await c.waitReady(gid);
    const { page, errors } = await appPage(browser.context);
    await page.goto(origin + '/');
    const body = { limit_constraints: [{ face: 10, subface: 0, u: 0.5, v: 0.5, displacement: [0, 0.01, 0], du_displacement: [0, 0, 0], dv_displacement: [0, 0, 0] }] };
    const run = (base) => page.evaluate(async ([b, id, req]) => {
      try {
        const { Client: C } = await import(`${b}/app/client.js`);
        const cl = new C(b);
        const list = await cl.geometries();
        const put = await cl.putHold(id, 'elsewhere-hand', req);
        const seen = await new Promise((resolve, reject) => {
          const sub = cl.events(id, { onResult: (r) => { sub.close(); resolve(r.res_id); } });
          setTimeout(() => { sub.close(); reject(new Error('no event')); }, 5000);
        });
        const released = await cl.deleteHold(id, 'elsewhere-hand');
        return { ok: true, geometries: list.length, put: put.res_id, seen, released: released.res_id };
      } catch (err) {
        return { ok: false, error: String(err) };
      }
    }, [base, gid, body]);
    const allowed = await run(open.url);
    assert.ok(allowed.ok, allowed.error);
    assert.equal(allowed.geometries, 1);
    assert.ok(allowed.seen >= allowed.put && allowed.released > allowed.put);
    // The suite's own server has no --cors-origin: the browser refuses to read its answers.
    const refused = await run(server.url);
    assert.equal(refused.ok, false);
    assert.ok(errors.length > 0, 'the browser reports the blocked requests');
    await page.close();
  } finally {
    await open.stop();
    site.close();
  }
});

test('screenshots: two pages pulling one object, and the stress view', { skip: process.env.SOFTSHELL_SCREENSHOTS === '0' }, async () => {
  const dir = join(repo, 'docs/images');
  mkdirSync(dir, { recursive: true });
  const page = await browser.context.newPage();
  await page.setViewportSize({ width: 960, height: 420 });
  await page.setContent(`<!doctype html><body style="margin:0;display:flex;gap:6px;background:#fff">
    <iframe name="a" src="${link()}" style="width:477px;height:420px;border:0"></iframe>
    <iframe name="b" src="${link()}&color=displacement&ghost=1" style="width:477px;height:420px;border:0"></iframe></body>`);
  const fa = await until(() => page.frame({ name: 'a' }), { what: 'frame a' });
  const fb = await until(() => page.frame({ name: 'b' }), { what: 'frame b' });
  for (const f of [fa, fb]) await waitReady(f);
  // Frame a stands the cow on the floor and pulls its head sideways; frame b follows.
  await fa.check('#floor');
  await until(async () => (await holdsOf()).some((h) => h.endsWith('-floor')), { what: 'the floor' });
  const head = await fa.evaluate(() => {
    const c = document.getElementById('view');
    const r = c.getBoundingClientRect();
    for (let y = 0.15; y < 0.9; y += 0.02) for (let x = 0.3; x < 0.7; x += 0.02) {
      const px = Math.round(x * r.width), py = Math.round(y * r.height);
      if (window.softshell.pickAt(px, py)?.hit) return { x: px, y: py + 6, left: r.left, top: r.top };
    }
    return null;
  });
  await drag(page, head, 45, 10, 10);
  await until(() => fb.evaluate(() => window.softshell.state.holders >= 1), { what: 'frame b following' });
  await sleep(300);
  await page.screenshot({ path: join(dir, 'browser-two-pages.png') });
  await page.mouse.up();
  await fa.uncheck('#floor');
  await until(async () => (await holdsOf()).length === 0, { what: 'the floor released' });
  await page.close();
});
