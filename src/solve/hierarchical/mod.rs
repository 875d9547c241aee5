//! The indirect light by hierarchical radiosity with clustering (`--solver hierarchical`).
//!
//! Papers: Hanrahan, Salzman, Aupperle, "A rapid hierarchical radiosity algorithm", SIGGRAPH
//! 1991 (links between nodes of a hierarchy, refined by a `B F A` oracle; gather, push-pull);
//! Lischinski, Tampieri, Greenberg, "Combining hierarchical radiosity and discontinuity
//! meshing", SIGGRAPH 1993 (the leaves are the discontinuity mesh's elements, so no link ever
//! averages across a shadow boundary or a contact); Smits, Arvo, Greenberg, "A clustering
//! algorithm for radiosity in complex environments", SIGGRAPH 1994, and Sillion, "A unified
//! hierarchical algorithm for global illumination with scattering volumes and object
//! clusters", IEEE TVCG 1995 (clusters of surfaces above the polygons, so the number of links
//! grows with the number of elements, not its square).
//!
//! # Why
//!
//! The progressive solver gathers every coarse patch at every mesh vertex: O(vertices ×
//! patches) rays, and a patch that straddles a contact averages its dark and lit parts. Here
//! light moves along *links* between nodes of a hierarchy, each link as coarse as the power it
//! carries allows: distant or dim exchanges use one link between two clusters, bright close
//! ones go down to single mesh elements. The leaves are the receiver mesh's triangles, which
//! never cross a discontinuity or contact line, so the finest links resolve exactly what the
//! mesher resolved.
//!
//! # Hierarchy
//!
//! * **Leaves**: the triangles of every [`ReceiverMesh`] (one *element* each), with their
//!   direct irradiance = the mean of their three vertices' exact direct values. An element
//!   that faces only the inside of closed geometry (the floor under a box standing on it: all
//!   of nine fixed rays from its centroid hit the back of a surface) is left out: no light
//!   reaches it and no one sees it, and as part of a coarse source it would dilute that
//!   source's mean radiosity.
//! * **Surface nodes**: per receiver polygon, a binary tree of its elements, split at the
//!   median element centroid along the longer axis of their bounding box in the polygon's 2D
//!   frame. A surface node lies in one plane and has that plane's normal.
//! * **Clusters**: above the polygons' roots, a top-down median split of the polygons' 3D
//!   bounding-box centres along the longest axis, up to one root.
//!
//! Every node stores its area (scene units²), area-weighted reflectance, bounding box, centre
//! (area-weighted centroid) and bounding radius about the centre. Nodes are numbered children
//! before parents, and each covers a contiguous range of elements.
//!
//! # Links and the transport coefficient
//!
//! A link `r ← s` carries a transport coefficient `K` (dimensionless): the mean irradiance it
//! adds over the receiver node `r` per unit radiosity of the source node `s`, i.e. the
//! area-averaged form factor `F(r→s)`, with visibility. So `H_r += K B_s` (W/m²), and the link
//! carries the power `K B_s A_r` (W).
//!
//! `K` is estimated from up to four fixed sample points per node (a leaf: its centroid and the
//! midpoints between centroid and corners; a larger node: the centroids of the elements at the
//! 1/8, 3/8, 5/8, 7/8 positions of its range):
//!
//! * **Surface to surface** (both nodes in one plane each): the exact unoccluded
//!   point-to-polygon form factor (Lambert's contour formula) from each receiver sample to the
//!   source (the disk formula below, about the source's centre, once the sample is more than
//!   [`FAR_FIELD`] bounding radii away), averaged over the receiver samples, times the visible fraction of the 4 × 4
//!   sample pairs. When the source's bounding box is above the sample's horizon the contour
//!   sum runs over the source node's *outline* only (its element edges whose reverse is not in
//!   the node: interior edges cancel in the contour sum), so a large source costs its boundary,
//!   not its area (collinear runs of outline edges are merged into one: a straight edge's term
//!   is the sum of its pieces'); a source straddling the horizon with at most `CONTOUR_ELEMENTS` elements is
//!   summed per element, each clipped to the horizon ([`point_polygon_form_factor`](crate::geometry::point_polygon_form_factor)); a larger
//!   straddling source falls to the disk estimate below.
//! * **Otherwise** (either end a cluster, or a large straddling source): per sample pair `(i, j)` the disk
//!   approximation `A_s cos_i cos_j / (π d_ij² + A_s)` (exact on the axis of a disk of area
//!   `A_s`), with `cos` taken at each end from that sample's own element normal and clamped at
//!   zero, times the pair's visibility, averaged over the pairs. At a cluster end this is a
//!   *sampled* orientation model rather than Sillion's isotropic one (the isotropic model
//!   replaces the cosine at a cluster end by 1/4, the mean of `max(cos, 0)` over the sphere):
//!   the samples are surfaces of the cluster, so a cluster whose surfaces face away from the
//!   other end neither sends nor receives. The irradiance a cluster receives is then pushed
//!   unchanged to all its surfaces (the cluster's mean irradiance), whichever way each faces:
//!   that is where a cluster link is coarse, and why the oracle below bounds the power such a
//!   link may carry and the irradiance it may bring to a cluster (see "Cluster receivers").
//!
//! Visibility: one shadow ray per sample pair with `cos > 0` at both ends
//! ([`Visibility::occluded_skipping`] between the two points' ray origins, each offset off its
//! surface like [`SurfacePoint::new`](crate::light::SurfacePoint::new), skipping the two points' own polygons), in two stages:
//! first the pairs `(k mod 4, k mod 4)`, one per sample; when at least two are tested and all
//! agree (all visible or all hidden), the other pairs are taken to agree too, else every pair
//! is cast (a surface-to-surface link whose first pairs disagree is settled by them alone, see
//! "Partial visibility" below). Most links are wholly visible, so this casts about half the
//! rays: on the 20x20 box grid 6.9 M instead of 12.2 M (measured before partially visible
//! links were refined, below), with the same error against the Monte Carlo reference in every
//! region (and on the Cornell box). Deterministic points, no randomness.
//!
//! Pairs that carry nothing are never linked: two nodes of one plane (a planar polygon does not
//! see itself), a source whose bounding box lies behind (or in) a surface receiver's plane, a
//! receiver whose box lies behind a surface source's plane, and sources of zero reflectance
//! (their indirect radiosity is always zero; their emission is in the direct light).
//!
//! # Refinement
//!
//! From the root-to-root link, a link `r ← s` is refined while any test of the oracle fails:
//!
//! * **Power** (Hanrahan et al.'s `B F A`): the bound `B_s K̂ A_r` on the power the link
//!   carries exceeds `hr_tolerance × P`, where `P` is the total reflected direct power (W, the
//!   power the indirect solve starts from). For surface-to-surface links `K̂` is the
//!   unoccluded `K` (a partially visible link has its shadow unresolved, so the whole
//!   unoccluded transfer is at stake; a wholly visible one has `K` = the unoccluded `K`). For
//!   links with a cluster end the four samples may miss the surfaces that matter, so the
//!   power is bounded geometrically: `K̂ = min(A_s / (π g² + A_s), (R_s / d)²)`, the point form
//!   factor with both cosines bounded by 1 (`g` the smallest possible distance between the
//!   nodes' bounding spheres, 0 when they overlap) and the projected solid angle of the
//!   source's bounding sphere (radius `R_s`, at least `d` away); and by reciprocity
//!   (`A_r F(r→s) = A_s F(s→r)`) the power is also at most `A_s` times the same bound seen
//!   from the source, so a large ground plane beside a small cluster is bounded by what the
//!   cluster sends. Where the spheres are apart, also by the nodes' orientations: every pair's
//!   direction lies in the cone between the two spheres, and each node stores its projected
//!   area along the six axis directions, so `A_r F(r→s) ≤ P_r P_s / (π g²)` with `P` the most
//!   projected area a node can show along the cone ([`projected_bound`](transfer::projected_bound)); this cut the
//!   refinements by 16% on the 20x20 box grid and 19% on the 40x40 (neighbouring clusters of
//!   boxes, whose faces mostly do not face each other). So `--hr-tolerance` is the largest fraction of the reflected direct power
//!   one link may carry (dimensionless); the variation, source and visibility limits below
//!   scale with it from its default ([`Limits::of_bake`]: see "The tolerance as a dial"). The
//!   node of larger area that has children is split.
//! * **Variation** (the receiver-side test of Lischinski, Tampieri, Greenberg 1993 and
//!   Holzschuch, Sillion, "An exhaustive error-bounding algorithm for hierarchical radiosity",
//!   CGF 1998, with the sample spread in place of their analytic bounds): for a
//!   surface-to-surface link, `B_s (f_max − f_min)`, the spread of the unoccluded
//!   point-to-source form factors `f` at the receiver's sample points times the source
//!   radiosity (W/m²), exceeds [`VARIATION`] × `P / A` (the mean reflected direct radiosity,
//!   `A` the total area). The receiver is split. Without this test a coarse receiver's `K`
//!   is pushed unchanged to elements whose true `K` differs (measured on the furnace box: row
//!   sums of `K` per element from 0.84 to 1.25 at `hr_tolerance` 1e-5; with it, within 6e-4
//!   of 1 at 1e-4). [`VARIATION`] is 2e-3, the largest at which the furnace holds to 1e-3 at
//!   every vertex with the vertex values below (9.1e-4; at 3e-3, 1.5e-3 at the box's edges,
//!   which the mean of the elements around a vertex used to hide: 1e-3 was the limit's old
//!   rule); against 3e-3 it costs 7-13% more rays on box-grid-20 and a 13 000-triangle town.
//!   A receiver whose bounding box reaches across a surface source's plane while all its
//!   samples lie behind it (a floor node past the corner of a box, across the plane of the
//!   box's side face) is split too while `B_s` times the geometric bound on its form factor
//!   ([`point_bound`](transfer::point_bound)) is over the limit: its part in front still sees the source. (Splitting
//!   every receiver across a source's plane by that bound cost 74% more refinements on Bevy's
//!   Cornell box for the same error on ours; with a sample in front, the variation test
//!   decides on the samples' own values.) The source's coarseness needs no such
//!   test: the contour formula is exact for the whole source from each receiver point. A large surface source straddling the
//!   receiver's horizon (estimated by the disk formula, crude at a contact) is split while
//!   `B_s K̂` exceeds the same limit.
//! * **Cluster receivers**: a cluster pushes the irradiance it gathers unchanged to all its
//!   surfaces, so across them the link's irradiance varies by up to `B_s K̂` (a sill's top
//!   and its bottom take the same light from the street, where the top sees none of it), `K̂`
//!   the geometric bound ([`point_bound`](transfer::point_bound)). The receiver is split while that is over the
//!   variation limit: the variation test, with the bound in place of the samples' spread (four
//!   samples cannot show a cluster's orientations). The power test alone left clusters of
//!   small surfaces receiving as a whole (their power is small), and each of their many small
//!   links under every limit. Measured on a town with a sill under every window
//!   ([`crate::fixtures::ladder::sill_town`], 2 500 triangles, `tests/it/hierarchical.rs`),
//!   what the sills' faces gather from the bake's own radiosity against a brute-force gather
//!   (within 7% of the path tracer's indirect light at their centroids): the faces looking down
//!   gathered 46% too little, up 21% too much, sideways 20% too little; with this test, within
//!   2%. (With the source limit in its place, the ten times looser one: 24% too little, 20% too
//!   much, 14% too little.) Against the path tracer at the vertices (`examples/hier_compare.rs`
//!   with `REFERENCE`, RMSE of the vertex irradiance as a fraction of the reference's mean,
//!   buried vertices left out; 1 024 paths at about 1 700 vertices; before → after, and the
//!   progressive solver's): sill-town-13k 22.0% → 13.5% (bias -8.3% → -1.8%; progressive
//!   23.7%), town-13k 6.6% → 5.9% (progressive 12.0%), interior-20 17.5% → 16.6%
//!   (progressive 39.6%), box-grid-20 10.4% → 10.4% (progressive 21.6%), Bevy's
//!   DepthOfField example 7.3% → 4.0% (bias -1.6% → -0.1%; progressive 27.0%). It costs
//!   solve time where clusters of surfaces facing many ways receive much light (the ladder's
//!   solve, docs/bench-ladder.md, before and after back to back): sill-town-13k 1.15 →
//!   2.07 s (links 0.80 M → 1.39 M), interior-20 4.5 → 6.9 s, town-100k 6.0 → 8.9 s,
//!   box-grid-40 3.0 → 4.4 s, box-grid-20 +16%, the other towns +9-18%; box-grid-20's solve
//!   is still 5.1-5.2x faster than progressive's (two runs of `examples/hier_compare.rs`),
//!   town-13k's 1.9x. The Cornell box's links are the same (its 16 clusters receive
//!   nothing this test refines).
//! * **Source uniformity**: a link gathers `K B̄_s`, the source's *mean* radiosity, so it
//!   misplaces up to `ΔB_s K̂`, with `ΔB_s` the spread of the source's element radiosities and
//!   `K̂` the largest point form factor at the receiver's samples (the geometric bound for a
//!   cluster end). The source is split while that exceeds [`SOURCE_VARIATION`] × `P / A`.
//!   This is not noise but a bias: the parts of a source that face a receiver most directly
//!   are usually its brightest too (the middle of a floor under a ceiling light), so the mean
//!   underestimates. Measured on the Cornell box against the Monte Carlo reference: without
//!   this test the bake's RMSE was 7.5% of the lit mean (mean indirect light 12% low); with it
//!   at 0.1, 3.0%; at 0.03, 1.9%. The same bias has the other sign in shadow: a receiver that
//!   the direct light does not reach sees most the nearby parts of its sources, which share
//!   its shadow and are darker than the source's mean, and all its light is this indirect
//!   light. So the limit is scaled per receiver by its brightest element's direct irradiance
//!   against the elements' mean ([`Limits::source_at`]), down to [`SHADOWED_SOURCE`] (0.3)
//!   where none arrives. On the Cornell box (`penumbra compare`'s measure, 15 554 elements)
//!   the umbra read 0.25% of the lit mean too bright with one limit (RMSE 0.43%, progressive
//!   0.24%), 0.04% too dark with the scaled one (RMSE 0.22%); against a brute-force gather of
//!   the bake's own radiosity, the shadowed floor's links gathered 0.75% too much, now 0.07%
//!   too little (`tests/it/hierarchical.rs`). At 0.1 instead of 0.3: 0.11% too dark, RMSE
//!   0.28%, for more links. It costs 7-9% more links on the box grids and 22-32% on the sunlit
//!   towns (whose shadowed ground and walls are large), 10-37% more solve time; on town-6k the
//!   error against the reference did not move measurably (its umbra's error is the texel
//!   resolution of the direct light). Scaling the power tolerance the same way instead changed
//!   the umbra's bias by 0.03% of the lit mean.
//! * **Partial visibility** (the "refined where it is partial"): a surface-to-surface
//!   link whose tested sample pairs disagree (some see each other, some do not) is split at
//!   its larger node while `B_s K_unoccluded`, the irradiance its visible fraction decides,
//!   exceeds [`PARTIAL_VISIBILITY`] × `P / A`. Also a bias, not noise: the visible fraction
//!   weights the 16 pairs alike, but the pairs that see past an occluder are usually the near
//!   ones, of the larger form factor. Measured on the Cornell box (`examples/hier_rowsum.rs`,
//!   every element at `B = 1`, against ray casting): without this test the row sums of `K`
//!   were 2.1% short over all elements (the back wall's share of the floor, behind the two
//!   boxes, 30% short); with it they are 0.4% over, and the bake's RMSE against the Monte
//!   Carlo reference fell from 2.1% to 1.9% of the lit mean (indirect region 2.4% to 2.2%),
//!   for 10-25% more refinement time. A link whose `B_s K_unoccluded` is over the limit is
//!   split as soon as its first pairs (one per sample) disagree, without the other pairs' rays
//!   (10-12% fewer rays on box-grid-20 and town-6k, the same links). One under the limit is
//!   kept with the visible fraction of those first pairs: the irradiance its visibility
//!   decides is within the limit anyway, and its other twelve pairs were most of the rays
//!   (on box-grid-20, 3.5 M of the 4.0 M that kept surface links cast). Casting them changed
//!   the error against the Monte Carlo reference by at most 0.01% of the lit mean in any
//!   region of the Cornell box (umbra 0.22% against 0.23%, penumbra 0.68% against 0.69%,
//!   indirect 0.49% against 0.50%) and town-6k, for 20% more rays on box-grid-20 (7.25 M
//!   against 5.79 M) and 11% more solve time. Only a link of two leaves over the limit (it
//!   cannot be split) casts all sixteen pairs.
//! * **Hidden, in doubt**: a link that the power, variation or source test would split but
//!   whose sixteen sample pairs are all hidden may still see past the occluder between them
//!   (a box's face and the wall behind the box). It is split like a partially visible link
//!   while `B_s K_unoccluded` exceeds the same limit, else kept as `K = 0`. It used to be
//!   dropped, and that was the Cornell box's remaining bias: the row sums of the links a bake
//!   keeps were 0.63% short of ray casting (now 0.22% over, `examples/hier_rowsum.rs` with
//!   `BAKE_LINKS=1`), which after the bounces made the indirect light 1.2% lower than the
//!   progressive solver's. Against the Monte Carlo reference (256 samples, 512² page) the lit
//!   region's RMSE went from 0.85% to 0.15% of the lit mean, all texels 1.15% to 0.78%; on
//!   interior-20 the absorbed power rose by 4%, the light that crossed doorways between
//!   rooms. It costs more rays: 12% on box-grid-40, 21-34% on the towns, 41% on interior-20
//!   (same mesh).
//!
//! A self-link of a cluster becomes the four links between its two children; a link between
//! two leaves is kept as it is. Only the shadow rays the decision needs are cast: none for a
//! link the geometric bound splits, and for a surface-to-surface link that will be split, none
//! when `B_s K_unoccluded` is over the partial-visibility limit (split whether hidden or not),
//! else rays only until the first visible pair (a wholly hidden link is split only when in
//! doubt, above). Skipping those rays cast 15% fewer on box-grid-20 and 22% fewer on a
//! 13 000-triangle town, for the same links and the same bytes out.
//!
//! `B_s` for the oracle: [`REFINE_PASSES`] passes. The first refines from the root with the
//! reflected direct light; the solution then gives every node its full radiosity (a node in
//! shadow has none at first), and the first pass's links are tested again with it (each link
//! stores its power and spread factors): those that now fail are refined further, the others
//! are kept without a new estimate; the system is then solved again from the start.
//!
//! # Solve
//!
//! Jacobi iterations (every receiver gathers from the previous iterate, in parallel with an
//! indexed collect, so the result does not depend on the thread count): gather along the links
//! into each node's irradiance, push it down to the leaves (a leaf's indirect irradiance is the
//! sum of what it and its ancestors gathered), `B_leaf = rho (H_direct + H_indirect)`, pull
//! back up (a node's radiosity is the area-weighted mean of its children's). Only the
//! *reflected* light moves: the emitters' direct light is already exact at the vertices.
//!
//! A link from a surface source gathers the source's radiosity where the receiver looks, not
//! its mean: every iteration fits each surface node a radiosity gradient (least squares over
//! its elements' centroids, [`Hierarchy::gradients`]), and the link, which stores where its
//! receiver looks (`toward`: the offset of the source samples' mean weighted by the
//! point-to-point kernel from the receiver's samples over the pairs that see each other,
//! [`seen_offset`](transfer::seen_offset); counting the hidden pairs too, the Cornell box's umbra read 0.45% of the
//! lit mean against 0.43%, indirect 0.56% against 0.52%), gathers `B̄_s + ∇B_s ·
//! toward`, kept within 0 and `2 B̄_s`. A first-order answer to the source-mean bias that the
//! source-uniformity test bounds: the part of the floor under the light, which the walls see
//! most, is brighter than the floor's mean. Uniform radiosity (the furnace) has no gradient,
//! so the furnace and the row sums are unchanged. Measured on the Cornell box against the
//! Monte Carlo reference (256 samples, 512² page): the bias in the lit region fell from 1.47%
//! to 0.69% of the lit mean (progressive: 0.17%), RMSE over all texels 1.93% to 1.15%, lit
//! 1.89% to 0.96%, indirect 2.10% to 1.03%, for no measurable solve time (box-grid-20 and
//! town-6k: the same error, 1e-4 apart).
//!
//! Converged when the power the last iteration added, `sum A |ΔB|` (mean over RGB), is below
//! `tolerance` of `P` (the progressive solver's rule: its unshot power), or after `bounces`
//! iterations when given (iteration `n` adds the `n`-th bounce).
//!
//! # Values at the vertices
//!
//! The solve gives each element its mean indirect irradiance; the lightmap interpolates values
//! at the vertices linearly. The value at a vertex is that of the linear function fitted (area-
//! weighted least squares) to the elements of its own mesh that use it, an element's mean of a
//! linear function being its value at the centroid; where those elements' centroids leave the
//! gradient undetermined (two triangles at a polygon's corner, whose centroids lie along the
//! edge), the elements that share a vertex with them are fitted instead. The value is kept
//! within the elements' values widened by their spread on each side, and at least zero. Then
//! one correction step: each vertex moves by the area-weighted mean of its elements' residuals
//! (element mean minus the mean of its three vertex values), so that the interpolated light
//! keeps each element's mean where the light peaks, which a linear fit through element means
//! flattens. A vertex split along a contact (one copy per side) is used only by the elements
//! of its side, so the sides stay separate. The direct light stays the exact vertex value.
//!
//! The mean of the elements around each vertex, used before, stands for a point a third of an
//! element inside the mesh at its edges, so at a concave corner (a floor beside a box, where
//! the light falls into the corner) it read the light of the element's middle. Measured on the
//! Cornell box against the Monte Carlo reference (1024 samples, `penumbra compare`'s 256² page,
//! 15 554 elements; RMSE as a fraction of the lit mean, all texels / lit / penumbra / umbra /
//! contact / indirect): the mean, 0.89 / 0.65 / 0.72 / 0.50 / 1.60 / 0.73%; the fit over the
//! elements using the vertex, 0.74 / 0.62 / 0.70 / 0.47 / 1.14 / 0.65%; with the sources' side
//! respected (`Hierarchy::point_factor`) and [`VARIATION`] at 2e-3, 0.72 / 0.61 / 0.69 / 0.39 /
//! 1.04 / 0.69%; with the wider fit at corners, 0.71 / 0.61 / 0.69 / 0.39 / 0.99 / 0.68%; with
//! the correction step, 0.66 / 0.59 / 0.69 / 0.45 / 0.92 / 0.56% (the umbra's elements are
//! about 1.4% too bright, and the step shows them as they are). At 1 986 elements, the last
//! two: all texels 3.20% to 2.73%, indirect 2.63% to 1.48%, umbra 0.94% to 0.60%. (These
//! steps split every receiver across a source's plane; as it is now, with `toward` over the
//! visible pairs: 0.65 / 0.59 / 0.69 / 0.43 / 0.92 / 0.53%.)
//!
//! # The tolerance as a dial
//!
//! `--hr-tolerance` sets the power limit, and the variation, source and visibility limits
//! scale with it from its default 3e-5 ([`Limits::of_bake`]): one option trades speed for
//! accuracy. With the power limit alone, 10x the default refined 10% fewer links on a
//! 13 000-triangle town (the other tests asked for the rest); with all four, 4.6x fewer.
//! Measured against the Monte Carlo reference (`examples/solver_error.rs`, RMSE as a
//! fraction of the lit mean, all texels / lit / umbra / contact / indirect; solve seconds),
//! both solvers in each run:
//!
//! | `--hr-tolerance` | Cornell box (1024 samples, 256² page) | solve s | town-6k (64 samples, 512² page) | solve s | town-13k solve s |
//! |---|---|--:|---|--:|--:|
//! | 3e-5 (default) | 0.63 / 0.58 / 0.23 / 0.88 / 0.50 | 1.29 | 3.77 / 3.71 / 4.56 / 5.05 / 0.70 | 0.56 | 0.75 (2.0x) |
//! | 1e-4 | 1.25 / 1.26 / 0.78 / 1.48 / 1.05 | 0.50 | 3.86 / 3.77 / 4.58 / 5.30 / 1.03 | 0.33 | |
//! | 3e-4 | 2.52 / 2.70 / 1.84 / 2.61 / 2.20 | 0.23 | 4.00 / 3.86 / 4.63 / 5.67 / 1.35 | 0.24 | 0.29 (5.1x) |
//! | 1e-3 | 5.16 / 5.35 / 2.59 / 5.96 / 4.47 | 0.11 | 4.27 / 4.06 / 4.78 / 6.16 / 1.95 | 0.13 | 0.21 (7.0x) |
//! | progressive | 2.15 / 0.61 / 0.24 / 4.74 / 1.70 | 0.82 | 4.79 / 3.94 / 5.19 / 7.54 / 3.36 | 0.64 | 1.49 |
//!
//! (town-13k: `examples/hier_compare.rs`, the ratio to progressive's solve in the same run.)
//! On the sunlit towns, whose error is mostly the texel resolution of the direct light, 3e-4
//! is still better than progressive in every region at 5x its speed (town-13k, 64 samples,
//! 512² page: 6.62 / 5.10 / 8.23 / 9.99 / 2.62 against 8.43 / 6.34 / 8.49 / 12.34 / 7.06);
//! the Cornell box, whose indirect light is a large part of what is seen, needs the default
//! to be no worse than progressive in any region (its lit region is 0.58% against 0.61%), and
//! that is why the default is 3e-5.
//!
//! At equal accuracy the town's speed-up is well past 5x. Progressive's accuracy comes with
//! more patches: on town-13k (one run against one reference, `examples/solver_error.rs` with
//! `PATCHES` and `TOLS`, 64 samples, 512² page, 20 092 elements; all / lit / umbra / contact /
//! indirect, solve seconds), progressive at 1024 patches (its default, 1 480 here) read 8.33 /
//! 6.28 / 9.57 / 12.82 / 7.08 in 1.28 s, at 4096 patches 6.74 / 5.03 / 9.35 / 11.12 / 2.41 in
//! 3.85 s, at 16384 patches 6.61 / 5.03 / 9.24 / 10.76 / 2.23 in 30.08 s; this solver at 3e-5
//! 6.49 / 5.11 / 9.22 / 10.28 / 1.89 in 0.61 s, at 1e-4 6.53 / 5.17 / 9.19 / 10.34 / 2.14 in
//! 0.31 s, at 3e-4 6.66 / 5.25 / 9.30 / 10.49 / 2.51 in 0.19 s. The lit region's error is the
//! direct light's texel resolution, which both share. (On the town with a sill under every
//! window, where progressive needs a patch per polygon, default against default: 8.7x.)
//!
//! # Status (measured on 2 shared cores, default options)
//!
//! Against the Monte Carlo reference (`examples/solver_error.rs`, `penumbra compare`'s error by
//! region, RMSE as a fraction of the mean lit irradiance):
//!
//! * Cornell box (`penumbra compare`'s 256² page, 4x4 sub-samples, 1024 samples per texel,
//!   15 554 elements): better than progressive in every region: all texels 0.63% against
//!   2.15%; lit 0.58% against 0.61%; penumbra 0.69% against 1.04%; umbra 0.23% against
//!   0.24%; contact 0.88% against 4.74% (largest texel error 10.0% against 37.0%); indirect
//!   0.50% against 1.70% (0.68%, 0.22% and 0.49% before kept links stopped at their first
//!   pairs' visibility, see "Partial visibility"). The umbra was 0.43% (a bias: its elements
//!   about 1.4% too bright, 0.25% of the lit mean) until the source limit was scaled by the
//!   receiver's direct light (see "Source uniformity"); before that it was traced to the
//!   sources: not the clusters
//!   (splitting every cluster end, source or receiver, moved it by 1e-4 of the lit mean), nor
//!   the row sums (right within 0.2% of ray casting on the shadowed floor), nor the power
//!   tolerance alone (+0.23% at 3e-5, +0.11% at 3e-6, for 15-43% more links). Before the
//!   vertex fit and the sources' side: all 0.89%, lit 0.65%, penumbra 0.72%, umbra 0.50%,
//!   contact 1.60%, indirect 0.73%. Solve 1.4x slower than progressive (1.3 s against
//!   0.9 s; 1.9 s before this session's link-phase changes), whose 1024 patches suit a
//!   36-triangle scene.
//! * box-grid-20 (1024² page, one sub-sample, 128 samples): better in every region: all
//!   texels 14.2% against 24.2%, indirect 4.0% against 17.9%, contact 19.1% against 30.5%,
//!   lit 9.9% against 23.8%; penumbra and umbra within 2.5% (their error is the texel
//!   resolution of the direct light both share). Solve 4.2-5.1x faster than progressive in
//!   six runs of `examples/hier_compare.rs` before the vertex fit (3.0 s against 14.0 s,
//!   3.5 s against 17.7 s, 2.5 s against 10.4 s, 3.1 s against 14.4 s, 2.6 s against 13.3 s);
//!   4.0x after it (2.78 s against 11.0 s), with 6% more rays; 4.1x (2.58 s against 10.6 s)
//!   since the split links cast no hidden-check rays (7.2 M rays instead of 8.5 M); 5.26x
//!   (1.12 s against 5.91 s; the previous code 4.37x in the same run) with the projected point
//!   bound, the reused contour sums and the first-pair visibility of kept links. Its mean
//!   indirect light at the vertices is 1.9x progressive's there, and right: progressive's
//!   coarse patches leave the lit region 17% of the lit mean too dark against the Monte Carlo
//!   reference (this solver: 4.7%).
//! * town-6k (64 samples): better in every region (indirect 0.48% against 2.5%, contact 4.3%
//!   against 6.5%); a 13 000 triangle town's solve 1.7-2.5x faster (1.4-1.7 s against
//!   2.8-3.7 s; 1.7x with hidden links split in doubt, 1.68x after the vertex fit, 1.83x
//!   with 3.1 M rays instead of 4.0 M: 1.73 s against 3.16 s; 1.97x now, 0.73 s against
//!   1.43 s, 3.0 M rays). Where its 414 000 links go (a census of the bake's links): 56% end
//!   on walls and 40% on up-facing surfaces (ground, roofs), 4% on clusters; 60% end on
//!   receivers in shadow (direct light under 0.2 of the mean), where all the light is this
//!   indirect light and the source limit is tightest; 98% start at a surface node or an
//!   element, 2% at a cluster. So the clusters are not what costs: the links between
//!   surfaces are (with the source-uniformity test off for cluster sources, 406 000 links
//!   instead of 413 000, the same time). Of the splits between surfaces, the source-uniformity
//!   test asks for two in three (the walls' and the ground's radiosity steps at the shadow
//!   lines); of those with a cluster end, the power bound asks for two in three. Tried, to
//!   reach 5x: bounding the source test by how much the point kernel varies over the source's
//!   bounding sphere (4% fewer links); testing the source's spread about its fitted gradient
//!   (which the gather applies) instead of about its mean (13% fewer links, 4% less solve
//!   time, but the Cornell box's lit region 0.63% and umbra 0.34% of the lit mean, worse than
//!   progressive's 0.61% and 0.24%); loosening every limit at receivers brighter than the
//!   mean direct light, by that ratio (8% fewer links). None is in. Each limit loosened 10x
//!   alone (town-13k speed-up in one `hier_compare` run, against 1.99x; Cornell box lit /
//!   umbra RMSE, against 0.58 / 0.23%): power 2.20x, 0.58 / 0.24%; variation 2.79x, 1.27 /
//!   1.19%; source 2.67x, 1.54 / 0.63%; visibility 2.20x, 1.06 / 1.15%. So no one limit is
//!   the town's cost, and only the power limit is free on the Cornell box (there its umbra
//!   reaches progressive's 0.24%). A first pass refined 4x or 16x looser (the second, at
//!   the full radiosity, refines what it left): 7-10% less link time, 7% fewer links, as the
//!   final pass's oracle decides most of them. Earlier, town-25k:
//!   indirect 2.7% against 6.0%.
//! * Scale ladder (`cargo bench --bench ladder`): every rung bakes; solve 5.9-7.4 s on the
//!   40x40 box grid (progressive: 375 s), 14-15 s on town-100k (147 863 elements;
//!   progressive: over 600 s).
//! * Furnace box: `B = M/(1-rho)` within 1e-3 at every vertex (9.1e-4 at `rho` 0.8).
//! * Values at vertices, tried: gathering each element's links at its corners (the point form
//!   factor at the corner times the link's visible fraction, instead of the element's mean)
//!   lowered every region's RMSE on the Cornell box by 3-14% but cost 25-35% more solve time
//!   (2.2 s on the Cornell box's million links), and did not change the worst case it was
//!   meant for (a box's wall base under the sky, below); it is not in. Also tried: a
//!   linear `K` per link (the least-squares gradient of its four receiver samples' point form
//!   factors, pushed down the hierarchy and extrapolated from each element's centroid to its
//!   vertices): RMSE on the Cornell box 1.79% to 1.71% of the lit mean, but the furnace's worst
//!   vertex off by 2.7% (the per-link gradients do not cancel at the box's edges); without the
//!   extrapolation to vertices it changed nothing (1.78%). Not in.
//! * Cornell box, what the lit-region error was: a bias, not noise. Against the Monte Carlo
//!   reference (64 samples) the bake was 1.45% of the lit mean low in the lit region, and
//!   about as low on every polygon (progressive: 0.19% low); its mean indirect irradiance at
//!   the vertices was 4% below progressive's, while the link coefficients' row sums at `B = 1`
//!   are right (0.4% over). [`SOURCE_VARIATION`] at 0.01 instead of 0.03 took the bias to
//!   1.15%, at 0.003 to 1.0% (for 2x the solve time); partial visibility at 0.1% and the
//!   variation limit at 3e-4 changed nothing, nor the power tolerance (1e-4 to 1e-5). Hence
//!   the sources' radiosity gradients (above), which halved it. What was left (0.7%): the row
//!   sums of the links the bake keeps were short, 0.832 against a ray-cast 0.837 (those of
//!   links refined at `B = 1` everywhere were not). Refining them further made it worse
//!   (0.826 at a 100x tighter power tolerance), which pointed at links dropped rather than
//!   links too coarse: the wholly hidden ones (above). Split when in doubt, the sums are
//!   0.839 and the lit region's bias 0.38% (progressive: 0.17%).
//! * Concave corners below one element: a box's wall under the sky, 0.05 m above the ground,
//!   reads 0.67 of `pi L` against the reference's 0.44-0.53 (`tests/it/sky.rs`): the light
//!   falls steeply into the corner within the wall's lowest element, and linear interpolation
//!   between its vertices cannot follow.
//! * Row sums of `K` (`examples/hier_rowsum.rs`, every element at `B = 1`, against a ray-cast
//!   estimate): 0.4% over on the Cornell box, since partially visible links are refined
//!   (above); 2.1% short before. Tried on the way and not the cause: weighting a node's four
//!   samples by the area they stand for, the contour sum at every distance instead of the
//!   far-field disk formula, the clipped contour sum for every source straddling a sample's
//!   horizon, splitting wholly hidden links too (at `B = 1`, where they are few; in a bake,
//!   with dim sources, they were the cause, above), weighting the pairs' visibility by their
//!   point-to-disk form factor (it overcorrected the floor and undercorrected the back wall).
//!
//! Units: lengths in scene units; irradiance `H` and radiosity `B` in W/m² per linear RGB
//! channel; powers in W (mean over RGB); form factors and `K` dimensionless.

