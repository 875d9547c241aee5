// The three.js side of the client check: load a baked glb with GLTFLoader and the MOZ_lightmap
// plugin, draw it from the file's camera as a lightmap-only client shows it, and report what
// was loaded. The driver (../run.mjs) calls `window.renderGlb(options)` and takes the screenshot.
//
// What a client shows: radiance = albedo/pi x (lightmap x intensity) + emissive, in W/(m² sr).
// MeshLambertMaterial with no scene lights does exactly that. To show it like
// `penumbra render --exposure E` (radiance E is white, clamped, sRGB-encoded), the lightmap
// intensity and the emissive intensity are divided by E, with no tone mapping and sRGB output.
// (LinearToneMapping with toneMappingExposure = 1/E is the same thing.)

import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
// For files that glTF-Transform or gltfpack compressed (EXT_meshopt_compression).
import { MeshoptDecoder } from 'three/addons/libs/meshopt_decoder.module.js';
import { MozLightmapExtension, directionalPages } from './moz-lightmap.mjs';

let renderer = null;

function rendererOfSize(width, height) {
  if (!renderer) {
    renderer = new THREE.WebGLRenderer({ antialias: false, alpha: false, preserveDrawingBuffer: true });
    renderer.setPixelRatio(1);
    renderer.toneMapping = THREE.NoToneMapping;
    renderer.outputColorSpace = THREE.SRGBColorSpace;
    renderer.setClearColor(0x000000, 1);
    document.body.appendChild(renderer.domElement);
  }
  renderer.setSize(width, height);
  return renderer;
}

/** Replaces every mesh material by a MeshLambertMaterial with the same diffuse, emission and lightmap. */
function toLambert(root) {
  const converted = new Map();
  root.traverse((obj) => {
    if (!obj.isMesh) return;
    const one = (m) => {
      if (!converted.has(m)) {
        converted.set(m, new THREE.MeshLambertMaterial({
          name: m.name,
          color: m.color,
          map: m.map,
          emissive: m.emissive,
          emissiveIntensity: m.emissiveIntensity,
          emissiveMap: m.emissiveMap,
          lightMap: m.lightMap,
          lightMapIntensity: m.lightMapIntensity,
          // glTF's occlusionTexture: three applies it to the indirect light, the lightmap's too.
          aoMap: m.aoMap,
          aoMapIntensity: m.aoMapIntensity,
          // Shades nothing without lights, but the directional lightmap's shader reads it.
          normalMap: m.normalMap,
          normalScale: m.normalScale,
          side: m.side,
          vertexColors: m.vertexColors,
        }));
        m.dispose();
      }
      return converted.get(m);
    };
    obj.material = Array.isArray(obj.material) ? obj.material.map(one) : one(obj.material);
  });
  return [...converted.values()];
}

/**
 * Shades `material`'s lightmap with its directional pages ([x, y, z]): the irradiance for the
 * normal-mapped world-space normal n is H (1/2 + 2 r · n), r = 2 v - 1 per channel and axis,
 * clamped at zero (penumbra's `extras.penumbra.directional`). `swap` swaps the x and z pages
 * (a self-test breaks the decoding with it).
 */
function useDirectional(material, pages, swap) {
  const [x, y, z] = swap ? [pages[2], pages[1], pages[0]] : pages;
  material.onBeforeCompile = (shader) => {
    shader.uniforms.lightMapL1x = { value: x };
    shader.uniforms.lightMapL1y = { value: y };
    shader.uniforms.lightMapL1z = { value: z };
    const before = 'vec3 lightMapIrradiance = lightMapTexel.rgb * lightMapIntensity;';
    const chunk = THREE.ShaderChunk.lights_fragment_maps;
    if (!chunk.includes(before) || !shader.fragmentShader.includes('#include <lights_fragment_maps>')) {
      throw new Error('three.js lightmap chunk changed');
    }
    shader.fragmentShader = 'uniform sampler2D lightMapL1x;\nuniform sampler2D lightMapL1y;\nuniform sampler2D lightMapL1z;\n' +
      shader.fragmentShader.replace('#include <lights_fragment_maps>', chunk.replace(before, `${before}
        {
          vec3 rx = texture2D( lightMapL1x, vLightMapUv ).rgb * 2.0 - 1.0;
          vec3 ry = texture2D( lightMapL1y, vLightMapUv ).rgb * 2.0 - 1.0;
          vec3 rz = texture2D( lightMapL1z, vLightMapUv ).rgb * 2.0 - 1.0;
          // The normal-mapped normal, from view to world space.
          vec3 n = normalize( ( vec4( normal, 0.0 ) * viewMatrix ).xyz );
          lightMapIrradiance *= max( vec3( 0.0 ), 0.5 + 2.0 * ( rx * n.x + ry * n.y + rz * n.z ) );
        }`));
  };
  material.customProgramCacheKey = () => (swap ? 'penumbra-l1-swapped' : 'penumbra-l1');
  material.needsUpdate = true;
}

function dispose(root) {
  root.traverse((obj) => {
    if (!obj.isMesh) return;
    obj.geometry.dispose();
    for (const m of [obj.material].flat()) {
      for (const t of [m.map, m.emissiveMap, m.lightMap, m.aoMap, m.normalMap]) t?.dispose();
      m.dispose();
    }
  });
}

