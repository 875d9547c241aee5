// The JS glTF toolchain on a baked file (issue 37): glTF-Transform with the MOZ_lightmap module in
// examples/gltf-transform/, and gltfpack. run.mjs calls these and draws the results in three.js.

import { spawnSync } from 'node:child_process';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { readGlb, writeGlb } from './glb.mjs';

const HERE = path.dirname(fileURLToPath(import.meta.url));
const ROOT = path.resolve(HERE, '../..');
const BIN = path.join(HERE, 'node_modules', '.bin');
export const GT_CONFIG = path.join(ROOT, 'examples', 'gltf-transform', 'gltf-transform.config.mjs');

/**
 * The `gltf-transform optimize` options that keep the lightmap as baked (docs/engines.md): no
 * simplification (it moves vertices, and with them the lightmap UVs), the UV sets kept (else
 * TEXCOORD_1 becomes TEXCOORD_0 wherever no other texture uses TEXCOORD_0) and no palette (it
 * merges the materials and moves their albedo into an 8-bit texture). The rest stays at its
 * default: meshopt compression, and `--texture-compress auto`, which re-encodes PNG losslessly.
 */
export const OPTIMIZE_KEEP_LIGHTMAP = ['--simplify', 'false', '--prune-attributes', 'false', '--palette', 'false'];

/** The gltfpack options that keep the most of a baked file (it still drops MOZ_lightmap). */
export const GLTFPACK_KEEP = ['-kn', '-km', '-ke', '-kv', '-vtf'];

function tool(name, args) {
  const t0 = Date.now();
  const r = spawnSync(path.join(BIN, name), args, { encoding: 'utf8', maxBuffer: 64 << 20, timeout: 120_000 });
  if (r.error) throw r.error;
  if (r.status !== 0) throw new Error(`${name} ${args.join(' ')}: exit ${r.status}\n${r.stderr}${r.stdout}`);
  return { seconds: (Date.now() - t0) / 1000, stderr: r.stderr };
}

/** `gltf-transform optimize IN OUT` with the MOZ_lightmap config (unless `config` is false) and `options`. */
export function gltfTransformOptimize(input, output, options, { config = true } = {}) {
  return tool('gltf-transform', ['optimize', input, output, ...options, ...(config ? ['--config', GT_CONFIG] : [])]);
}

/** `gltfpack -i IN -o OUT options`. */
export function gltfpack(input, output, options) {
  return tool('gltfpack', ['-i', input, '-o', output, ...options]);
}

/** gltfpack's version line. */
export function gltfpackVersion() {
  return spawnSync(path.join(BIN, 'gltfpack'), ['-v'], { encoding: 'utf8' }).stdout.trim().split('\n')[0];
}

/**
 * What a baked file holds of its lightmap: the materials and primitives with MOZ_lightmap, their
 * texCoord and intensity, whether each such primitive has that UV set, and each lightmap
 * texture's `extras.penumbra`.
 */
export function lightmapOf(file) {
  const { json } = readGlb(file);
  const materials = json.materials ?? [];
  const lit = materials.map((m) => m.extensions?.MOZ_lightmap ?? null);
  const prims = (json.meshes ?? []).flatMap((m) => m.primitives);
  const litPrims = prims.filter((p) => p.material !== undefined && lit[p.material]);
  return {
    used: (json.extensionsUsed ?? []).includes('MOZ_lightmap'),
    required: (json.extensionsRequired ?? []).includes('MOZ_lightmap'),
    materials: lit.filter(Boolean).length,
    primitives: prims.length,
    litPrimitives: litPrims.length,
    texCoords: [...new Set(lit.filter(Boolean).map((l) => l.texCoord ?? 0))],
    intensities: [...new Set(lit.filter(Boolean).map((l) => l.intensity ?? 1))],
    // Every lit primitive has the UV set its MOZ_lightmap names.
    uvsPresent: litPrims.every((p) => `TEXCOORD_${lit[p.material].texCoord ?? 0}` in p.attributes),
    texcoord1: prims.filter((p) => 'TEXCOORD_1' in p.attributes).length,
    pages: [...new Set(lit.filter(Boolean).map((l) => JSON.stringify(json.textures?.[l.index]?.extras?.penumbra ?? null)))],
    images: [...new Set((json.images ?? []).map((i) => i.mimeType))],
    extensionsUsed: json.extensionsUsed ?? [],
  };
}

