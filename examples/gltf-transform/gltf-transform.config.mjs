// The glTF-Transform CLI with MOZ_lightmap: every extension it knows, plus moz-lightmap.mjs.
//
//   gltf-transform optimize baked.glb small.glb --config examples/gltf-transform/gltf-transform.config.mjs \
//     --simplify false --prune-attributes false --palette false
//
// Those options keep the lightmap as baked (docs/engines.md says why). The CLI replaces its list
// of extensions with `extensions` from this file, so the list holds ALL_EXTENSIONS as well. Node must find @gltf-transform/extensions and @gltf-transform/core from
// this folder, and they must be the copies the CLI itself uses (see docs/engines.md).

import { ALL_EXTENSIONS } from '@gltf-transform/extensions';
import { MozLightmap } from './moz-lightmap.mjs';

export default {
  extensions: [...ALL_EXTENSIONS, MozLightmap],
};
