// penumbra's output in the clients users load it with.
//
//  1. Bake every fixtures/*.glb with the release binary.
//  2. Khronos glTF validator on every baked file: zero errors and zero warnings (infos are fine,
//     e.g. the validator does not know MOZ_lightmap).
//  3. three.js in headless Chromium draws every baked file from a fixed camera (the file's own,
//     or one this script adds) with GLTFLoader, the MOZ_lightmap plugin and Lambert materials.
//     Its screenshot must match `penumbra render` of the same file and camera (mean absolute
//     difference in linear RGB below MAD_TOLERANCE), and must differ from three.js's picture
//     of the same file with the lightmap removed (MAD at least APPLIED_MIN_MAD).
//  4. Self-tests: broken files must be caught (TEXCOORD_0 dropped: the validator reports an
//     error; MOZ_lightmap.texCoord wrong: the three.js comparison fails; MOZ_lightmap removed:
//     the "lightmap applied" check fails; the default (sRGB-encoded) lightmap decoded as linear,
//     or a `--encoding linear` lightmap decoded as sRGB: the comparison fails).
//  Besides the fixtures as they are, two variants go through 2-3: cornell-box baked with
//  `--encoding linear`, and box-on-floor baked onto several small pages (`--texels-per-unit`,
//  `--page-size`).
//
// Usage: node run.mjs [--only NAME,...] [--update-screenshot]
//   PENUMBRA_BIN   the penumbra binary (default: <target>/release/penumbra, where <target> is
//                  $CARGO_TARGET_DIR or <repo>/target)
//   CHROMIUM       the Chromium binary (default: chromium or chromium-browser on PATH)
//   CI=true        a missing Chromium fails the run instead of skipping the three.js checks
// Pictures and baked files go to <target>/clients/.
// The last line is `N passed, N failed[, N skipped]`; the exit code is 1 when anything failed.

import { spawnSync } from 'node:child_process';
import fs from 'node:fs';
import http from 'node:http';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { PNG } from 'pngjs';
import * as validator from 'gltf-validator';
import { addCamera, breakages, editGlb, hasCamera, readGlb } from './glb.mjs';

const HERE = path.dirname(fileURLToPath(import.meta.url));
const ROOT = path.resolve(HERE, '../..');
const TARGET = process.env.CARGO_TARGET_DIR ? path.resolve(ROOT, process.env.CARGO_TARGET_DIR) : path.join(ROOT, 'target');
const OUT = path.join(TARGET, 'clients');
const SIZE = 512; // pixels, width and height, for both renderers

/** Largest mean absolute difference (linear RGB, 0..1) between three.js and `penumbra render`. */
const MAD_TOLERANCE = 0.005;
/** Smallest mean absolute difference between three.js with and without the lightmap. */
const APPLIED_MIN_MAD = 0.02;

/**
 * The fixed camera for fixtures that have none: eye, target, vertical field of view (rad).
 * Below the emitters, so that single-sided emitters face the camera (three.js culls back
 * faces, `penumbra render` does not). `exposure` (radiance shown as white) where the default
 * (see exposureOf) does not fit: the furnace's own emission alone would be white.
 */
const VIEWS = {
  'box-on-floor': { eye: [2.4, 1.6, 3.0], target: [0, 0.3, 0], yfov: 0.9 },
  'box-on-floor-pages': { eye: [2.4, 1.6, 3.0], target: [0, 0.3, 0], yfov: 0.9 },
  'directional-light': { eye: [1.6, 1.2, 2.0], target: [0.1, 0, 0], yfov: 0.9 },
  'furnace-box': { eye: [0.35, 0.3, 0.4], target: [-0.2, -0.15, -0.5], yfov: 1.2, exposure: 0.8 },
  instanced: { eye: [1.5, 1.9, 2.2], target: [0, 0.6, 0], yfov: 0.9 },
  'plane-uniform': { eye: [1.2, 1.0, 1.6], target: [0, 0, 0], yfov: 0.9 },
  'point-light': { eye: [1.8, 1.4, 2.4], target: [0, 0, 0], yfov: 0.9 },
  'spot-light': { eye: [1.6, 1.2, 2.0], target: [0.1, 0, 0], yfov: 0.9 },
  'square-occluder': { eye: [3.0, 1.5, 4.0], target: [0, 0.5, 0], yfov: 0.9 },
};
const DEFAULT_VIEW = { eye: [2.4, 1.6, 3.2], target: [0, 0.3, 0], yfov: 0.9 };