/**
 * Whether `after` (a processed copy of the baked file `before`) still carries the lightmap as
 * baked: MOZ_lightmap on every primitive that had it, on TEXCOORD_1, the same intensities, the
 * same `extras.penumbra` on the lightmap textures. Returns `{ ok, detail }`.
 */
export function lightmapKept(before, after) {
  const a = lightmapOf(before);
  const b = lightmapOf(after);
  const problems = [];
  if (!b.used) problems.push('MOZ_lightmap not in extensionsUsed');
  if (b.required) problems.push('MOZ_lightmap in extensionsRequired');
  if (b.materials === 0) problems.push('no material has MOZ_lightmap');
  if (b.litPrimitives / b.primitives !== a.litPrimitives / a.primitives) {
    problems.push(`${b.litPrimitives}/${b.primitives} primitives lit (before: ${a.litPrimitives}/${a.primitives})`);
  }
  if (JSON.stringify(b.texCoords) !== '[1]') problems.push(`texCoord ${b.texCoords.join(',') || '-'} (not 1)`);
  if (!b.uvsPresent) problems.push('a lit primitive lacks its lightmap UV set');
  if (b.texcoord1 < b.litPrimitives) problems.push(`TEXCOORD_1 on ${b.texcoord1} primitives, ${b.litPrimitives} lit`);
  if (JSON.stringify([...b.intensities].sort()) !== JSON.stringify([...a.intensities].sort())) problems.push('intensity changed');
  if (JSON.stringify([...b.pages].sort()) !== JSON.stringify([...a.pages].sort())) problems.push('texture extras.penumbra changed or lost');
  const detail = `${b.materials} materials with MOZ_lightmap (before ${a.materials}), ${b.litPrimitives}/${b.primitives} primitives lit, ` +
    `texCoord ${b.texCoords.join(',') || '-'}, TEXCOORD_1 on ${b.texcoord1}, images ${b.images.join(',') || '-'}, ` +
    `extensions ${b.extensionsUsed.join(',') || '-'}`;
  return { ok: problems.length === 0, problems, detail: problems.length ? `${problems.join('; ')} | ${detail}` : detail };
}

/** Bytes of a file, as KiB text. */
export const kib = (file) => `${(fs.statSync(file).size / 1024).toFixed(0)} KiB`;

/**
 * The module and config in examples/gltf-transform/ import @gltf-transform/core and
 * @gltf-transform/extensions by name, and must get the very copies the CLI uses (the extension's
 * properties are matched with `instanceof`). Node looks for them in a node_modules beside the
 * files, so that is made a link to this folder's node_modules (git ignores it). An existing
 * examples/gltf-transform/node_modules is left alone.
 */
export function linkExampleModules() {
  const link = path.join(path.dirname(GT_CONFIG), 'node_modules');
  if (fs.existsSync(link)) return;
  try {
    fs.lstatSync(link);
    fs.unlinkSync(link); // a dangling link
  } catch { /* none */ }
  fs.symlinkSync(path.relative(path.dirname(link), path.join(HERE, 'node_modules')), link, 'dir');
}

/** Triangles in a file's meshes (each mesh counted once, however many nodes place it). */
export function triangles(file) {
  const { json } = readGlb(file);
  let n = 0;
  for (const m of json.meshes ?? []) {
    for (const p of m.primitives) {
      if ((p.mode ?? 4) !== 4) continue;
      n += (p.indices !== undefined ? json.accessors[p.indices].count : json.accessors[p.attributes.POSITION].count) / 3;
    }
  }
  return n;
}

const SRGB = Float64Array.from({ length: 256 }, (_, i) => {
  const c = i / 255;
  return c <= 0.04045 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4;
});

