//! Mixed lighting: how each light goes into the bake, as Unity's light modes and Godot's
//! per-light bake mode say it.
//!
//! * `bake: all` (the default): the light's direct light and its bounces are in the lightmap.
//! * `bake: indirect`: only its bounces. The engine draws the light's direct part (and its
//!   specular) in real time.
//! * `bake: none`: not baked at all (a light only for moving objects). It neither lights nor
//!   casts discontinuities; its surface still reflects.
//! * `group: NAME`: the light's contribution (as its `bake` says) is also written as a lightmap
//!   layer of its own, per group, that a game scales at run time (a flickering lamp, a switch).
//!   The main lightmap holds every group at scale 1, so a client that knows no layers shows the
//!   bake as it is: scaling group `g` by `f` adds `(f - 1) x layer_g`.
//!
//! Radiosity is linear in the emitters' power, so the layers are exact: each group's direct
//! light is computed alone, and its bounces with the links the whole bake refined
//! ([`crate::solve::hierarchical`]).
//!
//! A light's rule comes from, most specific last (each overrides the ones before):
//! 1. the `extras` of its `KHR_lights_punctual` light, or of its emissive material:
//!    `{"penumbra_bake": "indirect", "penumbra_group": "lamps"}` (Blender exports custom
//!    properties as `extras`);
//! 2. the `extras` of the node that places it;
//! 3. the command line: `--light-bake PATTERN=MODE` and `--light-group PATTERN=NAME`, where
//!    `PATTERN` matches the light's, its node's or its material's name (`*` matches any run of
//!    characters), in the order given.
//!
//! The sky (`--sky`) is always baked fully, in no group.

use super::{Instance, Scene};
use crate::error::{Error, Result};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;

/// How a light goes into the bake (`penumbra_bake`, `--light-bake`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum BakeMode {
    /// Direct light and bounces.
    #[default]
    All,
    /// Bounces only: the engine adds the direct light in real time.
    Indirect,
    /// Not baked.
    None,
}

impl BakeMode {
    /// `all`, `indirect` or `none`.
    pub(crate) fn from_name(name: &str) -> Option<BakeMode> {
        match name {
            "all" => Some(BakeMode::All),
            "indirect" => Some(BakeMode::Indirect),
            "none" => Some(BakeMode::None),
            _ => None,
        }
    }
}

/// One light's rule.
#[derive(Clone, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) struct LightRule {
    pub(crate) bake: BakeMode,
    /// The layer it is also written to; `None`: only the main lightmap.
    pub(crate) group: Option<String>,
}

/// The rules of a scene's lights: per punctual light (as [`Scene::lights`]) and per instance
/// (for the area emitters among its polygons). Empty: every light `all`, in no group.
#[derive(Clone, Debug, Default)]
pub(crate) struct Mixed {
    pub(crate) lights: Vec<LightRule>,
    pub(crate) instances: Vec<LightRule>,
}

/// A command-line rule: lights whose name matches `pattern` get `bake` or `group`.
#[derive(Clone, Debug, PartialEq)]
pub struct CliRule {
    pub(crate) pattern: String,
    pub(crate) bake: Option<BakeMode>,
    pub(crate) group: Option<String>,
}

impl CliRule {
    /// Parses `PATTERN=MODE` (`--light-bake`).
    pub fn bake(text: &str) -> std::result::Result<CliRule, String> {
        let (pattern, mode) = split_rule(text)?;
        let mode = BakeMode::from_name(mode)
            .ok_or_else(|| format!("{mode:?} is not a bake mode: all, indirect or none"))?;
        Ok(CliRule {
            pattern: pattern.into(),
            bake: Some(mode),
            group: None,
        })
    }

    /// Parses `PATTERN=NAME` (`--light-group`).
    pub fn group(text: &str) -> std::result::Result<CliRule, String> {
        let (pattern, name) = split_rule(text)?;
        check_group(name)?;
        Ok(CliRule {
            pattern: pattern.into(),
            bake: None,
            group: Some(name.into()),
        })
    }
}

fn split_rule(text: &str) -> std::result::Result<(&str, &str), String> {
    match text.rsplit_once('=') {
        Some((p, v)) if !p.is_empty() && !v.is_empty() => Ok((p, v)),
        _ => Err(format!("{text:?}: expected PATTERN=VALUE")),
    }
}