mod gather;
mod refine;
mod transfer;
mod tree;
mod vertex;

pub use gather::Gradient;
pub use refine::{Limits, Link, Linked, Sources};
pub use transfer::Transfer;
pub use tree::{Element, Hierarchy, Node};

use super::{DEFAULT_HR_TOLERANCE, SolveOptions, SolveStats};
use crate::mesh::ReceiverMesh;
use crate::scene::Scene;
use crate::visibility::Visibility;
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;
use vertex::vertex_indirect;

/// Refinement passes: the first with the reflected direct light as the sources' radiosity, the
/// next ones with the previous pass's solution.
const REFINE_PASSES: usize = 2;

/// The refinement oracle's bound on how much one link's irradiance may vary across its
/// receiver's sample points, as a fraction of the mean reflected direct radiosity `P / A`
/// (dimensionless; see the module doc).
pub const VARIATION: f64 = 2e-3;

/// The refinement oracle's bound on the irradiance a source's non-uniformity may misplace, as a
/// fraction of the mean reflected direct radiosity `P / A` (dimensionless; see the module doc).
const SOURCE_VARIATION: f64 = 0.03;

/// The source limit of a receiver that gets no direct light, as a fraction of the limit
/// [`SOURCE_VARIATION`] sets for a lit one (dimensionless): a receiver's limit scales with its
/// brightest element's direct irradiance against the scene's mean, down to this (see the
/// module doc, "Source uniformity").
pub const SHADOWED_SOURCE: f64 = 0.3;