/** The lightmap pages of a file: page number -> { pixels (RGB bytes), width, height, encoding }. */
async function lightmapPages(file) {
  const { default: sharp } = await import('sharp');
  const { json, bin } = readGlb(file);
  const pages = new Map();
  for (const m of json.materials ?? []) {
    const lm = m.extensions?.MOZ_lightmap;
    const tex = lm && json.textures?.[lm.index];
    if (!tex) continue;
    const page = tex.extras?.penumbra?.page ?? 0;
    if (pages.has(page)) continue;
    let source = tex.source;
    for (const ext of ['EXT_texture_webp', 'EXT_texture_avif']) source ??= tex.extensions?.[ext]?.source;
    const view = json.bufferViews[json.images[source].bufferView];
    const bytes = bin.subarray(view.byteOffset ?? 0, (view.byteOffset ?? 0) + view.byteLength);
    const { data, info } = await sharp(bytes).removeAlpha().raw().toBuffer({ resolveWithObject: true });
    pages.set(page, { pixels: data, width: info.width, height: info.height, encoding: tex.extras?.penumbra?.encoding ?? 'linear' });
  }
  return pages;
}

/**
 * The lightmap texels of `after` against those of `before`, page by page: the mean absolute
 * difference of the decoded (linear) values as a fraction of their mean, and the largest
 * difference in 8-bit codes. null when `after` has no lightmap (or a page changed size).
 */
export async function texelDiff(before, after) {
  const [a, b] = [await lightmapPages(before), await lightmapPages(after)];
  if (b.size === 0) return null;
  let sum = 0;
  let ref = 0;
  let maxCode = 0;
  for (const [page, pa] of a) {
    const pb = b.get(page);
    if (!pb || pb.width !== pa.width || pb.height !== pa.height) return null;
    const lin = (v) => (pa.encoding === 'srgb' ? SRGB[v] : v / 255);
    for (let i = 0; i < pa.pixels.length; i++) {
      sum += Math.abs(lin(pa.pixels[i]) - lin(pb.pixels[i]));
      ref += lin(pa.pixels[i]);
      maxCode = Math.max(maxCode, Math.abs(pa.pixels[i] - pb.pixels[i]));
    }
  }
  return { relative: ref > 0 ? sum / ref : 0, maxCode };
}

/**
 * A copy of `from` whose primitives with TEXCOORD_0 get a base colour texture: a 64x64 PNG
 * checker of two colours (the input for the optimised-input checks, where `gltf-transform webp`
 * needs a texture to re-encode). Their materials are copied first, so other primitives keep
 * their own colour.
 */
export async function withCheckerTexture(from, to) {
  const { PNG } = await import('pngjs');
  const png = new PNG({ width: 64, height: 64 });
  for (let y = 0; y < 64; y++) {
    for (let x = 0; x < 64; x++) {
      const light = ((x >> 3) + (y >> 3)) % 2 === 0;
      png.data.set(light ? [230, 200, 150, 255] : [60, 90, 140, 255], 4 * (64 * y + x));
    }
  }
  const bytes = PNG.sync.write(png);
  const glb = readGlb(from);
  const { json } = glb;
  const pad = (b) => Buffer.concat([b, Buffer.alloc((4 - (b.length % 4)) % 4)]);
  const base = pad(glb.bin ?? Buffer.alloc(0));
  glb.bin = Buffer.concat([base, bytes]);
  json.buffers[0].byteLength = glb.bin.length;
  json.bufferViews.push({ buffer: 0, byteOffset: base.length, byteLength: bytes.length });
  (json.images ??= []).push({ bufferView: json.bufferViews.length - 1, mimeType: 'image/png' });
  (json.samplers ??= []).push({ wrapS: 10497, wrapT: 10497 });
  (json.textures ??= []).push({ source: json.images.length - 1, sampler: json.samplers.length - 1 });
  const texture = json.textures.length - 1;
  for (const mesh of json.meshes) {
    for (const p of mesh.primitives) {
      if (!('TEXCOORD_0' in p.attributes)) continue;
      const m = structuredClone(json.materials?.[p.material] ?? {});
      (m.pbrMetallicRoughness ??= {}).baseColorTexture = { index: texture };
      json.materials.push(m);
      p.material = json.materials.length - 1;
    }
  }
  writeGlb(to, glb);
}

/** `gltf-transform CMD IN OUT args` (any command; no MOZ_lightmap config). */
export function gltfTransform(cmd, input, output, args = []) {
  return tool('gltf-transform', [cmd, input, output, ...args]);
}

/** The extensions a file requires. */
export function required(file) {
  return readGlb(file).json.extensionsRequired ?? [];
}