/// Group names are written into the file's JSON and shown in messages: 1 to 64 characters,
/// letters, digits, `-`, `_`, `.` and spaces.
fn check_group(name: &str) -> std::result::Result<(), String> {
    let ok = (1..=64).contains(&name.chars().count())
        && name
            .chars()
            .all(|c| c.is_alphanumeric() || matches!(c, '-' | '_' | '.' | ' '));
    if ok {
        Ok(())
    } else {
        Err(format!(
            "group name {name:?} must be 1 to 64 letters, digits, '-', '_', '.' or spaces"
        ))
    }
}

/// True when `name` matches `pattern`, whose `*` matches any run of characters.
fn matches(pattern: &str, name: &str) -> bool {
    let parts: Vec<&str> = pattern.split('*').collect();
    if parts.len() == 1 {
        return pattern == name;
    }
    let (first, last) = (parts[0], parts[parts.len() - 1]);
    if !name.starts_with(first) || name.len() < first.len() + last.len() || !name.ends_with(last) {
        return false;
    }
    let mut rest = &name[first.len()..name.len() - last.len()];
    for part in &parts[1..parts.len() - 1] {
        match rest.find(part) {
            Some(at) => rest = &rest[at + part.len()..],
            None => return false,
        }
    }
    true
}

/// Overrides `rule` with an object's `extras` (`penumbra_bake`, `penumbra_group`); `item`
/// names the object in errors.
fn apply_extras(
    path: &Path,
    extras: &Value,
    item: &str,
    rule: &mut LightRule,
) -> Result<()> {
    let bad = |reason: String| Error::BadItem {
        path: path.into(),
        item: item.into(),
        reason,
    };
    if let Some(v) = extras.get("penumbra_bake") {
        rule.bake = v.as_str().and_then(BakeMode::from_name).ok_or_else(|| {
            bad(format!(
                "extras.penumbra_bake {v} is not a bake mode: \"all\", \"indirect\" or \"none\""
            ))
        })?;
    }
    if let Some(v) = extras.get("penumbra_group") {
        let name = v
            .as_str()
            .ok_or_else(|| bad(format!("extras.penumbra_group {v} is not a string")))?;
        check_group(name).map_err(|r| bad(format!("extras.penumbra_group: {r}")))?;
        rule.group = Some(name.into());
    }
    Ok(())
}

fn apply_cli(rules: &[CliRule], names: &[Option<&str>], rule: &mut LightRule) {
    for r in rules {
        if names.iter().flatten().any(|n| matches(&r.pattern, n)) {
            if let Some(b) = r.bake {
                rule.bake = b;
            }
            if let Some(g) = &r.group {
                rule.group = Some(g.clone());
            }
        }
    }
}

/// The rules of `scene`'s lights from the file's extras and `cli`, stored in `scene.mixed`;
/// then the lights with `bake: none` are taken out of the scene (punctual lights removed,
/// emitting surfaces made non-emitting: they still reflect). An error names the item whose
/// extras are not a rule. `json` is the glTF JSON of the file at `path`.
pub(crate) fn apply(path: &Path, json: &Value, scene: &mut Scene, cli: &[CliRule]) -> Result<()> {
    let node_name = |n: usize| json["nodes"][n]["name"].as_str();
    let mut lights = Vec::with_capacity(scene.lights.len());
    for l in &scene.lights {
        let mut rule = LightRule::default();
        let def = &json["extensions"]["KHR_lights_punctual"]["lights"][l.index];
        let item = format!("KHR_lights_punctual.lights[{}]", l.index);
        apply_extras(path, &def["extras"], &item, &mut rule)?;
        let node = format!("node {}", l.node);
        apply_extras(path, &json["nodes"][l.node]["extras"], &node, &mut rule)?;
        apply_cli(cli, &[Some(&l.name), node_name(l.node)], &mut rule);
        lights.push(rule);
    }
    let mut instances = Vec::with_capacity(scene.instances.len());
    for inst in &scene.instances {
        instances.push(instance_rule(path, json, inst, cli)?);
    }
    scene.mixed = Mixed { lights, instances };
    silence(scene);
    Ok(())
}

