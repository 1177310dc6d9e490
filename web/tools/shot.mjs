// Screenshot of a page: node tools/shot.mjs URL out.png [width height]
import { chromium } from 'playwright-core';
const [url, out, w = 900, h = 640] = process.argv.slice(2);
const browser = await chromium.launch({ executablePath: '/usr/bin/chromium', args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--no-sandbox', '--disable-background-networking', '--disable-component-update', '--disable-sync', '--no-first-run'] });
const page = await browser.newPage({ viewport: { width: Number(w), height: Number(h) } });
page.on('console', (m) => console.log('console', m.type(), m.text()));
page.on('pageerror', (e) => console.log('pageerror', e.message));
await page.goto(url);
await page.waitForFunction(() => !window.softshell || window.softshell.ready, null, { timeout: 30000 }).catch((e) => console.log(e.message));
await page.waitForTimeout(1500);
await page.screenshot({ path: out });
console.log(await page.evaluate(() => document.getElementById('status')?.textContent));
await browser.close();