const CHROMIUM_ARGS = [
  '--headless', '--no-sandbox', '--disable-gpu', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
  '--disable-quic', '--no-first-run', '--disable-background-networking', '--disable-component-update', '--disable-sync',
];

// ---------------------------------------------------------------------------------------------
// Reporting

const counts = { passed: 0, failed: 0, skipped: 0 };
const results = [];
function check(name, ok, detail) {
  counts[ok ? 'passed' : 'failed']++;
  results.push({ name, result: ok ? 'passed' : 'failed', detail });
  console.log(`${ok ? 'ok  ' : 'FAIL'} ${name}: ${detail}`);
}
function skip(name, why) {
  counts.skipped++;
  results.push({ name, result: 'skipped', detail: why });
  console.log(`skip ${name}: ${why}`);
}
function finish() {
  if (fs.existsSync(OUT)) fs.writeFileSync(path.join(OUT, 'summary.json'), JSON.stringify({ counts, results }, null, 1));
  const skipped = counts.skipped ? `, ${counts.skipped} skipped` : '';
  console.log(`\nclient checks: pictures and baked files in ${path.relative(process.cwd(), OUT) || '.'}`);
  console.log(`${counts.passed} passed, ${counts.failed} failed${skipped}`);
  process.exit(counts.failed ? 1 : 0);
}

// ---------------------------------------------------------------------------------------------
// penumbra

const PENUMBRA = process.env.PENUMBRA_BIN || path.join(TARGET, 'release', 'penumbra');

function penumbra(args) {
  const r = spawnSync(PENUMBRA, args, { encoding: 'utf8', maxBuffer: 64 << 20 });
  if (r.error) throw r.error;
  if (r.status !== 0) throw new Error(`penumbra ${args.join(' ')}: exit ${r.status}\n${r.stderr}`);
  return r.stdout;
}

/**
 * Radiance shown as white: 0.8 x the brightest albedo/pi x H a lightmapped material can reach
 * (emitters then show white, the rest is not clipped), or the exposure stored in the file's
 * `asset.extras.clientCheckExposure` by this script.
 */
function exposureOf(json) {
  const stored = json.asset?.extras?.clientCheckExposure;
  if (typeof stored === 'number') return stored;
  let top = 0;
  for (const m of json.materials ?? []) {
    const lm = m.extensions?.MOZ_lightmap;
    if (!lm) continue;
    const albedo = Math.max(...(m.pbrMetallicRoughness?.baseColorFactor ?? [1, 1, 1]).slice(0, 3));
    top = Math.max(top, (albedo / Math.PI) * (lm.intensity ?? 1));
  }
  return top > 0 ? 0.8 * top : 1;
}

// ---------------------------------------------------------------------------------------------
// Images

const SRGB_TO_LINEAR = Float64Array.from({ length: 256 }, (_, i) => {
  const c = i / 255;
  return c <= 0.04045 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4;
});

const readPng = (file) => PNG.sync.read(fs.readFileSync(file));

/** Mean absolute difference in linear RGB (0..1) over every pixel and channel. */
function meanAbsDiff(a, b) {
  if (a.width !== b.width || a.height !== b.height) {
    throw new Error(`image sizes differ: ${a.width}x${a.height} and ${b.width}x${b.height}`);
  }
  let sum = 0;
  for (let i = 0; i < a.data.length; i += 4) {
    for (let c = 0; c < 3; c++) sum += Math.abs(SRGB_TO_LINEAR[a.data[i + c]] - SRGB_TO_LINEAR[b.data[i + c]]);
  }
  return sum / ((a.data.length / 4) * 3);
}

