// Browser client numbers (not a test): frame rate of the page in headless Chromium (SwiftShader:
// a CPU floor, not a GPU) at level 3 on spot_control_mesh and spot_quadrangulated, the cost of
// one update in the page (x = S P and normals), bytes per update against sending a level-2
// triangulation, and the time from a pointer move to the new shape on screen on loopback.
//
//   node tests/bench/bench_browser.mjs            (after ./build.sh build and npm ci in web/)
import { Client } from '../../web/src/client.js';
import { appPage, assetMesh, launchChromium, sleep, startServer, until, waitReady } from '../../web/test/support/harness.js';

const server = await startServer();
const client = new Client(server.url);
const browser = await launchChromium();
const rows = [];
try {
  for (const name of (process.env.BENCH_MESHES ?? 'spot_control_mesh.obj,spot_quadrangulated.obj').split(',')) {
    const mesh = assetMesh(name);
    const { geom_id: id } = await client.upload(mesh);
    const t0 = performance.now();
    await client.waitReady(id, { timeoutMs: 600000 });
    const precompute = (performance.now() - t0) / 1000;
    const V = mesh.vertices.length;
    const result = await client.deform(id, { limit_constraints: [{ face: 3, u: 0.5, v: 0.5, displacement: [0, 0.01, 0], du_displacement: [0, 0, 0], dv_displacement: [0, 0, 0] }] });
    const eventJson = JSON.stringify({ res_id: result.res_id, positions: Array.from({ length: V }, (_, i) => Array.from(result.positions.slice(3 * i, 3 * i + 3))) });
    const l2 = await client.renderTable(id, 2);
    const tableBytes = {};
    for (const level of [2, 3]) {
      const res = await fetch(`${server.url}/geometries/${id}/render?level=${level}`, { headers: { Accept: 'application/octet-stream' } });
      tableBytes[level] = (await res.arrayBuffer()).byteLength;
    }

    // Frame rate at level 3: the camera turns every frame, so every frame is drawn.
    const { page, errors } = await appPage(browser.context);
    await page.setViewportSize({ width: 800, height: 600 });
    await page.goto(`${server.url}/?geometry=${id}&level=3`);
    await waitReady(page, 120000);
    const fps = await page.evaluate(async () => {
      const v = window.softshell.view;
      const f0 = v.frames, t0 = performance.now();
      await new Promise((done) => {
        const spin = () => {
          v.camera.orbit(2, 0);
          v.dirty = true;
          if (performance.now() - t0 < 5000) requestAnimationFrame(spin); else done();
        };
        requestAnimationFrame(spin);
      });
      return ((v.frames - f0) * 1000) / (performance.now() - t0);
    });
    // One update in the page: x = S P with normals (JavaScript), then the upload to WebGL.
    const update = await page.evaluate(() => {
      const s = window.softshell.state;
      const t0 = performance.now();
      for (let i = 0; i < 10; ++i) s.surface.evaluate(s.control);
      return (performance.now() - t0) / 10;
    });
    const triangles3 = await page.evaluate(() => window.softshell.state.surface.triangleCount);
    // Pointer move to new shape on screen (level 2, the page's default).
    await page.goto(`${server.url}/?geometry=${id}&level=2`);
    await waitReady(page, 120000);
    await until(() => page.evaluate(() => window.softshell.state.connection === 'live'), { what: 'events' });
    const at = await page.evaluate(() => {
      const c = document.getElementById('view');
      const r = c.getBoundingClientRect();
      for (let fy = 0.5; fy < 0.8; fy += 0.02) {
        const x = Math.round(0.5 * r.width), y = Math.round(fy * r.height);
        if (window.softshell.pickAt(x, y)?.hit) return { x: r.left + x, y: r.top + y };
      }
      return null;
    });
    await page.mouse.move(at.x, at.y);
    await page.mouse.down();
    for (let i = 1; i <= 120; ++i) {
      await page.mouse.move(at.x + 20 * Math.sin(i / 10), at.y - i * 0.4);
      await sleep(16);
    }
    await sleep(300);
    const times = await page.evaluate(() => window.softshell.state.moveToScreen.slice().sort((a, b) => a - b));
    const puts = await page.evaluate(() => window.softshell.state.latencies.slice().sort((a, b) => a - b));
    const frameMs = await page.evaluate(async () => {
      const v = window.softshell.view, t0 = performance.now(), f0 = v.frames;
      await new Promise((done) => { const spin = () => { v.camera.orbit(1, 0); v.dirty = true; if (performance.now() - t0 < 2000) requestAnimationFrame(spin); else done(); }; requestAnimationFrame(spin); });
      return (performance.now() - t0) / (v.frames - f0);
    });
    await page.mouse.up();
    await sleep(300);
    await page.close();
    const q = (p) => times[Math.min(times.length - 1, Math.floor(p * times.length))];
    rows.push({
      mesh: name, control_points: V, precompute_s: precompute.toFixed(1),
      level3_triangles: triangles3, fps_level3: fps.toFixed(1), update_ms_level3: update.toFixed(1),
      bytes_update_binary: 4 + 12 * V, bytes_update_event_json: eventJson.length,
      bytes_level2_triangulation: l2.vertices * 24, level2_vertices: l2.vertices,
      render_table_mb: `${(tableBytes[2] / 1e6).toFixed(2)} (L2), ${(tableBytes[3] / 1e6).toFixed(2)} (L3)`,
      put_ms: puts.length ? `p50 ${puts[Math.floor(puts.length / 2)].toFixed(1)}, p95 ${puts[Math.floor(0.95 * puts.length)].toFixed(1)}` : 'none',
      frame_ms_level2: frameMs.toFixed(1),
      move_to_screen_ms: times.length ? `p50 ${q(0.5).toFixed(1)}, p95 ${q(0.95).toFixed(1)} (${times.length} moves)` : 'none',
      console_errors: errors.length,
    });
  }
} finally {
  await browser.close();
  await server.stop();
}
for (const r of rows) console.log(JSON.stringify(r));
console.log('\n| mesh | control points | fps at level 3 (triangles) | page update at level 3 | bytes per update (binary / SSE JSON) | level-2 triangulation (positions + normals, f32) | pointer move to screen |');
console.log('| --- | --- | --- | --- | --- | --- | --- |');
for (const r of rows) {
  console.log(`| ${r.mesh} | ${r.control_points} | ${r.fps_level3} (${r.level3_triangles}) | ${r.update_ms_level3} ms | ${r.bytes_update_binary} / ${r.bytes_update_event_json} | ${r.bytes_level2_triangulation} (${r.level2_vertices} vertices) | ${r.move_to_screen_ms} ms |`);
}
