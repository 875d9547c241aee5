// MOZ_lightmap for glTF-Transform: read and write the lightmap that `penumbra bake` puts on each
// lit material, so that glTF-Transform (its CLI, or a script) keeps it.
//
//   "materials": [{ ..., "extensions": { "MOZ_lightmap": { "index": 3, "texCoord": 1, "intensity": 4.76 } } }]
//   "textures":  [{ "source": 2, "sampler": 0, "name": "penumbra lightmap",
//                   "extras": { "penumbra": { "encoding": "srgb", "scale": 4.76, "page": 0, ... } } }]
//
// Without this extension glTF-Transform drops MOZ_lightmap (it drops every extension it does not
// know), then prunes the lightmap texture as unused. With it:
//   - each lit Material gets a `Lightmap` property that holds the lightmap Texture as a texture
//     reference with its TextureInfo (texCoord, sampler), and the intensity. The reference keeps
//     the texture from being pruned, and glTF-Transform's own steps see it as the texture slot
//     `lightmapTexture` (e.g. `--slots` of the texture commands);
//   - glTF-Transform keeps no `name` or `extras` of a glTF texture (its Texture is the image), so
//     the Lightmap property carries the lightmap texture's `name` and `extras` (penumbra's
//     encoding, scale and page) and writes them back onto the texture it writes.
//
// Use: register it like any extension,
//   import { MozLightmap } from './moz-lightmap.mjs';
//   const io = new NodeIO().registerExtensions([...ALL_EXTENSIONS, MozLightmap]);
// or give gltf-transform.config.mjs (beside this file) to the CLI with `--config`.
// Tested with @gltf-transform/core 4.5.1.

import { Extension, ExtensionProperty, PropertyType, TextureChannel, TextureInfo } from '@gltf-transform/core';

export const MOZ_LIGHTMAP = 'MOZ_lightmap';

const { R, G, B } = TextureChannel;

/** The MOZ_lightmap of one Material. */
export class Lightmap extends ExtensionProperty {
  static EXTENSION_NAME = MOZ_LIGHTMAP;

  init() {
    this.extensionName = MOZ_LIGHTMAP;
    this.propertyType = 'Lightmap';
    this.parentTypes = [PropertyType.MATERIAL];
  }

  getDefaults() {
    return Object.assign(super.getDefaults(), {
      intensity: 1,
      lightmapTexture: null,
      lightmapTextureInfo: new TextureInfo(this.graph, 'lightmapTextureInfo'),
      textureName: '',
      textureExtras: {},
    });
  }

  /** The lightmap image; its texel value (decoded) x intensity is the irradiance. */
  getLightmapTexture() {
    return this.getRef('lightmapTexture');
  }

  /** texCoord and sampler of the lightmap; null when there is no texture. */
  getLightmapTextureInfo() {
    return this.getRef('lightmapTexture') ? this.getRef('lightmapTextureInfo') : null;
  }

  setLightmapTexture(texture) {
    return this.setRef('lightmapTexture', texture, { channels: R | G | B });
  }

  /** MOZ_lightmap.intensity: the scale from the decoded texel to irradiance (W/m² for penumbra). */
  getIntensity() {
    return this.get('intensity');
  }

  setIntensity(intensity) {
    return this.set('intensity', intensity);
  }

  /** `name` of the glTF texture that MOZ_lightmap.index names. */
  getTextureName() {
    return this.get('textureName');
  }

  setTextureName(name) {
    return this.set('textureName', name);
  }

  /** `extras` of the glTF texture that MOZ_lightmap.index names (penumbra: `extras.penumbra`). */
  getTextureExtras() {
    return this.get('textureExtras');
  }

  setTextureExtras(extras) {
    return this.set('textureExtras', extras);
  }
}

/** The MOZ_lightmap extension: register it with the I/O to read and write MOZ_lightmap. */
export class MozLightmap extends Extension {
  static EXTENSION_NAME = MOZ_LIGHTMAP;
  extensionName = MOZ_LIGHTMAP;
  // Read after the materials and textures exist; write after the materials are written.
  prereadTypes = [PropertyType.MESH];
  prewriteTypes = [PropertyType.MESH];

  createLightmap() {
    return new Lightmap(this.document.getGraph());
  }

  read(_context) {
    return this;
  }

  write(_context) {
    return this;
  }

  preread(context) {
    const json = context.jsonDoc.json;
    const textureDefs = json.textures ?? [];
    (json.materials ?? []).forEach((materialDef, materialIndex) => {
      const def = materialDef.extensions?.[MOZ_LIGHTMAP];
      if (!def) return;
      const lightmap = this.createLightmap();
      if (def.extras) lightmap.setExtras(def.extras);
      if (def.intensity !== undefined) lightmap.setIntensity(def.intensity);
      const textureDef = textureDefs[def.index];
      if (textureDef) {
        const source = imageOf(textureDef);
        if (source !== undefined) {
          lightmap.setLightmapTexture(context.textures[source]);
          // texCoord (1 for penumbra) and the texture's sampler. (MOZ_lightmap's own extras are
          // the property's, above.)
          context.setTextureInfo(lightmap.getLightmapTextureInfo(), { index: def.index, texCoord: def.texCoord });
        }
        if (textureDef.name) lightmap.setTextureName(textureDef.name);
        if (textureDef.extras) lightmap.setTextureExtras(structuredClone(textureDef.extras));
      }
      context.materials[materialIndex].setExtension(MOZ_LIGHTMAP, lightmap);
    });
    return this;
  }

  prewrite(context) {
    const json = context.jsonDoc.json;
    for (const material of this.document.getRoot().listMaterials()) {
      const lightmap = material.getExtension(MOZ_LIGHTMAP);
      if (!lightmap) continue;
      const texture = lightmap.getLightmapTexture();
      // A MOZ_lightmap without its texture means nothing: leave it out.
      if (!texture) continue;
      const materialDef = json.materials[context.materialIndexMap.get(material)];
      const def = context.createPropertyDef(lightmap);
      const info = context.createTextureInfoDef(texture, lightmap.getLightmapTextureInfo());
      def.index = info.index;
      def.texCoord = info.texCoord ?? 0;
      def.intensity = lightmap.getIntensity();
      materialDef.extensions ??= {};
      materialDef.extensions[MOZ_LIGHTMAP] = def;

      // The glTF texture's name and extras, which glTF-Transform itself does not keep.
      const textureDef = json.textures[info.index];
      if (lightmap.getTextureName() && textureDef.name === undefined) textureDef.name = lightmap.getTextureName();
      const extras = lightmap.getTextureExtras();
      if (extras && Object.keys(extras).length > 0) textureDef.extras = { ...textureDef.extras, ...structuredClone(extras) };
    }
    return this;
  }
}

/** The image a glTF texture samples: `source`, or the source of an image-format extension. */
function imageOf(textureDef) {
  if (textureDef.source !== undefined) return textureDef.source;
  for (const ext of ['EXT_texture_webp', 'EXT_texture_avif', 'KHR_texture_basisu']) {
    const source = textureDef.extensions?.[ext]?.source;
    if (source !== undefined) return source;
  }
  return undefined;
}
