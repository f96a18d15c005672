// Static HTTP server for the viewer (docs/viewer.md): / -> this folder (the page and its
// node_modules), /export/ -> the export folder, /job/ -> a folder with scene.json (and queries for
// the GLSL round trip). Usage: node server.mjs --export DIR [--job DIR] [--port P] [--host H]
import http from 'node:http';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const types = { '.html': 'text/html', '.js': 'text/javascript', '.mjs': 'text/javascript', '.json': 'application/json',
                '.glsl': 'text/plain', '.css': 'text/css', '.png': 'image/png' };

export function startServer({ exportDir, jobDir = null, port = 0, host = '127.0.0.1' }) {
  const roots = [['/export/', exportDir], ['/job/', jobDir], ['/', here]];
  const server = http.createServer((req, res) => {
    const url = decodeURIComponent(new URL(req.url, 'http://x').pathname);
    for (const [prefix, dir] of roots) {
      if (!dir || !url.startsWith(prefix)) continue;
      const rel = url.slice(prefix.length) || 'index.html';
      const file = path.resolve(dir, rel);
      if (file !== path.resolve(dir) && !file.startsWith(path.resolve(dir) + path.sep)) break;  // no escape
      fs.readFile(file, (err, data) => {
        if (err) { res.writeHead(404); res.end('not found'); return; }
        res.writeHead(200, { 'Content-Type': types[path.extname(file)] || 'application/octet-stream',
                             'Cache-Control': 'no-store' });
        res.end(data);
      });
      return;
    }
    res.writeHead(404); res.end('not found');
  });
  return new Promise((resolve, reject) => {
    server.once('error', reject);
    server.listen(port, host, () => resolve({ server, url: `http://${host}:${server.address().port}/` }));
  });
}

export function parseArgs(argv) {
  const a = {};
  for (let i = 0; i < argv.length; ++i) {
    if (!argv[i].startsWith('--')) throw new Error(`unexpected argument '${argv[i]}'`);
    a[argv[i].slice(2)] = argv[i + 1];
    ++i;
  }
  return a;
}

if (process.argv[1] && path.resolve(process.argv[1]) === fileURLToPath(import.meta.url)) {
  const a = parseArgs(process.argv.slice(2));
  if (!a.export) { console.error('usage: node server.mjs --export DIR [--job DIR] [--port P] [--host H]'); process.exit(2); }
  startServer({ exportDir: a.export, jobDir: a.job || null, port: Number(a.port || 0), host: a.host || '127.0.0.1' })
    .then(({ url }) => console.log(`${url}index.html${a.job ? '?job=1' : ''}`))
    .catch((e) => { console.error(`cannot serve: ${e.message}`); process.exit(4); });
}