/** Mean linear RGB value of an image. */
function meanLinear(img) {
  let sum = 0;
  for (let i = 0; i < img.data.length; i += 4) {
    for (let c = 0; c < 3; c++) sum += SRGB_TO_LINEAR[img.data[i + c]];
  }
  return sum / ((img.data.length / 4) * 3);
}

/** |a - b| x 4 per channel, as a picture for a person. */
function writeDiff(a, b, file) {
  const d = new PNG({ width: a.width, height: a.height });
  for (let i = 0; i < a.data.length; i += 4) {
    for (let c = 0; c < 3; c++) d.data[i + c] = Math.min(255, 4 * Math.abs(a.data[i + c] - b.data[i + c]));
    d.data[i + 3] = 255;
  }
  fs.writeFileSync(file, PNG.sync.write(d));
}

// ---------------------------------------------------------------------------------------------
// The page server (127.0.0.1 only) and the browser

const MIME = { '.html': 'text/html', '.mjs': 'text/javascript', '.js': 'text/javascript', '.glb': 'model/gltf-binary', '.png': 'image/png', '.json': 'application/json' };

function serve() {
  const roots = {
    page: path.join(HERE, 'page'),
    three: path.join(HERE, 'node_modules', 'three'),
    out: OUT,
  };
  const server = http.createServer((req, res) => {
    const url = new URL(req.url, 'http://127.0.0.1');
    const [, top, ...rest] = decodeURIComponent(url.pathname).split('/');
    const root = roots[top];
    const file = root && path.resolve(root, rest.join('/'));
    if (!file || !file.startsWith(root + path.sep) || !fs.existsSync(file) || !fs.statSync(file).isFile()) {
      res.writeHead(404).end('not found');
      return;
    }
    res.writeHead(200, { 'content-type': MIME[path.extname(file)] ?? 'application/octet-stream', 'cache-control': 'no-store' });
    fs.createReadStream(file).pipe(res);
  });
  return new Promise((resolve) => server.listen(0, '127.0.0.1', () => resolve(server)));
}

/** `promise`, or an error naming `what` after `ms` milliseconds. */
function withTimeout(ms, what, promise) {
  let timer;
  const late = new Promise((_, reject) => { timer = setTimeout(() => reject(new Error(`${what}: no answer in ${ms / 1000} s`)), ms); });
  return Promise.race([promise, late]).finally(() => clearTimeout(timer));
}

function findChromium() {
  if (process.env.CHROMIUM) return process.env.CHROMIUM;
  for (const name of ['chromium', 'chromium-browser']) {
    const r = spawnSync('sh', ['-c', `command -v ${name}`], { encoding: 'utf8' });
    if (r.status === 0 && r.stdout.trim()) return r.stdout.trim();
  }
  return null;
}

class Browser {
  static async open(executablePath) {
    const { chromium } = await import('playwright-core');
    const b = new Browser();
    b.server = await serve();
    b.base = `http://127.0.0.1:${b.server.address().port}`;
    b.profile = fs.mkdtempSync(path.join(os.tmpdir(), 'penumbra-chromium-'));
    b.context = await chromium.launchPersistentContext(b.profile, {
      executablePath,
      headless: true,
      args: CHROMIUM_ARGS,
      viewport: { width: SIZE, height: SIZE },
      deviceScaleFactor: 1,
      timeout: 60_000,
    });
    // Nothing leaves this machine: every request other than to our server is refused.
    await b.context.route((url) => !url.href.startsWith(b.base + '/'), (route) => route.abort());
    b.page = b.context.pages()[0] ?? (await b.context.newPage());
    b.messages = [];
    b.page.on('console', (m) => {
      // SwiftShader's "GPU stall due to ReadPixels" notes are not news.
      if ((m.type() === 'error' || m.type() === 'warning') && !m.text().includes('GL Driver Message')) {
        b.messages.push(`${m.type()}: ${m.text()}`);
      }
    });
    b.page.on('pageerror', (e) => b.messages.push(`page error: ${e.message}`));
    await b.page.goto(`${b.base}/page/index.html`);
    await b.page.waitForFunction(() => window.pageReady === true, null, { timeout: 30_000 });
    b.version = b.context.browser()?.version() ?? '';
    return b;
  }