fn instance_rule(path: &Path, json: &Value, inst: &Instance, cli: &[CliRule]) -> Result<LightRule> {
    let mut rule = LightRule::default();
    let material = inst.gltf_material.map(|m| &json["materials"][m]);
    if let (Some(m), Some(i)) = (material, inst.gltf_material) {
        apply_extras(path, &m["extras"], &format!("material {i}"), &mut rule)?;
    }
    let node = &json["nodes"][inst.node];
    apply_extras(
        path,
        &node["extras"],
        &format!("node {}", inst.node),
        &mut rule,
    )?;
    let material_name = material.and_then(|m| m["name"].as_str());
    apply_cli(cli, &[node["name"].as_str(), material_name], &mut rule);
    Ok(rule)
}

/// Takes the `bake: none` lights out of the scene: punctual lights removed (with their rules),
/// the emitting polygons of `none` instances given non-emitting copies of their materials.
fn silence(scene: &mut Scene) {
    let mixed = &mut scene.mixed;
    let mut k = 0;
    scene.lights.retain(|_| {
        k += 1;
        mixed.lights[k - 1].bake != BakeMode::None
    });
    mixed.lights.retain(|r| r.bake != BakeMode::None);
    let mut dark: BTreeMap<usize, usize> = BTreeMap::new();
    for p in 0..scene.polygons.len() {
        let (inst, material) = (scene.polygons[p].instance, scene.polygons[p].material);
        let none = scene.mixed.instances.get(inst).map(|r| r.bake) == Some(BakeMode::None);
        if !none || !scene.materials[material].is_emitter() {
            continue;
        }
        let copy = *dark.entry(material).or_insert_with(|| {
            let mut m = scene.materials[material].clone();
            m.radiance = glam::DVec3::ZERO;
            scene.materials.push(m);
            scene.materials.len() - 1
        });
        scene.polygons[p].material = copy;
        for &t in &scene.polygons[p].triangles {
            scene.triangles[t].material = copy;
        }
        scene.instances[inst].emission = None;
    }
}

impl Mixed {
    /// True when every light is baked fully into the main lightmap alone.
    pub(crate) fn is_plain(&self) -> bool {
        self.lights
            .iter()
            .chain(&self.instances)
            .all(|r| *r == LightRule::default())
    }

    /// The rule of punctual light `l`.
    pub(crate) fn light(&self, l: usize) -> LightRule {
        self.lights.get(l).cloned().unwrap_or_default()
    }

    /// The rule of the area emitter on polygon `p`.
    pub(crate) fn polygon(&self, scene: &Scene, p: usize) -> LightRule {
        self.instances
            .get(scene.polygons[p].instance)
            .cloned()
            .unwrap_or_default()
    }

    /// The groups some light is in, sorted.
    pub(crate) fn groups(&self) -> Vec<String> {
        let mut g: Vec<String> = self
            .lights
            .iter()
            .chain(&self.instances)
            .filter(|r| r.bake != BakeMode::None)
            .filter_map(|r| r.group.clone())
            .collect();
        g.sort();
        g.dedup();
        g
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patterns_match_runs_of_characters() {
        assert!(matches("lamp", "lamp"));
        assert!(!matches("lamp", "lamp 2"));
        assert!(matches("lamp*", "lamp 2"));
        assert!(matches("*lamp", "street lamp"));
        assert!(matches("*", ""));
        assert!(matches("a*b*c", "axxbyyc"));
        assert!(!matches("a*b*c", "axxcyyb"));
        assert!(!matches("ab*ba", "aba"));
    }

    #[test]
    fn command_line_rules_are_checked() {
        assert_eq!(
            CliRule::bake("sun=indirect").unwrap().bake,
            Some(BakeMode::Indirect)
        );
        assert!(CliRule::bake("sun=direct").is_err());
        assert!(CliRule::bake("=none").is_err());
        assert_eq!(
            CliRule::group("lamp*=street lamps")
                .unwrap()
                .group
                .as_deref(),
            Some("street lamps")
        );
        assert!(CliRule::group("lamp*=a\"b").is_err());
        assert!(CliRule::group("lamp*=").is_err());
    }
}
