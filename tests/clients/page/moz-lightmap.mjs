// A GLTFLoader plugin for MOZ_lightmap, the lightmap extension penumbra writes.
//
// three.js (0.187) ships no MOZ_lightmap support: GLTFLoader ignores the extension and its
// addons hold no `GLTFLightMapLoaderExtension`. This is the smallest plugin that reads it.
//
//   MOZ_lightmap: { index: <texture>, texCoord: <n>, intensity: <s>,
//                   extras: { penumbra: { layers: [{ group, index, texCoord, intensity }] } } }
//
// The texel value, decoded by the curve the texture's `extras.penumbra.encoding` names ("srgb":
// the sRGB transfer curve, penumbra's default; "linear" or absent: none), x `intensity` is the
// irradiance H in W/m². three's `lightMap` x `lightMapIntensity` is irradiance too, and Lambert
// shows it as albedo/pi x H, which is what penumbra means. Each lightmap page is its own texture;
// a material names its page's texture in `index`.
//
// Light groups (a bake's `--light-group`): the lightmap holds every group at scale 1, and each
// group's part of it is a layer of its own. `new MozLightmapExtension(parser, { lamp: 0.5 })`
// shows group `lamp` at half its baked power: H + (0.5 - 1) x H_lamp, composed once on the CPU
// into a float texture (a game that flickers a lamp does the same sum in its shader).

// Directional lightmaps (a bake's `--directional`): `extras.penumbra.directional` names three
// more textures per page, the L1 ratio `r` per axis x, y, z (linear 8-bit, r = 2 v - 1, per
// channel), and the irradiance for a unit world-space normal n is H (1/2 + 2 r · n). The plugin
// loads them and files them under the page's lightmap texture in `directionalPages`; a client
// shades with them in its shader (see view.mjs).

import { DataTexture, DataUtils, HalfFloatType, LinearFilter, NoColorSpace, RGBAFormat, SRGBColorSpace } from 'three';

/** Lightmap texture -> its directional pages [x, y, z] (textures). */
export const directionalPages = new WeakMap();

export class MozLightmapExtension {
  constructor(parser, layerScales = {}) {
    this.parser = parser;
    this.name = 'MOZ_lightmap';
    this.layerScales = layerScales;
  }

  async extendMaterialParams(materialIndex, materialParams) {
    const ext = this.parser.json.materials[materialIndex].extensions?.[this.name];
    if (!ext) return;
    const scaled = (ext.extras?.penumbra?.layers ?? []).filter((l) => this.layerScales[l.group] !== undefined);
    let map;
    if (scaled.length) {
      map = await this.composed(ext, scaled);
      materialParams.lightMapIntensity = 1;
    } else {
      map = await this.parser.getDependency('texture', ext.index);
      const encoding = this.encodingOf(ext.index);
      // sRGB: three decodes the curve to linear when sampling; else the values are linear.
      map.colorSpace = encoding === 'srgb' ? SRGBColorSpace : NoColorSpace;
      map.needsUpdate = true;
      materialParams.lightMapIntensity = ext.intensity ?? 1;
    }
    map.channel = ext.texCoord ?? 0; // like any glTF textureInfo; TEXCOORD_n is three's uv channel n
    materialParams.lightMap = map;
    const directional = ext.extras?.penumbra?.directional;
    if (directional) {
      const pages = await Promise.all(['x', 'y', 'z'].map(async (axis) => {
        const t = await this.parser.getDependency('texture', directional[axis].index);
        t.colorSpace = NoColorSpace;
        t.channel = directional[axis].texCoord ?? 0;
        t.needsUpdate = true;
        return t;
      }));
      directionalPages.set(map, pages);
    }
  }

  encodingOf(texture) {
    return this.parser.json.textures?.[texture]?.extras?.penumbra?.encoding;
  }

  /** Linear irradiance (W/m², RGB per texel) of a lightmap texture, decoded as its extras say. */
  async irradiance(texture, intensity) {
    const image = (await this.parser.getDependency('texture', texture)).image;
    const canvas = document.createElement('canvas');
    canvas.width = image.width;
    canvas.height = image.height;
    const ctx = canvas.getContext('2d', { willReadFrequently: true });
    ctx.drawImage(image, 0, 0);
    const rgba = ctx.getImageData(0, 0, image.width, image.height).data;
    const srgb = this.encodingOf(texture) === 'srgb';
    const decode = (c) => (!srgb ? c : c <= 0.04045 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4);
    const out = new Float32Array((rgba.length / 4) * 3);
    for (let i = 0, j = 0; i < rgba.length; i += 4, j += 3) {
      for (let c = 0; c < 3; c++) out[j + c] = decode(rgba[i + c] / 255) * intensity;
    }
    return { width: image.width, height: image.height, values: out };
  }

  /** The page's lightmap with each of `layers` scaled by its group's factor, as a half-float texture. */
  async composed(ext, layers) {
    const main = await this.irradiance(ext.index, ext.intensity ?? 1);
    for (const l of layers) {
      const part = await this.irradiance(l.index, l.intensity ?? 1);
      const w = this.layerScales[l.group] - 1;
      for (let i = 0; i < main.values.length; i++) main.values[i] += w * part.values[i];
    }
    const data = new Uint16Array(main.width * main.height * 4);
    for (let p = 0; p < main.width * main.height; p++) {
      for (let c = 0; c < 3; c++) data[4 * p + c] = DataUtils.toHalfFloat(Math.max(0, main.values[3 * p + c]));
      data[4 * p + 3] = DataUtils.toHalfFloat(1);
    }
    const map = new DataTexture(data, main.width, main.height, RGBAFormat, HalfFloatType);
    map.colorSpace = NoColorSpace;
    map.magFilter = LinearFilter;
    map.minFilter = LinearFilter;
    map.generateMipmaps = false;
    map.flipY = false;
    map.needsUpdate = true;
    return map;
  }
}