/**
 * options: url (the glb), width, height, exposure (radiance shown as white, W/(m² sr)),
 * lightmapColorSpace ('file': as the texture's extras.penumbra.encoding says, through the
 * plugin; 'srgb' or 'none' to override it, e.g. to break it on purpose), layerScales (light
 * group name to factor: the plugin shows those groups' layers scaled).
 * Draws the glb, leaves the picture in the canvas, and returns what was loaded.
 */
/**
 * The probes' spherical harmonics (`extras.penumbra_probes`) at `centre`, as `penumbra render
 * --probe-sphere` takes them: trilinear over the eight probes around it (clamped to the grid),
 * the probes inside geometry left out. `order` permutes the coefficients (a self-test breaks it).
 */
function probeHarmonics(probes, centre, order) {
  const { origin, spacing, counts, sh } = probes;
  const inside = new Set(probes.inside ?? []);
  const sum = new Array(27).fill(0);
  let weights = 0;
  for (let corner = 0; corner < 8; corner++) {
    let index = 0;
    let w = 1;
    for (const [axis, stride] of [[0, 1], [1, counts[0]], [2, counts[0] * counts[1]]]) {
      const c = Math.min(Math.max((centre[axis] - origin[axis]) / spacing, 0), counts[axis] - 1);
      const lo = Math.min(Math.floor(c), counts[axis] - 1);
      const f = c - lo;
      const up = (corner >> axis) & 1;
      index += (up ? Math.min(lo + 1, counts[axis] - 1) : lo) * stride;
      w *= up ? f : 1 - f;
    }
    if (w <= 0 || inside.has(index)) continue;
    for (let k = 0; k < 27; k++) sum[k] += sh[index][k] * w;
    weights += w;
  }
  const out = new Array(27);
  for (let k = 0; k < 9; k++) for (let c = 0; c < 3; c++) out[3 * k + c] = sum[3 * order[k] + c] / weights;
  return out;
}

window.renderGlb = async function renderGlb({ url, width, height, exposure, lightmapColorSpace = 'file', layerScales = {}, probeSphere = null, directional = null }) {
  const r = rendererOfSize(width, height);
  const loader = new GLTFLoader();
  loader.register((parser) => new MozLightmapExtension(parser, layerScales));
  loader.setMeshoptDecoder(MeshoptDecoder);
  const gltf = await loader.loadAsync(url);
  const scene = gltf.scene;

  // The lightmap holds all the light: drop the file's punctual lights.
  const lights = [];
  scene.traverse((obj) => { if (obj.isLight) lights.push(obj); });
  for (const l of lights) l.removeFromParent();

  const materials = toLambert(scene);
  const channels = new Set();
  let directionalMaterials = 0;
  for (const m of materials) {
    m.emissiveIntensity /= exposure;
    // Directional lightmaps: 'decode' as penumbra writes them, 'swapped' broken on purpose.
    const pages = m.lightMap && directionalPages.get(m.lightMap);
    if (directional && pages) {
      useDirectional(m, pages, directional === 'swapped');
      directionalMaterials++;
    }
    if (m.lightMap) {
      m.lightMapIntensity /= exposure;
      channels.add(m.lightMap.channel);
      if (lightmapColorSpace !== 'file') {
        m.lightMap.colorSpace = lightmapColorSpace === 'srgb' ? THREE.SRGBColorSpace : THREE.NoColorSpace;
        m.lightMap.needsUpdate = true;
      }
    }
  }

  // A white sphere lit by the file's light probes: one LightProbe with the harmonics at its
  // centre (three.js adds a LightProbe's light to every lit material; the check compares the
  // sphere's pixels only).
  if (probeSphere) {
    const probes = gltf.parser.json.extras?.penumbra_probes;
    if (!probes) throw new Error(`${url}: no extras.penumbra_probes`);
    const order = probeSphere.order ?? [0, 1, 2, 3, 4, 5, 6, 7, 8];
    const probe = new THREE.LightProbe();
    probe.sh.fromArray(probeHarmonics(probes, probeSphere.centre, order));
    probe.intensity = 1 / exposure;
    scene.add(probe);
    const ball = new THREE.Mesh(
      new THREE.SphereGeometry(probeSphere.radius, 256, 128),
      new THREE.MeshLambertMaterial({ color: 0xffffff }),
    );
    ball.position.fromArray(probeSphere.centre);
    scene.add(ball);
  }

  const camera = gltf.cameras[0];
  if (!camera) throw new Error(`${url}: no camera in the file`);
  camera.aspect = width / height;
  camera.updateProjectionMatrix();
  scene.updateMatrixWorld(true);
  r.render(scene, camera);
  const gl = r.getContext();
  const result = {
    three: THREE.REVISION,
    webgl2: r.capabilities.isWebGL2 !== false && gl instanceof WebGL2RenderingContext,
    glRenderer: gl.getParameter(gl.getExtension('WEBGL_debug_renderer_info')?.UNMASKED_RENDERER_WEBGL ?? gl.RENDERER),
    meshes: 0,
    materials: materials.length,
    lightmapped: materials.filter((m) => m.lightMap).length,
    lightmapChannels: [...channels],
    // Distinct lightmap images three.js decoded (one per atlas page the scene uses).
    lightmapImages: new Set(materials.filter((m) => m.lightMap?.image?.width > 0).map((m) => m.lightMap.image)).size,
    lightsRemoved: lights.length,
    directionalMaterials,
  };
  scene.traverse((obj) => { if (obj.isMesh) result.meshes++; });
  dispose(scene);
  return result;
};

window.pageReady = true;