/// The refinement oracle's bound on the irradiance a partially visible link may carry, as a
/// fraction of the mean reflected direct radiosity `P / A` (dimensionless; see the module doc).
pub const PARTIAL_VISIBILITY: f64 = 0.01;

/// Distance, in bounding radii of a surface source node, past which its form factor is the
/// disk formula instead of the exact contour sum (see [`Hierarchy::point_factor`]).
const FAR_FIELD: f64 = 6.0;

/// Most links a refinement may hold (the default of [`SolveOptions::hr_max_links`]: 1.4 GB
/// at 48 bytes a link); past it the refinement stops and is redone with a 4× larger
/// tolerance, up to 1 (a warning). The links of zero `K` a pass keeps for the next one count.
pub const MAX_LINKS: usize = 30_000_000;

/// The Tikhonov term of the radiosity-gradient fit ([`Hierarchy::inverse_moments`]), as a fraction of
/// the second moment's trace: it keeps the fit from amplifying noise across a nearly
/// degenerate node, and shrinks a well-spread node's gradient by about 0.2%.
const REGULARIZATION: f64 = 1e-3;

/// Most Jacobi iterations when iterating to convergence (a warning when reached).
const MAX_ITERATIONS: usize = 1000;

/// Counters of the hierarchical solve (`--stats`: `solve.hierarchical`).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct HierStats {
    /// Nodes of the hierarchy (leaves, surface nodes, clusters).
    pub nodes: usize,
    /// Leaves: mesh elements.
    pub elements: usize,
    /// Cluster nodes (spanning more than one polygon).
    pub clusters: usize,
    /// Links of the last refinement pass.
    pub links: usize,
    /// Links refined (split), summed over the passes.
    pub refinements: u64,
    /// Jacobi iterations, summed over the passes.
    pub iterations: usize,
    /// Shadow rays of the link estimates.
    pub rays: u64,
    /// The refinement tolerance in effect (after any cap), fraction of the reflected direct
    /// power.
    pub tolerance: f64,
    /// Seconds building the hierarchy.
    pub build_seconds: f64,
    /// Seconds refining links (all passes).
    pub link_seconds: f64,
    /// Seconds iterating (all passes).
    pub solve_seconds: f64,
    /// Seconds computing the vertex values.
    pub vertex_seconds: f64,
}

