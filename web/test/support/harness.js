// Test support: a softshell-server on an ephemeral port (the executable from SOFTSHELL_SERVER, as
// ctest passes it, else the build tree's), meshes, the SDK probe and headless Chromium.
import { spawn, execFileSync } from 'node:child_process';
import { existsSync, readFileSync, mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';
import { parseObj } from '../../src/client.js';

const here = dirname(fileURLToPath(import.meta.url));
export const repo = join(here, '..', '..', '..');
const build = process.env.SOFTSHELL_BUILD_DIR ?? join(repo, 'build');
export const serverExe = process.env.SOFTSHELL_SERVER ?? join(build, 'server/app/softshell-server');
export const probeExe = process.env.SOFTSHELL_SDK_PROBE ?? join(build, 'tests/browser/softshell_sdk_probe');

/** Starts softshell-server on 127.0.0.1:0; resolves to {url, stop()} once it listens. */
export function startServer(extraArgs = []) {
  if (!existsSync(serverExe)) throw new Error(`no softshell-server at ${serverExe} (build it, or set SOFTSHELL_SERVER)`);
  const proc = spawn(serverExe, ['--host', '127.0.0.1', '--port', '0', '--threads', '1', '--log-level', 'warning', ...extraArgs],
    { stdio: ['ignore', 'pipe', 'pipe'] });
  let stderr = '';
  proc.stderr.on('data', (d) => { stderr += d; });
  return new Promise((resolve, reject) => {
    let out = '';
    const timer = setTimeout(() => reject(new Error(`softshell-server did not start: ${stderr}`)), 20000);
    proc.on('exit', (code) => { clearTimeout(timer); reject(new Error(`softshell-server exited (${code}): ${stderr}`)); });
    proc.stdout.on('data', (d) => {
      out += d;
      const m = /listening on (http:\/\/\S+)/.exec(out);
      if (!m) return;
      clearTimeout(timer);
      proc.removeAllListeners('exit');
      resolve({
        url: m[1],
        proc,
        stderr: () => stderr,
        stop: () => new Promise((done) => {
          if (proc.exitCode !== null) return done();
          proc.on('exit', () => done());
          proc.kill('SIGTERM');
        }),
      });
    });
  });
}

/** E, nu, t exact in f32 (binary and JSON uploads carry the same values). */
export const exactMaterial = { youngs_modulus: 1.0e6, poisson_ratio: 0.25, thickness: 0.015625 };

/** An n x n grid of quads over [0, 1]^2 at z = 0 (coordinates exact in f32 for n a power of two). */
export function grid(n = 4) {
  const vertices = [], faces = [];
  for (let j = 0; j <= n; ++j) for (let i = 0; i <= n; ++i) vertices.push([i / n, j / n, 0]);
  for (let j = 0; j < n; ++j) for (let i = 0; i < n; ++i) {
    const a = j * (n + 1) + i;
    faces.push([a, a + 1, a + n + 2, a + n + 1]);
  }
  return { vertices, faces, material: exactMaterial };
}

/** A mesh of assets/meshes with a material. */
export function assetMesh(name, material = { youngs_modulus: 6.9e10, poisson_ratio: 0.33, thickness: 0.001 }) {
  return { ...parseObj(readFileSync(join(repo, 'assets/meshes', name), 'utf8')), material };
}

/** The SDK's answers (tests/browser/sdk_probe.cpp): {size, vertices, picks}. */
export function sdkProbe(input) {
  if (!existsSync(probeExe)) throw new Error(`no softshell_sdk_probe at ${probeExe} (build it, or set SOFTSHELL_SDK_PROBE)`);
  return JSON.parse(execFileSync(probeExe, { input: JSON.stringify(input), maxBuffer: 1 << 28 }).toString());
}

/** Headless Chromium (Debian's, through playwright-core) with WebGL on SwiftShader. */
export async function launchChromium() {
  const { chromium } = await import('playwright-core');
  const profile = mkdtempSync(join(tmpdir(), 'softshell-chromium-'));
  const executablePath = process.env.SOFTSHELL_CHROMIUM ?? '/usr/bin/chromium';
  // A persistent context is the only way to give a fresh --user-data-dir; pages share it.
  const context = await chromium.launchPersistentContext(profile, {
    executablePath,
    headless: true,
    viewport: { width: 640, height: 480 },
    args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist',
      '--disable-background-networking', '--disable-component-update', '--disable-sync', '--no-first-run',
      '--disable-default-apps', '--disable-quic'],
  });
  return { context, close: async () => { await context.close(); rmSync(profile, { recursive: true, force: true }); } };
}

/**
 * A page of the app with its console errors collected: `errors` (console.error and uncaught
 * exceptions), `openView(url)`.
 */
export async function appPage(context) {
  const page = await context.newPage();
  const errors = [];
  page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  page.on('pageerror', (e) => errors.push(String(e)));
  return { page, errors };
}

/** Waits until the view page reports ready (render table loaded, first frame drawn). */
export async function waitReady(page, timeout = 30000) {
  await page.waitForFunction(() => window.softshell?.ready && window.softshell.view.frames > 0, null, { timeout });
}

/**
 * Canvas pixels in the page: {width, height, nonBackground (fraction of pixels that differ
 * from the clear colour), hash (a checksum of all pixels)}.
 */
export async function canvasPixels(page) {
  return page.evaluate(() => {
    const c = document.getElementById('view');
    const w = c.width, h = c.height;
    const tmp = document.createElement('canvas');
    tmp.width = w; tmp.height = h;
    const ctx = tmp.getContext('2d');
    ctx.drawImage(c, 0, 0);
    const d = ctx.getImageData(0, 0, w, h).data;
    let other = 0, hash = 0;
    const bg = [d[0], d[1], d[2]];
    for (let i = 0; i < d.length; i += 4) {
      if (Math.abs(d[i] - bg[0]) + Math.abs(d[i + 1] - bg[1]) + Math.abs(d[i + 2] - bg[2]) > 12) other++;
      hash = (hash * 31 + d[i] * 7 + d[i + 1] * 3 + d[i + 2]) >>> 0;
    }
    return { width: w, height: h, nonBackground: other / (w * h), hash, background: bg };
  });
}

/** Fraction of pixels that differ between two RGBA snapshots taken with `snapshot`. */
export async function snapshot(page) {
  return page.evaluate(() => {
    const c = document.getElementById('view');
    const tmp = document.createElement('canvas');
    tmp.width = c.width; tmp.height = c.height;
    tmp.getContext('2d').drawImage(c, 0, 0);
    return Array.from(tmp.getContext('2d').getImageData(0, 0, c.width, c.height).data);
  });
}
export function pixelDifference(a, b) {
  let n = 0;
  for (let i = 0; i < a.length; i += 4) {
    if (Math.abs(a[i] - b[i]) + Math.abs(a[i + 1] - b[i + 1]) + Math.abs(a[i + 2] - b[i + 2]) > 24) n++;
  }
  return n / (a.length / 4);
}

export const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

/** Polls `fn` until it returns a truthy value (or throws after `timeout` ms). */
export async function until(fn, { timeout = 10000, interval = 20, what = 'condition' } = {}) {
  const end = Date.now() + timeout;
  for (;;) {
    const v = await fn();
    if (v) return v;
    if (Date.now() > end) throw new Error(`timed out waiting for ${what}`);
    await sleep(interval);
  }
}
