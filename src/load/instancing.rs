//! `EXT_mesh_gpu_instancing`: a node that draws its mesh many times, once per row of its
//! `TRANSLATION`, `ROTATION` and `SCALE` accessors. Each instance is a placement of its own:
//! it receives, occludes and gets its own lightmap space, like a node of its own (the writer
//! makes it one, [`crate::write`]).

use super::Gltf;
use crate::error::Result;
use glam::{DMat4, DQuat, DVec3};
use gltf::accessor::Dimensions;

/// The name of the extension.
pub(crate) const NAME: &str = "EXT_mesh_gpu_instancing";

/// The local transform of each of node `node`'s GPU instances (applied before the node's own
/// transform), or `None` when the node has none; refused past `most` instances (checked before
/// they are read).
pub(crate) fn instances(gltf: &Gltf, node: usize, most: usize) -> Result<Option<Vec<DMat4>>> {
    let ext = &gltf.json["nodes"][node]["extensions"][NAME];
    if ext.is_null() {
        return Ok(None);
    }
    let item = format!("node {node} {NAME}");
    let attributes = ext["attributes"]
        .as_object()
        .ok_or_else(|| gltf.bad(&item, "has no attributes object"))?;
    let mut count = None;
    let mut read = |name: &str, dims: Dimensions| -> Result<Option<Vec<f64>>> {
        let Some(index) = attributes.get(name) else {
            return Ok(None);
        };
        let accessor = index
            .as_u64()
            .and_then(|i| gltf.document.accessors().nth(i as usize))
            .ok_or_else(|| gltf.bad(&item, format!("{name}: {index} is not an accessor")))?;
        if accessor.count() > most {
            return Err(gltf.bad(
                &item,
                format!(
                    "{name} has {} instances, more than {most} (--max-instances raises the limit)",
                    accessor.count()
                ),
            ));
        }
        if *count.get_or_insert(accessor.count()) != accessor.count() {
            return Err(gltf.bad(
                &item,
                format!(
                    "{name} has {} elements, the other attributes {count:?}",
                    accessor.count()
                ),
            ));
        }
        gltf.read_floats(&accessor, dims)
            .map(Some)
            .map_err(|e| e.within(&format!("{item} {name}")))
    };
    let t = read("TRANSLATION", Dimensions::Vec3)?;
    let r = read("ROTATION", Dimensions::Vec4)?;
    let s = read("SCALE", Dimensions::Vec3)?;
    let n = count.ok_or_else(|| gltf.bad(&item, "has none of TRANSLATION, ROTATION and SCALE"))?;
    let v3 = |a: &Option<Vec<f64>>, k: usize, default: DVec3| {
        a.as_ref().map_or(default, |a| {
            DVec3::new(a[3 * k], a[3 * k + 1], a[3 * k + 2])
        })
    };
    (0..n)
        .map(|k| {
            let q = r.as_ref().map_or(DQuat::IDENTITY, |r| {
                DQuat::from_xyzw(r[4 * k], r[4 * k + 1], r[4 * k + 2], r[4 * k + 3])
            });
            let m = DMat4::from_scale_rotation_translation(
                v3(&s, k, DVec3::ONE),
                q.normalize(),
                v3(&t, k, DVec3::ZERO),
            );
            if m.is_finite() && q.length() > 0.5 {
                Ok(m)
            } else {
                Err(gltf.bad(
                    &item,
                    format!("instance {k}: the transform is not finite or its rotation is not a unit quaternion"),
                ))
            }
        })
        .collect::<Result<Vec<_>>>()
        .map(Some)
}