/// The indirect light at every vertex of `meshes`, added to their direct light `direct_h`, by
/// hierarchical radiosity. Fills the powers, `unshot_fraction`, `hierarchical` and `warnings`
/// of `stats` and adds the rays cast.
pub fn indirect(
    scene: &Scene,
    vis: &Visibility,
    meshes: &[ReceiverMesh],
    direct_h: &[Vec<DVec3>],
    options: &SolveOptions,
    stats: &mut SolveStats,
    progress: &crate::progress::Progress<'_>,
) -> Vec<Vec<DVec3>> {
    let mut hs = HierStats {
        tolerance: options.hr_tolerance,
        ..Default::default()
    };
    let start = Instant::now();
    let Some(h) = Hierarchy::build(scene, vis, meshes, direct_h) else {
        stats.hierarchical = Some(hs);
        return direct_h.to_vec();
    };
    hs.nodes = h.nodes.len();
    hs.elements = h.elements.len();
    hs.clusters = h.clusters();
    let moments = h.inverse_moments();
    hs.build_seconds = start.elapsed().as_secs_f64();
    let mean = |c: DVec3| c.element_sum() / 3.0;
    let els = &h.elements;
    let (reflected_direct, initial) = h.reflected_direct();
    let total_area: f64 = els.iter().map(|e| e.area).sum();
    // Receivers count as lit from the mean direct irradiance (see `Limits::source_at`).
    let lit = h.mean_direct();
    stats.direct_power = lit * total_area;
    let mut indirect = vec![DVec3::ZERO; els.len()];
    let mut b_el = reflected_direct.clone();
    let mut left = 0.0;
    if initial > 0.0 {
        let mut tolerance = options.hr_tolerance;
        let mut previous: Option<Vec<Link>> = None;
        for pass in 0..REFINE_PASSES {
            progress("indirect light", pass as u64, REFINE_PASSES as u64);
            let t = Instant::now();
            let last = pass + 1 == REFINE_PASSES;
            let sources = h.sources(&b_el);
            let links = loop {
                let mut limits = Limits::of_bake(tolerance, initial, total_area, lit);
                // At the loosest tolerance the links are what the hierarchy's shape asks for
                // (a cluster's self-link is always split): no cap then.
                limits.max_links = if tolerance < 1.0 {
                    options.hr_max_links
                } else {
                    usize::MAX
                };
                let r = match &previous {
                    Some(p) => h.relink(vis, p, &sources, limits, last),
                    None => h.link(vis, &sources, limits),
                };
                hs.refinements += r.refinements;
                hs.rays += r.rays;
                if !r.overflow {
                    break r.links;
                }
                let looser = (tolerance * 4.0).min(1.0);
                stats.warnings.push(format!(
                    "hierarchical radiosity: more than {} links at --hr-tolerance {tolerance:e}; \
                     refined again at {looser:e}",
                    options.hr_max_links
                ));
                tolerance = looser;
                previous = None;
            };
            hs.tolerance = tolerance;
            // Links of zero `K` stay only for the next pass's oracle (the last pass's relink
            // drops them as it goes: on box-grid-40 they are four in five).
            let (links, all) = if last {
                let mut links = links;
                links.retain(|l| l.k > 0.0);
                (links, Vec::new())
            } else {
                (links.iter().filter(|l| l.k > 0.0).copied().collect(), links)
            };
            hs.links = links.len();
            hs.link_seconds += t.elapsed().as_secs_f64();
            let t = Instant::now();
            let mut iterations = 0usize;
            // Each pass restarts from the reflected direct light: the links changed.
            b_el.clone_from(&reflected_direct);
            loop {
                let b_nodes = h.pull(&b_el);
                let grads = h.gradients(&b_nodes, &moments);
                let gathered = h.gather_linear(&links, &b_nodes, &grads);
                indirect = h.push(&gathered);
                let next: Vec<DVec3> = els
                    .iter()
                    .zip(&indirect)
                    .map(|(e, hi)| e.rho * (e.direct + *hi))
                    .collect();
                left = els
                    .iter()
                    .zip(next.iter().zip(&b_el))
                    .map(|(e, (n, o))| e.area * mean((*n - *o).abs()))
                    .sum();
                b_el = next;
                iterations += 1;
                // Each bounce carries at most rho (< 1) of the previous one, so the change
                // shrinks; where it grows (surfaces counted twice, as with duplicated
                // geometry) the solve diverges: stop, and `unshot_fraction` > 1 says so.
                if left.is_nan() || left > 2.0 * initial {
                    break;
                }
                match options.bounces {
                    Some(n) if iterations >= n as usize => break,
                    Some(_) => {}
                    None if left <= options.tolerance * initial => break,
                    None if iterations >= MAX_ITERATIONS => {
                        stats.warnings.push(format!(
                            "hierarchical radiosity: not converged after {MAX_ITERATIONS} \
                             iterations (change {:e} of the reflected direct power)",
                            left / initial
                        ));
                        break;
                    }
                    None => {}
                }
            }
            hs.iterations += iterations;
            hs.solve_seconds += t.elapsed().as_secs_f64();
            previous = Some(all);
        }
    }
    let t = Instant::now();
    stats.absorbed_power = els
        .iter()
        .zip(&indirect)
        .map(|(e, hi)| e.area * mean((DVec3::ONE - e.rho) * (e.direct + *hi)))
        .sum();
    stats.unshot_fraction = if initial > 0.0 { left / initial } else { 0.0 };
    // Vertex values: a linear fit over the elements using each vertex copy.
    let mut per_mesh: Vec<Vec<(u32, f64, DVec3)>> = vec![Vec::new(); meshes.len()];
    for (e, hi) in els.iter().zip(&indirect) {
        per_mesh[e.mesh].push((e.triangle as u32, e.area, *hi));
    }
    let out = meshes
        .par_iter()
        .zip(direct_h)
        .zip(&per_mesh)
        .map(|((m, dh), items)| {
            let h = vertex_indirect(m, items);
            dh.iter()
                .zip(&h)
                .map(|(&d, hi)| d + hi.unwrap_or(DVec3::ZERO))
                .collect()
        })
        .collect();
    hs.vertex_seconds = t.elapsed().as_secs_f64();
    stats.rays += hs.rays;
    stats.hierarchical = Some(hs);
    out
}

#[cfg(test)]
mod tests;