  /** Draws `glb` (a path under OUT) and saves the screenshot to `png`. Returns the page's report. */
  async render(glb, png, { exposure, lightmapColorSpace }) {
    this.messages.length = 0;
    const url = `${this.base}/out/${path.relative(OUT, glb).split(path.sep).join('/')}`;
    const info = await withTimeout(60_000, `three.js drawing ${path.basename(glb)}`, this.page.evaluate(
      (o) => window.renderGlb(o),
      { url, width: SIZE, height: SIZE, exposure, lightmapColorSpace },
    ));
    await this.page.locator('canvas').screenshot({ path: png });
    info.messages = [...this.messages];
    return info;
  }

  async close() {
    await this.context.close();
    this.server.close();
    fs.rmSync(this.profile, { recursive: true, force: true });
  }
}

// ---------------------------------------------------------------------------------------------
// The checks

async function validate(file) {
  const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(file)), { maxIssues: 0, format: 'glb' });
  const { numErrors, numWarnings, numInfos, messages } = report.issues;
  const first = messages.filter((m) => m.severity <= 1).slice(0, 3).map((m) => `${m.code} at ${m.pointer}: ${m.message}`);
  return { errors: numErrors, warnings: numWarnings, infos: numInfos, first };
}

/**
 * The three.js picture of `glb` against `penumbra render` of the same file, and against
 * three.js with the lightmap removed. Returns the numbers; `tag` names the output files.
 */
async function compare(browser, glb, tag, { lightmapColorSpace = 'file' } = {}) {
  const { json } = readGlb(glb);
  const exposure = exposureOf(json);
  const ref = path.join(OUT, `${tag}-penumbra.png`);
  penumbra(['render', glb, '--out', ref, '--width', String(SIZE), '--height', String(SIZE), '--camera', 'gltf', '--exposure', String(exposure)]);
  const shot = path.join(OUT, `${tag}-threejs.png`);
  const info = await browser.render(glb, shot, { exposure, lightmapColorSpace });
  const stripped = path.join(OUT, 'glb', `${tag}-nolightmap.glb`);
  editGlb(glb, stripped, breakages.removeLightmap);
  const bare = path.join(OUT, `${tag}-threejs-nolightmap.png`);
  await browser.render(stripped, bare, { exposure, lightmapColorSpace });
  const [a, b, c] = [readPng(shot), readPng(ref), readPng(bare)];
  writeDiff(a, b, path.join(OUT, `${tag}-diff.png`));
  return {
    exposure,
    info,
    mad: meanAbsDiff(a, b),
    applied: meanAbsDiff(a, c),
    meanThree: meanLinear(a),
    meanPenumbra: meanLinear(b),
  };
}

const fmt = (x) => x.toFixed(4);

