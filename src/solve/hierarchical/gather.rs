//! Gather and push-pull: the irradiance every node gathers along its links, pushed down to the
//! elements; the radiosities pulled up to the nodes, and their gradients across surface nodes.

use super::REGULARIZATION;
use super::refine::Link;
use super::transfer::{WHITE, tinted};
use super::tree::Hierarchy;
use crate::light::NO_POLYGON;
use glam::{DMat3, DVec3};
use rayon::prelude::*;

/// The gradient of an RGB quantity in space: per axis `x, y, z`, the change of each channel
/// per scene unit.
pub(crate) type Gradient = [DVec3; 3];

/// The change `g · d` over the displacement `d` (scene units).
fn along(g: &Gradient, d: DVec3) -> DVec3 {
    g[0] * d.x + g[1] * d.y + g[2] * d.z
}

/// `a bᵀ`.
fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}
impl Hierarchy {
    /// Irradiance gathered by every node along `links` (sorted by receiver) from the node
    /// radiosities `b` (W/m²), each source taken as uniform.
    pub fn gather(&self, links: &[Link], b: &[DVec3]) -> Vec<DVec3> {
        self.gather_linear(links, b, &[])
    }

    /// [`Hierarchy::gather`] with the sources' radiosity gradients `g` (per node, empty for
    /// none, see [`Hierarchy::gradients`]): a link gathers its source's radiosity at the
    /// link's `toward` offset from the source's centre (kept within zero and twice the mean),
    /// not its mean.
    pub fn gather_linear(&self, links: &[Link], b: &[DVec3], g: &[Gradient]) -> Vec<DVec3> {
        self.gather_clamped_as(links, b, g, None)
    }

    /// [`Hierarchy::gather_linear`] of one part of a radiosity whose whole is `whole` (its node
    /// radiosities and gradients; `None`: `b` and `g` are the whole): each link's gradient
    /// term is scaled, per channel, as the clamp scales the whole's, so that the parts' gathers
    /// add up to the whole's exactly (the clamp alone is not linear).
    pub(crate) fn gather_clamped_as(
        &self,
        links: &[Link],
        b: &[DVec3],
        g: &[Gradient],
        whole: Option<(&[DVec3], &[Gradient])>,
    ) -> Vec<DVec3> {
        let mut starts = Vec::new();
        for (i, l) in links.iter().enumerate() {
            if i == 0 || links[i - 1].receiver != l.receiver {
                starts.push(i);
            }
        }
        starts.push(links.len());
        let sums: Vec<(u32, DVec3)> = starts
            .par_windows(2)
            .map(|w| {
                let group = &links[w[0]..w[1]];
                let h = group
                    .iter()
                    .map(|l| {
                        let s = l.source as usize;
                        let b = match g.get(s) {
                            Some(g) if l.toward != [0.0; 3] => {
                                let t = DVec3::from(l.toward.map(f64::from));
                                match whole {
                                    None => (b[s] + along(g, t)).clamp(DVec3::ZERO, 2.0 * b[s]),
                                    Some((bw, gw)) => {
                                        let e = along(&gw[s], t);
                                        let kept =
                                            (bw[s] + e).clamp(DVec3::ZERO, 2.0 * bw[s]) - bw[s];
                                        let scale = DVec3::select(
                                            e.cmpeq(DVec3::ZERO),
                                            DVec3::ONE,
                                            kept / e,
                                        );
                                        b[s] + scale * along(g, t)
                                    }
                                }
                            }
                            _ => b[s],
                        };
                        if l.tint == WHITE {
                            b * l.k
                        } else {
                            b * l.k * tinted(l.tint)
                        }
                    })
                    .sum::<DVec3>();
                (group[0].receiver, h)
            })
            .collect();
        let mut h = vec![DVec3::ZERO; self.nodes.len()];
        for (r, v) in sums {
            h[r as usize] = v;
        }
        h
    }

    /// Push: every element's irradiance is what its leaf and all its ancestors gathered.
    pub fn push(&self, gathered: &[DVec3]) -> Vec<DVec3> {
        let mut acc = gathered.to_vec();
        for i in (0..self.nodes.len()).rev() {
            if let Some(kids) = self.nodes[i].kids {
                let v = acc[i];
                for k in kids {
                    acc[k as usize] += v;
                }
            }
        }
        self.leaf.iter().map(|&n| acc[n as usize]).collect()
    }

