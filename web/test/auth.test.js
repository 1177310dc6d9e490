// A server started with --auth-token-file: the client module with and without the token (requests
// and event streams, which go over fetch with the Authorization header), and the web app, which
// takes the token from its URL fragment (#token=...), keeps it in sessionStorage and takes it out
// of the address bar. The app part needs web/node_modules (playwright-core) and Chromium.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { mkdtempSync, writeFileSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { ApiError, Client } from '../src/client.js';
import { appPage, grid, launchChromium, startServer, until, waitReady } from './support/harness.js';

const TOKEN = 'web-token-0123456789abcdef';
let server, dir, client, id;

const pinnedPush = (k) => ({
  vertex_constraints: [0, 4, 20, 24].map((index) => ({ index, mask: 7, displacement: [0, 0, 0] })),
  forces: [{ index: 12, force: [0, 0, -0.25 * k] }],
});

before(async () => {
  dir = mkdtempSync(join(tmpdir(), 'softshell-auth-'));
  const file = join(dir, 'token');
  writeFileSync(file, TOKEN + '\n', { mode: 0o600 });
  server = await startServer(['--auth-token-file', file]);
  client = new Client(server.url, { token: TOKEN });
  ({ geom_id: id } = await client.upload(grid(4)));
  await client.waitReady(id);
});
after(async () => {
  await server?.stop();
  if (dir) rmSync(dir, { recursive: true, force: true });
});

test('without the token: 401 with the challenge; with it: served', async () => {
  const anonymous = new Client(server.url);
  await assert.rejects(anonymous.geometries(), (e) => e instanceof ApiError && e.status === 401 && e.code === 'unauthenticated' && /Authorization: Bearer/.test(e.message));
  const wrong = new Client(server.url, { token: 'not-the-token-0123456789' });
  await assert.rejects(wrong.status(id), (e) => e instanceof ApiError && e.status === 401);
  const raw = await fetch(`${server.url}/geometries`);
  assert.equal(raw.status, 401);
  assert.equal(raw.headers.get('www-authenticate'), 'Bearer realm="softshell"');
  assert.equal((await fetch(`${server.url}/health`)).status, 200);
  assert.equal((await fetch(`${server.url}/`)).status, 200);
  assert.equal((await client.geometries()).length, 1);
});

test('event streams: followed with the token over fetch, closed at once without it', async () => {
  const got = [];
  const sub = client.events(id, { onResult: (r) => got.push(r.res_id), retryMs: 50 });
  try {
    const { res_id } = await client.deform(id, pinnedPush(1));
    await until(() => got.includes(res_id), { what: 'the result event', timeout: 20000 });
  } finally {
    sub.close();
  }
  const states = [];
  const denied = new Client(server.url).events(id, { onState: (s, e) => states.push([s, e]), retryMs: 50 });
  await until(() => states.some(([s]) => s === 'closed'), { what: 'the refused stream to close' });
  denied.close();
  const [, err] = states.find(([s]) => s === 'closed');
  assert.ok(err instanceof ApiError && err.status === 401, String(err));
  assert.ok(!states.some(([s]) => s === 'reconnecting'), 'a 401 is not retried');
});

let playwright = true;
try { await import('playwright-core'); } catch { playwright = false; }

test('the web app takes the token from #token=, keeps it for the tab and hides it', { skip: !playwright && 'no playwright-core (npm ci in web/)' }, async () => {
  const browser = await launchChromium();
  try {
    // Without the token the list page says what to do.
    const p = await appPage(browser.context);
    await p.page.goto(`${server.url}/`);
    await until(() => p.page.evaluate(() => document.getElementById('upload-error')?.textContent ?? ''), { what: 'the error' });
    const shown = await p.page.evaluate(() => document.getElementById('upload-error').textContent);
    assert.match(shown, /401/);
    assert.match(shown, /#token=/);

    // With it: the view renders, follows the event stream, and the address bar has no token.
    await p.page.goto(`${server.url}/?geometry=${id}&level=1#token=${TOKEN}`);
    await waitReady(p.page);
    await until(() => p.page.evaluate(() => window.softshell.state.connection === 'live'), { what: 'the event stream' });
    assert.equal(await p.page.evaluate(() => location.hash), '');
    assert.equal(await p.page.evaluate(() => sessionStorage.getItem('softshell.token')), TOKEN);

    // The same tab, a link without the fragment: the token is still sent.
    await p.page.goto(`${server.url}/`);
    await until(() => p.page.evaluate(() => document.querySelectorAll('#geometries tbody a').length === 1), { what: 'the geometry list' });
    assert.equal(await p.page.evaluate(() => document.getElementById('upload-error').textContent), '');
    await p.page.close();
  } finally {
    await browser.close();
  }
});
