// A real tactile-server serving this folder, and a page of it in Debian's Chromium (playwright-core,
// SwiftShader): what the end-to-end tests and the render benchmark start.
import assert from 'node:assert/strict';
import { spawn } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

import { chromium } from 'playwright-core';

const here = path.dirname(fileURLToPath(import.meta.url));
export const root = path.resolve(here, '..', '..');
export const CHROMIUM = process.env.TACTILE_CHROMIUM || '/usr/bin/chromium';
export const SWIFTSHADER = ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist'];

export function serverExe(build = process.env.TACTILE_BUILD || 'build/release') {
  const exe = path.resolve(root, build, 'tactile-server');
  assert.ok(fs.existsSync(exe), `tactile-server is not built at ${exe} (scripts/setup.sh builds it)`);
  return exe;
}

// Starts tactile-server with `argv` (after the executable), serving this folder on a free port.
export async function spawnServer(argv, { build, timeoutMs = 120000 } = {}) {
  const proc = spawn(serverExe(build), [...argv, '--port', '0', '--static', path.join(root, 'client-web')], {
    stdio: ['ignore', 'pipe', 'pipe'],
  });
  let out = '';
  const port = await new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error(`the server did not start:\n${out}`)), timeoutMs);
    proc.stdout.on('data', (d) => {
      out += d;
      const m = /listening on http:\/\/127\.0\.0\.1:(\d+)\//.exec(out);
      if (m) {
        clearTimeout(timer);
        resolve(Number(m[1]));
      }
    });
    proc.stderr.on('data', (d) => {
      out += d;
    });
    proc.on('exit', (code) => reject(new Error(`the server exited (${code}):\n${out}`)));
  });
  proc.output = () => out;
  return { proc, port };
}

// Writes `scene` (an object) into a fresh folder and starts the server on it on a free port, with `args`.
export async function startServer(scene, args = [], options = {}) {
  const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'tactile-live-'));
  const scenePath = path.join(dir, `${scene.name}.json`);
  fs.writeFileSync(scenePath, JSON.stringify(scene));
  return spawnServer([scenePath, ...args], options);
}

// Debian's Chromium, drawing in software (SwiftShader).
export function launchBrowser() {
  return chromium.launch({ executablePath: CHROMIUM, args: SWIFTSHADER });
}

// A page of the server at `port` in a fresh context of `browser` (its own localStorage); `context` adds
// options of a browser context (hasTouch, isMobile, ...). `problems` collects console errors and page errors.
export async function openPageIn(
  browser,
  port,
  { query = '', viewport = { width: 800, height: 600 }, context = {} } = {},
) {
  const page = await browser.newPage({ viewport, ...context });
  const problems = [];
  page.on('console', (m) => {
    if (m.type() === 'error') problems.push(`console: ${m.text()}`);
  });
  page.on('pageerror', (e) => problems.push(`page: ${e.message}`));
  await page.goto(`http://127.0.0.1:${port}/${query}`);
  return { page, problems };
}

// A page of the server at `port` in Chromium; `problems` collects console errors and page errors.
export async function openPage(port, { query = '', viewport = { width: 800, height: 600 } } = {}) {
  const browser = await launchBrowser();
  const { page, problems } = await openPageIn(browser, port, { query, viewport });
  return { browser, page, problems };
}

// The server on `scene` and a page of it at `query` (e.g. '?token=...'); `problems` collects console errors
// and page errors. close() ends both.
export async function openLive(scene, { args = [], query = '', viewport = { width: 800, height: 600 } } = {}) {
  const { proc, port } = await startServer(scene, args);
  const { browser, page, problems } = await openPage(port, { query, viewport });
  return {
    port,
    page,
    problems,
    // What the page and the server show, for a test's failure message: the page's frame count and
    // status line, its console errors, and the end of the server's output.
    describe: async () => {
      const state = await page
        .evaluate(() => ({
          frames: window.tactile ? window.tactile.frames : null,
          status: document.querySelector('#status') ? document.querySelector('#status').textContent : null,
        }))
        .catch((e) => ({ error: e.message }));
      return (
        `page: ${JSON.stringify(state)}\nproblems: ${problems.join('; ') || 'none'}\n` +
        `server output (end):\n${proc.output().slice(-2000)}`
      );
    },
    close: async () => {
      await browser.close();
      proc.kill('SIGINT');
    },
  };
}
