// Static HTTP server for the viewer (docs/viewer.md): / -> the page's own files (an allow-list: the
// page, its script and the three.js modules it imports), /export/ -> the export folder, /job/ -> a
// folder with scene.json (and queries for the GLSL round trip).
// Usage: node server.mjs --export DIR [--job DIR] [--port P] [--host H]
//
// Any web page the user visits can send requests to it, so it trusts none: a malformed URL gets
// 400, a Host header other than this server's own name gets 403 (DNS rebinding), only GET and HEAD
// are answered, files are served only from inside their folder after symbolic links are resolved,
// only regular files, streamed (memory stays flat however many requests come at once), with
// nosniff and a Content-Security-Policy. It binds 127.0.0.1 unless --host says otherwise.
import http from 'node:http';
import fs from 'node:fs';
import path from 'node:path';
import crypto from 'node:crypto';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const types = { '.html': 'text/html; charset=utf-8', '.js': 'text/javascript', '.mjs': 'text/javascript',
                '.json': 'application/json', '.glsl': 'text/plain; charset=utf-8', '.css': 'text/css',
                '.png': 'image/png', '.bin': 'application/octet-stream', '.f32': 'application/octet-stream' };
// The page's files under /: what index.html and viewer.js load (the same list btf-eval sweep
// copies beside its report, libbtf/eval/sweep.cpp kViewerFiles).
export const pageFiles = new Set(['index.html', 'viewer.js', 'node_modules/three/LICENSE',
                                  'node_modules/three/build/three.module.js', 'node_modules/three/build/three.core.js',
                                  'node_modules/three/examples/jsm/controls/OrbitControls.js']);

// CSP: scripts and styles from this server, plus the page's inline import map and style sheet by
// their hashes (read from index.html at start).
function contentSecurityPolicy() {
  const html = fs.readFileSync(path.join(here, 'index.html'), 'utf8');
  const hashes = (tag) => [...html.matchAll(new RegExp(`<${tag}(?![^>]*\\bsrc=)[^>]*>([\\s\\S]*?)</${tag}>`, 'g'))]
    .map((m) => `'sha256-${crypto.createHash('sha256').update(m[1]).digest('base64')}'`).join(' ');
  return [`default-src 'self'`, `script-src 'self' ${hashes('script')}`, `style-src 'self' ${hashes('style')}`,
          `img-src 'self' data: blob:`, `object-src 'none'`, `base-uri 'none'`, `frame-ancestors 'self'`,
          `form-action 'none'`].join('; ');
}

function fail(res, status, text) {
  res.writeHead(status, { 'Content-Type': 'text/plain; charset=utf-8', 'X-Content-Type-Options': 'nosniff' });
  res.end(`${text}\n`);
}

// The file to serve for a decoded path, or null: inside `dir` after symbolic links are resolved,
// and a regular file.
async function resolveInside(dir, rel) {
  try {
    const root = await fs.promises.realpath(dir);
    const file = await fs.promises.realpath(path.resolve(root, rel));
    if (!file.startsWith(root + path.sep)) return null;
    const st = await fs.promises.stat(file);
    return st.isFile() ? { file, size: st.size } : null;
  } catch {
    return null;
  }
}

export function startServer({ exportDir, jobDir = null, port = 0, host = '127.0.0.1' }) {
  const roots = [['/export/', exportDir], ['/job/', jobDir], ['/', here]];
  const csp = contentSecurityPolicy();
  let hosts = new Set();
  const server = http.createServer(async (req, res) => {
    try {
      if (!hosts.has((req.headers.host || '').toLowerCase())) return fail(res, 403, 'forbidden: unknown Host');
      if (req.method !== 'GET' && req.method !== 'HEAD') return fail(res, 405, 'method not allowed');
      let url;
      try {
        url = decodeURIComponent(new URL(req.url, 'http://x').pathname);
      } catch {
        return fail(res, 400, 'bad request: malformed URL');
      }
      if (url.includes('\0') || url.includes('\\')) return fail(res, 400, 'bad request');
      for (const [prefix, dir] of roots) {
        if (!dir || !url.startsWith(prefix)) continue;
        const rel = url.slice(prefix.length) || 'index.html';
        if (prefix === '/' && !pageFiles.has(rel)) break;
        const found = await resolveInside(dir, rel);
        if (!found) break;
        res.writeHead(200, { 'Content-Type': types[path.extname(found.file)] || 'application/octet-stream',
                             'Content-Length': found.size, 'Cache-Control': 'no-store',
                             'X-Content-Type-Options': 'nosniff', 'Content-Security-Policy': csp,
                             'Referrer-Policy': 'no-referrer', 'Cross-Origin-Resource-Policy': 'same-origin' });
        if (req.method === 'HEAD') return res.end();
        const stream = fs.createReadStream(found.file);
        stream.on('error', () => res.destroy());
        stream.pipe(res);
        return;
      }
      fail(res, 404, 'not found');
    } catch {
      if (!res.headersSent) fail(res, 500, 'internal error');
      else res.destroy();
    }
  });
  server.on('clientError', (err, socket) => socket.destroy());
  return new Promise((resolve, reject) => {
    server.once('error', reject);
    server.listen(port, host, () => {
      const p = server.address().port;
      hosts = new Set([`${host}:${p}`, `127.0.0.1:${p}`, `localhost:${p}`, `[::1]:${p}`].map((h) => h.toLowerCase()));
      resolve({ server, url: `http://${host}:${p}/` });
    });
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
