// node shoot.mjs FILE CAMERA.json OUT.png
// Serves this folder and FILE on 127.0.0.1, renders FILE with page/index.html in headless
// Chromium (software WebGL) from the camera in CAMERA.json, and screenshots the canvas.
import http from 'node:http';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const root = path.dirname(fileURLToPath(import.meta.url));
const [file, cameraJson, out] = process.argv.slice(2);
const types = { '.html': 'text/html', '.js': 'text/javascript' };
const server = http.createServer((req, res) => {
  const url = decodeURIComponent(req.url.split('?')[0]);
  const p = url.startsWith('/data/') ? file : path.join(root, path.normalize(url));
  fs.readFile(p, (err, data) => {
    if (err) { res.writeHead(404); res.end(); return; }
    res.writeHead(200, { 'content-type': types[path.extname(p)] || 'application/octet-stream' });
    res.end(data);
  });
});
await new Promise((ok) => server.listen(0, '127.0.0.1', ok));
const port = server.address().port;
const cam = JSON.parse(fs.readFileSync(cameraJson, 'utf8'));
cam.ext = path.extname(file);
cam.url = `http://127.0.0.1:${port}/data/scene${cam.ext}`;
// Flags of a closed network: no background fetches, no first-run, software GL.
const browser = await chromium.launch({
  executablePath: process.env.COCOG_CHROMIUM || '/usr/bin/chromium',
  args: ['--no-sandbox', '--disable-gpu', '--use-gl=swiftshader', '--enable-unsafe-swiftshader',
    '--ignore-gpu-blocklist', '--disable-background-networking', '--disable-component-update',
    '--disable-sync', '--no-first-run', '--disable-quic'],
});
try {
  const page = await browser.newPage({ viewport: { width: cam.width, height: cam.height } });
  const logs = [];
  page.on('console', (m) => logs.push(m.text()));
  await page.goto(`http://127.0.0.1:${port}/page/index.html#${encodeURIComponent(JSON.stringify(cam))}`);
  await page.waitForFunction(() => window.__done, null, { timeout: 120000 });
  const done = await page.evaluate(() => window.__done);
  if (done !== 'ok') { throw new Error(`${done}\n${logs.join('\n')}`); }
  await page.locator('canvas').screenshot({ path: out });
} finally {
  await browser.close();
  server.close();
}