async function main() {
  const args = process.argv.slice(2);
  const only = args.includes('--only') ? args[args.indexOf('--only') + 1].split(',') : null;
  const updateScreenshot = args.includes('--update-screenshot');
  const ci = process.env.CI === 'true';

  if (!fs.existsSync(PENUMBRA)) {
    check('penumbra binary', false, `${PENUMBRA} not found (run \`cargo build --release\` or set PENUMBRA_BIN)`);
    finish();
  }
  fs.rmSync(OUT, { recursive: true, force: true });
  fs.mkdirSync(path.join(OUT, 'glb'), { recursive: true });

  // 1-2. Bake and validate every fixture.
  const fixtures = fs.readdirSync(path.join(ROOT, 'fixtures'))
    .filter((f) => f.endsWith('.glb'))
    .map((f) => path.basename(f, '.glb'))
    .filter((n) => !only || only.includes(n))
    .sort();
  const baked = {};
  // [name, fixture, extra bake options]
  const bakes = fixtures.map((n) => [n, n, []]);
  if (fixtures.includes('cornell-box')) bakes.push(['cornell-box-linear', 'cornell-box', ['--encoding', 'linear']]);
  if (fixtures.includes('box-on-floor')) {
    bakes.push(['box-on-floor-pages', 'box-on-floor', ['--texels-per-unit', '24', '--page-size', '128']]);
  }
  for (const [name, fixture, extra] of bakes) {
    const out = path.join(OUT, 'glb', `${name}.glb`);
    const t0 = Date.now();
    try {
      penumbra(['bake', path.join(ROOT, 'fixtures', `${fixture}.glb`), out, '--quiet', ...extra]);
      if (name === 'box-on-floor-pages') {
        const pages = readGlb(out).json.textures.filter((t) => t.extras?.penumbra).length;
        check('bake box-on-floor onto several pages', pages > 1, `${pages} lightmap pages`);
      }
    } catch (e) {
      check(`bake ${name}`, false, e.message);
      continue;
    }
    baked[name] = out;
    const v = await validate(out);
    check(`validator ${name}`, v.errors === 0 && v.warnings === 0,
      `${v.errors} errors, ${v.warnings} warnings, ${v.infos} infos (bake ${((Date.now() - t0) / 1000).toFixed(1)} s)` +
      (v.first.length ? `\n       ${v.first.join('\n       ')}` : ''));
  }

  // Self-test: TEXCOORD_1 without TEXCOORD_0 is invalid glTF, and the validator must say so.
  if (baked['cornell-box']) {
    const broken = path.join(OUT, 'glb', 'broken-no-texcoord0.glb');
    editGlb(baked['cornell-box'], broken, breakages.dropTexcoord0);
    const v = await validate(broken);
    check('self-test: validator catches a dropped TEXCOORD_0', v.errors > 0,
      `${v.errors} errors, ${v.warnings} warnings${v.first.length ? ` (${v.first[0]})` : ''}`);
  }

  // 3. three.js.
  const chromium = findChromium();
  if (!chromium) {
    const why = 'Chromium not found (install Debian\'s `chromium`, or set CHROMIUM=/path/to/chromium)';
    if (ci) check('three.js', false, why);
    else skip('three.js checks', why);
    finish();
  }
  let browser;
  try {
    browser = await Browser.open(chromium);
  } catch (e) {
    check('three.js: start headless Chromium', false, `${chromium}: ${e.message}`);
    finish();
  }
  try {
    let announced = false;
    for (const name of Object.keys(baked)) {
      // The camera: the file's own, else a fixed one added to a copy of the file.
      const view = path.join(OUT, 'glb', `${name}-view.glb`);
      const v = VIEWS[name] ?? DEFAULT_VIEW;
      editGlb(baked[name], view, (json) => {
        if (!hasCamera(json)) addCamera(json, v);
        if (v.exposure) json.asset.extras = { ...json.asset.extras, clientCheckExposure: v.exposure };
      });
      const r = await compare(browser, view, name);
      if (!announced) {
        console.log(`     (three.js r${r.info.three}, Chromium ${browser.version}, WebGL${r.info.webgl2 ? '2' : '1'} on ${r.info.glRenderer})`);
        announced = true;
      }
      const loaded = `${r.info.lightmapped}/${r.info.materials} materials lightmapped, uv channel ${r.info.lightmapChannels.join(',') || '-'}`;
      check(`three.js ${name} matches penumbra render`, r.mad < MAD_TOLERANCE,
        `mean |diff| ${fmt(r.mad)} (tolerance ${MAD_TOLERANCE}), mean ${fmt(r.meanThree)} vs ${fmt(r.meanPenumbra)}, exposure ${r.exposure.toFixed(3)}, ${loaded}` +
        (r.info.messages.length ? `\n       ${r.info.messages.slice(0, 5).join('\n       ')}` : ''));
      check(`three.js ${name} lightmap applied`, r.applied >= APPLIED_MIN_MAD,
        `mean |lit - without lightmap| ${fmt(r.applied)} (at least ${APPLIED_MIN_MAD})`);
      if (name === 'cornell-box' && updateScreenshot) {
        const dest = path.join(HERE, 'screenshots', 'cornell-box-threejs.png');
        fs.mkdirSync(path.dirname(dest), { recursive: true });
        fs.copyFileSync(path.join(OUT, `${name}-threejs.png`), dest);
        console.log(`     screenshot copied to ${path.relative(process.cwd(), dest)}`);
      }
    }

    // Self-tests: each broken file (or broken client) must be caught.
    const selfTests = [
      {
        name: 'MOZ_lightmap.texCoord 2 (a UV set that does not exist)',
        tag: 'broken-texcoord2', base: 'cornell-box', edit: breakages.lightmapTexCoord(2),
        caught: (r) => r.mad >= MAD_TOLERANCE, what: (r) => `mean |diff| ${fmt(r.mad)} vs tolerance ${MAD_TOLERANCE}`,
      },
      {
        // instanced's panel mesh has its own TEXCOORD_0; elsewhere TEXCOORD_0 is a copy of
        // TEXCOORD_1 (penumbra adds it where the input had none), so texCoord 0 changes nothing there.
        name: 'MOZ_lightmap.texCoord 0 (the material UVs)',
        tag: 'broken-texcoord0', base: 'instanced', edit: breakages.lightmapTexCoord(0),
        caught: (r) => r.mad >= MAD_TOLERANCE, what: (r) => `mean |diff| ${fmt(r.mad)} vs tolerance ${MAD_TOLERANCE}`,
      },
      {
        name: 'MOZ_lightmap removed',
        tag: 'broken-no-lightmap', base: 'cornell-box', edit: breakages.removeLightmap,
        caught: (r) => r.applied < APPLIED_MIN_MAD, what: (r) => `mean |lit - without lightmap| ${fmt(r.applied)} vs minimum ${APPLIED_MIN_MAD}`,
      },
      {
        name: 'client decodes the (sRGB) lightmap as linear',
        tag: 'broken-linear-decode', base: 'cornell-box', edit: () => {}, client: { lightmapColorSpace: 'none' },
        caught: (r) => r.mad >= MAD_TOLERANCE, what: (r) => `mean |diff| ${fmt(r.mad)} vs tolerance ${MAD_TOLERANCE}`,
      },
      {
        name: 'client decodes a --encoding linear lightmap as sRGB',
        tag: 'broken-srgb-decode', base: 'cornell-box-linear', edit: () => {}, client: { lightmapColorSpace: 'srgb' },
        caught: (r) => r.mad >= MAD_TOLERANCE, what: (r) => `mean |diff| ${fmt(r.mad)} vs tolerance ${MAD_TOLERANCE}`,
      },
    ];
    for (const t of selfTests) {
      const view = path.join(OUT, 'glb', `${t.base}-view.glb`);
      if (!fs.existsSync(view)) continue;
      const broken = path.join(OUT, 'glb', `${t.tag}.glb`);
      editGlb(view, broken, t.edit);
      const r = await compare(browser, broken, t.tag, t.client);
      check(`self-test: three.js checks catch ${t.name}`, t.caught(r), t.what(r));
    }
  } catch (e) {
    check('three.js', false, e.stack ?? String(e));
  } finally {
    await browser.close();
  }
  finish();
}

main().catch((e) => {
  check('client checks', false, e.stack ?? String(e));
  finish();
});
