// Reading and rewriting .glb files: the JSON chunk is edited, the binary chunk is kept as is.
// Used to give a fixture a fixed camera and to break a baked file on purpose (the self-tests).

import fs from 'node:fs';

const GLB_MAGIC = 0x46546c67; // "glTF"
const CHUNK_JSON = 0x4e4f534a; // "JSON"
const CHUNK_BIN = 0x004e4942; // "BIN\0"

/** Reads a glb into `{ json, bin }` (bin: Buffer or null). */
export function readGlb(path) {
  const b = fs.readFileSync(path);
  if (b.length < 20 || b.readUInt32LE(0) !== GLB_MAGIC || b.readUInt32LE(4) !== 2) {
    throw new Error(`${path}: not a glTF 2.0 binary`);
  }
  let json = null;
  let bin = null;
  for (let at = 12; at + 8 <= b.length; ) {
    const len = b.readUInt32LE(at);
    const type = b.readUInt32LE(at + 4);
    const data = b.subarray(at + 8, at + 8 + len);
    if (type === CHUNK_JSON) json = JSON.parse(data.toString('utf8'));
    else if (type === CHUNK_BIN && bin === null) bin = Buffer.from(data);
    at += 8 + len;
  }
  if (!json) throw new Error(`${path}: no JSON chunk`);
  return { json, bin };
}

/** Writes `{ json, bin }` as a glb (chunks padded to 4 bytes: JSON with spaces, BIN with zeros). */
export function writeGlb(path, { json, bin }) {
  const pad = (buf, byte) => {
    const n = (4 - (buf.length % 4)) % 4;
    return n ? Buffer.concat([buf, Buffer.alloc(n, byte)]) : buf;
  };
  const chunk = (type, data) => {
    const head = Buffer.alloc(8);
    head.writeUInt32LE(data.length, 0);
    head.writeUInt32LE(type, 4);
    return Buffer.concat([head, data]);
  };
  const parts = [chunk(CHUNK_JSON, pad(Buffer.from(JSON.stringify(json), 'utf8'), 0x20))];
  if (bin) parts.push(chunk(CHUNK_BIN, pad(bin, 0)));
  const body = Buffer.concat(parts);
  const head = Buffer.alloc(12);
  head.writeUInt32LE(GLB_MAGIC, 0);
  head.writeUInt32LE(2, 4);
  head.writeUInt32LE(12 + body.length, 8);
  fs.writeFileSync(path, Buffer.concat([head, body]));
}

/** Copies a glb, passing its JSON through `edit(json)` (which changes it in place). */
export function editGlb(from, to, edit) {
  const glb = readGlb(from);
  edit(glb.json);
  writeGlb(to, glb);
}

/** True when the default scene (or scene 0) has a node with a camera. */
export function hasCamera(json) {
  const scene = json.scenes?.[json.scene ?? 0];
  const stack = [...(scene?.nodes ?? [])];
  while (stack.length) {
    const n = json.nodes[stack.pop()];
    if (n.camera !== undefined) return true;
    stack.push(...(n.children ?? []));
  }
  return false;
}

/**
 * Adds a perspective camera at `eye` looking at `target` (y up) as a new root node of the
 * default scene. Both `penumbra render --camera gltf` and three.js then use it.
 */
export function addCamera(json, { eye, target, yfov, name = 'client-check camera' }) {
  const sub = (a, b) => a.map((v, i) => v - b[i]);
  const norm = (a) => a.map((v) => v / Math.hypot(...a));
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const back = norm(sub(eye, target)); // the camera looks down its -z
  const right = norm(cross([0, 1, 0], back));
  const up = cross(back, right);
  json.cameras ??= [];
  json.cameras.push({ name, type: 'perspective', perspective: { aspectRatio: 1, yfov, znear: 0.01, zfar: 100 } });
  json.nodes.push({ name, translation: eye, rotation: quatFromAxes(right, up, back), camera: json.cameras.length - 1 });
  json.scenes[json.scene ?? 0].nodes.push(json.nodes.length - 1);
}

/** Unit quaternion [x, y, z, w] of the rotation whose matrix has columns x, y, z. */
function quatFromAxes(x, y, z) {
  const [m00, m10, m20] = x;
  const [m01, m11, m21] = y;
  const [m02, m12, m22] = z;
  const tr = m00 + m11 + m22;
  let q;
  if (tr > 0) {
    const s = 2 * Math.sqrt(tr + 1);
    q = [(m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s, s / 4];
  } else if (m00 > m11 && m00 > m22) {
    const s = 2 * Math.sqrt(1 + m00 - m11 - m22);
    q = [s / 4, (m01 + m10) / s, (m02 + m20) / s, (m21 - m12) / s];
  } else if (m11 > m22) {
    const s = 2 * Math.sqrt(1 + m11 - m00 - m22);
    q = [(m01 + m10) / s, s / 4, (m12 + m21) / s, (m02 - m20) / s];
  } else {
    const s = 2 * Math.sqrt(1 + m22 - m00 - m11);
    q = [(m02 + m20) / s, (m12 + m21) / s, s / 4, (m10 - m01) / s];
  }
  const n = Math.hypot(...q);
  return q.map((v) => v / n);
}

// The ways to break a baked file that the self-tests use. Each edits the JSON in place.
export const breakages = {
  /** Every primitive loses TEXCOORD_0 (TEXCOORD_1 without TEXCOORD_0 is invalid glTF). */
  dropTexcoord0(json) {
    for (const m of json.meshes ?? []) for (const p of m.primitives) delete p.attributes.TEXCOORD_0;
  },
  /** `MOZ_lightmap.texCoord` set to `n` on every material. */
  lightmapTexCoord(n) {
    return (json) => {
      for (const m of json.materials ?? []) if (m.extensions?.MOZ_lightmap) m.extensions.MOZ_lightmap.texCoord = n;
    };
  },
  /** No `MOZ_lightmap` anywhere: the file then has no lightmap for any client. */
  removeLightmap(json) {
    for (const m of json.materials ?? []) {
      if (!m.extensions) continue;
      delete m.extensions.MOZ_lightmap;
      if (Object.keys(m.extensions).length === 0) delete m.extensions;
    }
    for (const key of ['extensionsUsed', 'extensionsRequired']) {
      if (!json[key]) continue;
      json[key] = json[key].filter((e) => e !== 'MOZ_lightmap');
      if (json[key].length === 0) delete json[key];
    }
  },
  /** No light-group layers listed in any `MOZ_lightmap`: a client cannot scale them. */
  removeLayers(json) {
    for (const m of json.materials ?? []) delete m.extensions?.MOZ_lightmap?.extras;
  },
  /** No `occlusionTexture` on any material: the baked AO is not shown. */
  removeOcclusion(json) {
    for (const m of json.materials ?? []) delete m.occlusionTexture;
  },
};
