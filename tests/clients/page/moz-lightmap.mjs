// A GLTFLoader plugin for MOZ_lightmap, the lightmap extension penumbra writes.
//
// three.js (0.187) ships no MOZ_lightmap support: GLTFLoader ignores the extension and its
// addons hold no `GLTFLightMapLoaderExtension`. This is the smallest plugin that reads it.
//
//   MOZ_lightmap: { index: <texture>, texCoord: <n>, intensity: <s> }
//
// The texel value, decoded by the curve the texture's `extras.penumbra.encoding` names ("srgb":
// the sRGB transfer curve, penumbra's default; "linear" or absent: none), x `intensity` is the
// irradiance H in W/m². three's `lightMap` x `lightMapIntensity` is irradiance too, and Lambert
// shows it as albedo/pi x H, which is what penumbra means. Each lightmap page is its own texture;
// a material names its page's texture in `index`.

import { NoColorSpace, SRGBColorSpace } from 'three';

export class MozLightmapExtension {
  constructor(parser) {
    this.parser = parser;
    this.name = 'MOZ_lightmap';
  }

  async extendMaterialParams(materialIndex, materialParams) {
    const ext = this.parser.json.materials[materialIndex].extensions?.[this.name];
    if (!ext) return;
    const map = await this.parser.getDependency('texture', ext.index);
    map.channel = ext.texCoord ?? 0; // like any glTF textureInfo; TEXCOORD_n is three's uv channel n
    const encoding = this.parser.json.textures?.[ext.index]?.extras?.penumbra?.encoding;
    // sRGB: three decodes the curve to linear when sampling; else the values are linear.
    map.colorSpace = encoding === 'srgb' ? SRGBColorSpace : NoColorSpace;
    map.needsUpdate = true;
    materialParams.lightMap = map;
    materialParams.lightMapIntensity = ext.intensity ?? 1;
  }
}