    /// The least-squares gradient of the radiosity across every surface node (zero for leaves
    /// and clusters): with `b` the node radiosities (from [`Hierarchy::pull`]) and `inverse`
    /// from [`Hierarchy::inverse_moments`], `inverse × Σ A_leaf B_leaf (x_leaf - center)` per channel.
    /// A first-order model of an uneven source: the part of a floor under a light, which the
    /// walls see most, is brighter than the floor's mean.
    pub fn gradients(&self, b: &[DVec3], inverse: &[DMat3]) -> Vec<Gradient> {
        // Per node, Σ over its elements of A B (x - center), per axis (RGB each).
        let mut s = vec![[DVec3::ZERO; 3]; self.nodes.len()];
        for i in 0..self.nodes.len() {
            let n = &self.nodes[i];
            if let (Some(kids), true) = (n.kids, n.polygon != NO_POLYGON) {
                let mut acc = [DVec3::ZERO; 3];
                for k in kids {
                    let (c, d) = (
                        &self.nodes[k as usize],
                        self.nodes[k as usize].center - n.center,
                    );
                    let ab = b[k as usize] * c.area;
                    for (a, (sk, dk)) in acc.iter_mut().zip(s[k as usize].iter().zip(d.to_array()))
                    {
                        *a += *sk + ab * dk;
                    }
                }
                s[i] = acc;
            }
        }
        s.iter()
            .zip(inverse)
            .map(|(s, m)| {
                // g[axis][channel] = Σ_j m[axis][j] s[j][channel].
                let mut g = [DVec3::ZERO; 3];
                for (axis, ga) in g.iter_mut().enumerate() {
                    for (j, sj) in s.iter().enumerate() {
                        *ga += *sj * m.col(j)[axis];
                    }
                }
                g
            })
            .collect()
    }

    /// Per node, the inverse of the second moment of its elements' centroids about its centre,
    /// area-weighted (`Σ A (x - c)(x - c)ᵀ`, scene units⁴), plus [`REGULARIZATION`] of its
    /// trace on the diagonal (a surface node is flat, so the moment is singular along the
    /// normal, and a strip of elements nearly so across it); zero for leaves
    /// and clusters. The elements are taken as points, each at its radiosity: they sample a
    /// smooth radiosity, whose gradient the fit recovers exactly where it is linear.
    pub fn inverse_moments(&self) -> Vec<DMat3> {
        let mut m = vec![DMat3::ZERO; self.nodes.len()];
        for i in 0..self.nodes.len() {
            if let Some(kids) = self.nodes[i].kids {
                let mut acc = DMat3::ZERO;
                for k in kids {
                    let (c, d) = (
                        &self.nodes[k as usize],
                        self.nodes[k as usize].center - self.nodes[i].center,
                    );
                    acc += m[k as usize] + outer(d, d) * c.area;
                }
                m[i] = acc;
            }
        }
        m.iter()
            .zip(&self.nodes)
            .map(|(m, n)| {
                if n.kids.is_none() || n.polygon == NO_POLYGON {
                    return DMat3::ZERO;
                }
                let tr = m.x_axis.x + m.y_axis.y + m.z_axis.z;
                let r = *m + DMat3::IDENTITY * (REGULARIZATION * tr);
                if tr > 0.0 && r.determinant().abs() > 0.0 {
                    r.inverse()
                } else {
                    DMat3::ZERO
                }
            })
            .collect()
    }

    /// Pull: every node's radiosity is the area-weighted mean of its elements' `b_elements`.
    pub fn pull(&self, b_elements: &[DVec3]) -> Vec<DVec3> {
        let mut b = vec![DVec3::ZERO; self.nodes.len()];
        for (e, &n) in self.leaf.iter().enumerate() {
            b[n as usize] = b_elements[e];
        }
        for i in 0..self.nodes.len() {
            if let Some([x, y]) = self.nodes[i].kids {
                let (a, c) = (&self.nodes[x as usize], &self.nodes[y as usize]);
                let area = a.area + c.area;
                b[i] = if area > 0.0 {
                    (b[x as usize] * a.area + b[y as usize] * c.area) / area
                } else {
                    DVec3::ZERO
                };
            }
        }
        b
    }

    /// Every element's reflected direct radiosity `rho H_direct` (W/m²), and the power it
    /// carries (W, mean over RGB): what the indirect solve starts from.
    pub fn reflected_direct(&self) -> (Vec<DVec3>, f64) {
        let b: Vec<DVec3> = self.elements.iter().map(|e| e.rho * e.direct).collect();
        let power = self
            .elements
            .iter()
            .zip(&b)
            .map(|(e, b)| e.area * b.element_sum() / 3.0)
            .sum();
        (b, power)
    }
}
