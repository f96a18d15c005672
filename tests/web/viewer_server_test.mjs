// The viewer's HTTP server under hostile requests (viewer/server.mjs; docs/viewer.md, "Server").
// Run by ctest `web/ViewerServer` (node tests/web/viewer_server_test.mjs); exits 1 on a failure.
import assert from 'node:assert/strict';
import fs from 'node:fs';
import http from 'node:http';
import os from 'node:os';
import path from 'node:path';
import test from 'node:test';
import { fileURLToPath } from 'node:url';

const viewer = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../../viewer');
const { startServer } = await import(path.join(viewer, 'server.mjs'));

// A raw request (no URL normalisation by a client library): status, headers and body length.
function request(port, target, { host = `127.0.0.1:${port}`, method = 'GET' } = {}) {
  return new Promise((resolve, reject) => {
    const req = http.request({ host: '127.0.0.1', port, path: target, method, headers: { Host: host } }, (res) => {
      let bytes = 0;
      res.on('data', (c) => { bytes += c.length; });
      res.on('end', () => resolve({ status: res.statusCode, headers: res.headers, bytes }));
    });
    req.on('error', reject);
    req.end();
  });
}

const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'viewer-server-'));
const exportDir = path.join(dir, 'export');
fs.mkdirSync(exportDir);
fs.writeFileSync(path.join(exportDir, 'manifest.json'), '{"format":"test"}');
fs.writeFileSync(path.join(dir, 'secret.txt'), 'outside the export folder');
fs.symlinkSync(path.join(dir, 'secret.txt'), path.join(exportDir, 'link.txt'));
const big = Buffer.alloc(20 << 20, 7);
fs.writeFileSync(path.join(exportDir, 'big.bin'), big);
const { server, url } = await startServer({ exportDir });
const port = Number(new URL(url).port);

test.after(() => { server.close(); fs.rmSync(dir, { recursive: true, force: true }); });

test('serves the export and the page with nosniff and a CSP', async () => {
  const m = await request(port, '/export/manifest.json');
  assert.equal(m.status, 200);
  assert.equal(m.headers['x-content-type-options'], 'nosniff');
  assert.match(m.headers['content-security-policy'], /default-src 'self'/);
  assert.match(m.headers['content-security-policy'], /script-src 'self' 'sha256-/);  // the inline import map
  assert.equal((await request(port, '/')).status, 200);
  assert.equal((await request(port, '/viewer.js')).status, 200);
});

test('malformed URLs get 400 and the server keeps serving', async () => {
  for (const bad of ['/%', '/export/manifest.json%00', '/%E0%A4%A', '/export/%5c..%5csecret.txt'])
    assert.equal((await request(port, bad)).status, 400, bad);
  assert.equal((await request(port, '/export/manifest.json')).status, 200);
});

test('no way out of the folders: dot-dot in any encoding, symbolic links, the rest of viewer/', async () => {
  for (const p of ['/export/../secret.txt', '/export/%2e%2e/secret.txt', '/export/..%2fsecret.txt',
                   '/export/%2e%2e%2f%2e%2e%2fetc/passwd', '/export/link.txt', '/package.json', '/server.mjs',
                   '/node_modules/playwright-core/package.json', '/job/scene.json', '/export/'])
    assert.equal((await request(port, p)).status, 404, p);
});

test('a foreign Host header (DNS rebinding) gets 403; other methods 405', async () => {
  assert.equal((await request(port, '/export/manifest.json', { host: 'evil.example:80' })).status, 403);
  assert.equal((await request(port, '/export/manifest.json', { host: `localhost:${port}` })).status, 200);
  assert.equal((await request(port, '/export/manifest.json', { method: 'POST' })).status, 405);
});

test('40 parallel requests of a 20 MB file stream without holding it 40 times', async () => {
  const before = process.memoryUsage().rss;
  const all = await Promise.all(Array.from({ length: 40 }, () => request(port, '/export/big.bin')));
  for (const r of all) assert.equal(r.bytes, big.length);
  const grown = (process.memoryUsage().rss - before) / (1 << 20);
  // Read whole into memory, 40 copies would be 800 MB (measured before streaming: 810 MB).
  assert.ok(grown < 200, `rss grew by ${grown.toFixed(0)} MB`);
});
