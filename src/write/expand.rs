//! What the output does not keep of the input's encoding: meshopt-compressed buffer views are
//! written decoded, and a node's GPU instances become nodes of their own, so that each has its
//! own lightmap UVs. The extensions these used leave `extensionsUsed` and `extensionsRequired`
//! once nothing in the file uses them.

use super::{Bin, array_mut};
use crate::error::Result;
use crate::load::{Gltf, instancing, meshopt};
use crate::scene::Scene;
use serde_json::{Value, json};
use std::collections::BTreeMap;

/// Merges the input's buffers into `bin` and repoints every buffer view at it: a compressed
/// view at its decoded bytes, any other at its bytes in its buffer. A buffer that only
/// compressed views read from is left out.
pub(super) fn merge_buffers(gltf: &Gltf, root: &mut Value, bin: &mut Bin) {
    let decoded = |i: usize| gltf.decoded_views.get(i).and_then(Option::as_ref);
    let views = array_mut(root, "bufferViews");
    // Left out: a buffer that compressed views read from and no plain view does.
    let mut live = vec![true; gltf.buffers.len()];
    for view in views.iter() {
        if let Some(b) = meshopt::extension(view).and_then(|(_, e)| e["buffer"].as_u64())
            && let Some(l) = live.get_mut(b as usize)
        {
            *l = false;
        }
    }
    for (i, view) in views.iter().enumerate() {
        if decoded(i).is_none()
            && let Some(b) = view["buffer"]
                .as_u64()
                .and_then(|b| live.get_mut(b as usize))
        {
            *b = true;
        }
    }
    let base: Vec<usize> = gltf
        .buffers
        .iter()
        .zip(&live)
        .map(|(data, &live)| if live { bin.push(data) } else { 0 })
        .collect();
    for (i, view) in views.iter_mut().enumerate() {
        if let Some(bytes) = decoded(i) {
            view["byteOffset"] = json!(bin.push(bytes));
            view["byteLength"] = json!(bytes.len());
            for name in meshopt::NAMES {
                remove_extension(view, name);
            }
        } else {
            let b = view["buffer"].as_u64().unwrap_or(0) as usize;
            let off = view["byteOffset"].as_u64().unwrap_or(0) as usize;
            view["byteOffset"] = json!(off + base.get(b).copied().unwrap_or(0));
        }
        view["buffer"] = json!(0);
    }
    // Every compressed view was decoded, so nothing uses the extension any more.
    for name in meshopt::NAMES {
        undeclare(root, name);
    }
}

/// Turns every GPU-instanced node that the scene placed into a parent of one child node per
/// instance (its mesh and the instance's transform); returns the child node of each (node,
/// instance).
pub(super) fn split_gpu_instances(
    gltf: &Gltf,
    root: &mut Value,
    scene: &Scene,
) -> Result<BTreeMap<(usize, u32), usize>> {
    let parents: std::collections::BTreeSet<usize> = scene
        .instances
        .iter()
        .filter(|i| i.gpu_instance.is_some())
        .map(|i| i.node)
        .collect();
    let mut child = BTreeMap::new();
    for &node in &parents {
        let locals = instancing::instances(gltf, node, usize::MAX)?.unwrap_or_default();
        let mesh = root["nodes"][node]["mesh"].clone();
        let name = root["nodes"][node]["name"].as_str().map(str::to_string);
        let mut children = Vec::with_capacity(locals.len());
        for (k, local) in (0u32..).zip(locals) {
            let mut n = json!({"mesh": mesh, "matrix": local.to_cols_array()});
            if let Some(name) = &name {
                n["name"] = json!(format!("{name} instance {k}"));
            }
            let nodes = array_mut(root, "nodes");
            nodes.push(n);
            child.insert((node, k), nodes.len() - 1);
            children.push(json!(nodes.len() - 1));
        }
        let parent = &mut root["nodes"][node];
        if let Some(p) = parent.as_object_mut() {
            p.remove("mesh");
            let kids = p.entry("children").or_insert_with(|| json!([]));
            if let Some(kids) = kids.as_array_mut() {
                kids.extend(children);
            }
        }
        remove_extension(parent, instancing::NAME);
    }
    let still_used = root["nodes"]
        .as_array()
        .into_iter()
        .flatten()
        .any(|n| n["extensions"].get(instancing::NAME).is_some());
    if !still_used {
        undeclare(root, instancing::NAME);
    }
    Ok(child)
}

/// Removes extension `name` from an object's `extensions`, and `extensions` when it becomes
/// empty.
fn remove_extension(object: &mut Value, name: &str) {
    let Some(o) = object.as_object_mut() else {
        return;
    };
    if let Some(ext) = o.get_mut("extensions").and_then(Value::as_object_mut) {
        ext.remove(name);
        if ext.is_empty() {
            o.remove("extensions");
        }
    }
}

/// Removes extension `name` from `extensionsUsed` and `extensionsRequired`, and either list
/// when it becomes empty.
fn undeclare(root: &mut Value, name: &str) {
    for key in ["extensionsUsed", "extensionsRequired"] {
        if let Some(list) = root.get_mut(key).and_then(Value::as_array_mut) {
            list.retain(|e| e != name);
            if list.is_empty()
                && let Some(o) = root.as_object_mut()
            {
                o.remove(key);
            }
        }
    }
}
