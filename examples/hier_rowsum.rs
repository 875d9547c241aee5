//! Debug: row sums of the hierarchical links with B = 1 on every element, against a ray-cast
//! estimate of the same quantity (the cosine-weighted fraction of each element's hemisphere
//! that sees a reflecting receiver): `cargo run --release --example hier_rowsum -- [scene.glb]
//! [tol] [budget]` (the furnace box when no scene is given). With `BAKE_LINKS=1` in the
//! environment, the links are about those a bake keeps instead (refined with the reflected
//! direct light, then with the bake's radiosities averaged per element, at the bake's limits),
//! so a shortfall of the bake's coarser links shows. `RES=n`: the bake's lightmap size (128
//! unless given); `RECEIVER_POLYGON=p`: the links gathered by the first element of polygon `p`
//! and by its ancestors, with their sources.
use glam::DVec3;
use penumbra::light::SurfacePoint;
use penumbra::solve::hierarchical::{Hierarchy, Limits, MAX_LINKS, PARTIAL_VISIBILITY, VARIATION};
use penumbra::solve::sky::Sky;
use penumbra::visibility::Visibility;
use penumbra::{BakeOptions, load};
use std::path::Path;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let gltf = match args.next() {
        Some(p) => load::read(Path::new(&p))?,
        None => load::from_bytes(
            penumbra::fixtures::furnace_box_with(0.5, 1.0),
            Path::new("f.glb"),
        )?,
    };
    let tol: f64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(3e-5);
    let budget: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(4000);
    let mut o = BakeOptions {
        budget: Some(budget),
        // `RES` in the environment: the lightmap size (a scene of many small polygons needs
        // more than 128 to pack its charts).
        resolution: Some(
            std::env::var("RES")
                .ok()
                .and_then(|r| r.parse().ok())
                .unwrap_or(128),
        ),
        ..Default::default()
    };
    if std::env::var("BAKE_LINKS").is_err() {
        o.solve.bounces = Some(0);
    } else {
        o.solve.hr_tolerance = tol;
    }
    let b = penumbra::bake(&gltf, &o, &|_, _, _| {})?;
    let vis = Visibility::new(&b.scene);
    let h = Hierarchy::build(&b.scene, &vis, &b.meshes, &b.solution.direct).unwrap();
    let ones = vec![DVec3::ONE; h.elements.len()];
    let bn = h.pull(&ones);
    let total: f64 = h.elements.iter().map(|e| e.area).sum();
    let links = if std::env::var("BAKE_LINKS").is_ok() {
        // The links a bake keeps: refined first with the reflected direct light, then again
        // with the full radiosity (the bake's own vertex irradiance), at the bake's limits.
        let full = Hierarchy::build(&b.scene, &vis, &b.meshes, &b.solution.irradiance).unwrap();
        let (reflected, initial) = h.reflected_direct();
        let (radiosity, _) = full.reflected_direct();
        let limits = Limits::of_bake(tol, initial, total, h.mean_direct());
        let first = h.link(&vis, &h.sources(&reflected), limits).links;
        h.relink(&vis, &first, &h.sources(&radiosity), limits, true)
            .links
    } else {
        let limits = Limits {
            power: tol * total,
            variation: VARIATION,
            source: 1.0,
            visibility: PARTIAL_VISIBILITY,
            lit: 0.0,
            max_links: MAX_LINKS,
        };
        h.link(&vis, &h.sources(&ones), limits).links
    };
    let got = h.push(&h.gather(&links, &bn));
    // `RECEIVER_POLYGON=p`: the links gathered by the first element of polygon `p` and by its
    // ancestors (debug).
    if let Some(poly) = std::env::var("RECEIVER_POLYGON")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
        && let Some(e) = h.elements.iter().position(|e| e.polygon == poly)
    {
        let leaf = h.leaf[e];
        let covers =
            |n: &penumbra::solve::hierarchical::Node| (n.lo as usize..n.hi as usize).contains(&e);
        let mut sum = 0.0;
        for l in &links {
            let r = &h.nodes[l.receiver as usize];
            if !covers(r) {
                continue;
            }
            let s = &h.nodes[l.source as usize];
            sum += l.k;
            // The element's own transfer from the source's elements: exact form factors
            // from its centroid, one shadow ray per source element.
            let el = &h.elements[e];
            let c = (el.p[0] + el.p[1] + el.p[2]) / 3.0;
            let at = SurfacePoint::new(c, el.normal, el.polygon, &vis);
            let mut exact = 0.0;
            for src in &h.elements[s.lo as usize..s.hi as usize] {
                let f = penumbra::geometry::point_polygon_form_factor(c, el.normal, &src.p);
                let cs = (src.p[0] + src.p[1] + src.p[2]) / 3.0;
                let from = SurfacePoint::new(cs, src.normal, src.polygon, &vis);
                if f > 0.0
                    && src.normal.dot(c - cs) > 0.0
                    && !vis.occluded_skipping(
                        at.ray_origin,
                        from.ray_origin,
                        [el.polygon, src.polygon],
                    )
                {
                    exact += f;
                }
            }
            if (exact - l.k).abs() < 2e-3 {
                continue;
            }
            println!(
                "  link {} <- {}: receiver polygon {} ({} elements), source polygon {} ({} elements, area {:.2}, centre {:.2}), k {:.4}",
                l.receiver,
                l.source,
                r.polygon as i64,
                r.hi - r.lo,
                s.polygon as i64,
                s.hi - s.lo,
                s.area,
                s.center,
                l.k
            );
            println!("      the element's own: {exact:.4}");
        }
        println!("  element {e} (leaf {leaf}): sum of k {sum:.4}");
    }
    // Reflecting receivers: the polygons of the hierarchy with reflectance.
    let mut reflects = vec![false; b.scene.polygons.len()];
    for e in &h.elements {
        reflects[e.polygon] |= e.rho.max_element() > 0.0;
    }
    // Ray-cast estimate per element: the sky's stratified cosine-weighted directions from the
    // centroid.
    let sky = Sky::new(&b.scene, DVec3::ONE, 1024).expect("a sky");
    let mut per_poly: std::collections::BTreeMap<usize, (f64, f64, f64)> = Default::default();
    let (mut worst, mut sum_h, mut sum_r) = (Vec::new(), 0.0, 0.0);
    for (e, g) in h.elements.iter().zip(&got) {
        let c = (e.p[0] + e.p[1] + e.p[2]) / 3.0;
        let at = SurfacePoint::new(c, e.normal, e.polygon, &vis);
        let r = sky.hit_fraction(&vis, &at, |t, d| {
            let t = &b.scene.triangles[t];
            t.polygon.is_some_and(|p| reflects[p]) && t.normal.dot(d) < 0.0
        });
        let entry = per_poly.entry(e.polygon).or_default();
        entry.0 += e.area * g.x;
        entry.1 += e.area * r;
        entry.2 += e.area;
        sum_h += e.area * g.x;
        sum_r += e.area * r;
        worst.push(((g.x - r).abs(), e.polygon, c, g.x, r));
    }
    println!(
        "links {}: area-weighted row sum {:.4}, ray-cast {:.4}",
        links.len(),
        sum_h / total,
        sum_r / total
    );
    for (p, (hs, rs, a)) in &per_poly {
        println!(
            "  polygon {p}: normal {:.2} row sum {:.4} ray-cast {:.4}",
            b.scene.polygons[*p].frame.n,
            hs / a,
            rs / a
        );
    }
    worst.sort_by(|a, b| b.0.total_cmp(&a.0));
    for w in worst.iter().take(8) {
        println!(
            "  worst: polygon {} at {:.3}: row sum {:.4} ray-cast {:.4}",
            w.1, w.2, w.3, w.4
        );
    }
    Ok(())
}
