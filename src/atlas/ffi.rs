//! The xatlas FFI: `#[repr(C)]` mirrors of the structs of `xatlas/xatlas.h`, the C functions of
//! `xatlas/shim.cpp` (C names, so they link alike under every C++ ABI), and [`Xatlas`], the one
//! owner of an atlas. Every `unsafe` of the crate's atlas is here.

use std::ffi::{c_int, c_void};
use std::marker::PhantomData;

/// `atlasIndex` -1 (read as `u32`): a vertex of a triangle xatlas left out of every chart.
pub(super) const UNCHARTED: u32 = u32::MAX;

/// `xatlas::AddMeshError::Success`.
pub(super) const ADD_MESH_SUCCESS: c_int = 0;

/// The text of an `xatlas::AddMeshError` code.
pub(super) fn add_mesh_error_text(code: c_int) -> String {
    match code {
        1 => "IndexOutOfRange: an index is >= the vertex count".to_owned(),
        2 => "InvalidIndexCount: the index count is not a multiple of 3".to_owned(),
        other => format!("unknown AddMesh error {other}"),
    }
}

/// `struct xatlas::Atlas`.
#[repr(C)]
struct RawAtlas {
    width: u32,
    height: u32,
    atlas_count: u32,
    chart_count: u32,
    mesh_count: u32,
    meshes: *const RawMesh,
    utilization: *const f32,
    texels_per_unit: f32,
}

/// `struct xatlas::Mesh`.
#[repr(C)]
struct RawMesh {
    chart_array: *const RawChart,
    chart_count: u32,
    index_array: *const u32,
    index_count: u32,
    vertex_array: *const Vertex,
    vertex_count: u32,
}

/// `struct xatlas::Chart`.
#[repr(C)]
struct RawChart {
    atlas_index: u32,
    index_array: *const u32,
    index_count: u32,
}

/// `struct xatlas::Vertex`: an output vertex.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub(super) struct Vertex {
    /// The page (xatlas's sub-atlas), or [`UNCHARTED`].
    pub(super) atlas_index: u32,
    /// In texels of the page.
    pub(super) uv: [f32; 2],
    /// The input vertex it came from.
    pub(super) xref: u32,
}

/// `struct xatlas::MeshDecl`, with 32-bit indices.
#[repr(C)]
struct RawMeshDecl {
    vertex_count: u32,
    vertex_position_data: *const c_void,
    vertex_position_stride: u32,
    vertex_normal_data: *const c_void,
    vertex_normal_stride: u32,
    vertex_uv_data: *const c_void,
    vertex_uv_stride: u32,
    index_count: u32,
    index_data: *const c_void,
    index_offset: i32,
    /// `xatlas::IndexFormat::Enum`: 1 is `UInt32`.
    index_format: c_int,
    face_ignore_data: *const bool,
}

/// `struct xatlas::ChartOptions`.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub(super) struct ChartOptions {
    pub(super) max_chart_area: f32,
    pub(super) max_boundary_length: f32,
    pub(super) proxy_fit_metric_weight: f32,
    pub(super) roundness_metric_weight: f32,
    pub(super) straightness_metric_weight: f32,
    pub(super) normal_seam_metric_weight: f32,
    pub(super) texture_seam_metric_weight: f32,
    pub(super) max_threshold: f32,
    pub(super) grow_face_count: u32,
    pub(super) max_iterations: u32,
}

impl Default for ChartOptions {
    /// The header's defaults.
    fn default() -> Self {
        Self {
            max_chart_area: 0.0,
            max_boundary_length: 0.0,
            proxy_fit_metric_weight: 2.0,
            roundness_metric_weight: 0.01,
            straightness_metric_weight: 6.0,
            normal_seam_metric_weight: 4.0,
            texture_seam_metric_weight: 0.5,
            max_threshold: 2.0,
            grow_face_count: 32,
            max_iterations: 1,
        }
    }
}

/// `struct xatlas::PackOptions`.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub(super) struct PackOptions {
    pub(super) attempts: c_int,
    pub(super) texels_per_unit: f32,
    pub(super) resolution: u32,
    pub(super) max_chart_size: u32,
    pub(super) block_align: bool,
    pub(super) conservative: bool,
    pub(super) padding: u32,
}

unsafe extern "C" {
    fn penumbra_xatlas_create() -> *mut RawAtlas;
    fn penumbra_xatlas_destroy(atlas: *mut RawAtlas);
    fn penumbra_xatlas_add_mesh(atlas: *mut RawAtlas, decl: *const RawMeshDecl) -> c_int;
    fn penumbra_xatlas_generate(
        atlas: *mut RawAtlas,
        chart_options: *const ChartOptions,
        pack_options: *const PackOptions,
    );
    fn penumbra_xatlas_pack_charts(atlas: *mut RawAtlas, pack_options: *const PackOptions);
    fn penumbra_xatlas_silence();
    #[cfg(test)]
    fn penumbra_xatlas_multithreaded() -> c_int;
    #[cfg(test)]
    fn penumbra_xatlas_sizeof(which: c_int) -> usize;
}

/// Turns off xatlas's `printf` to stdout, once per process, before any atlas is made.
fn silence_xatlas() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    // SAFETY: SetPrint only stores the function pointer and flag in globals; Once makes this
    // happen before any xatlas call of this module, on any thread.
    ONCE.call_once(|| unsafe { penumbra_xatlas_silence() });
}

/// What xatlas reports after packing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct PackInfo {
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) atlas_count: u32,
    pub(super) chart_count: u32,
    pub(super) texels_per_unit: f32,
}

/// One chart of an output mesh: its page and its triangles' output vertex indices.
pub(super) struct Chart<'a> {
    pub(super) atlas_index: u32,
    pub(super) indices: &'a [u32],
}

/// A view of one output mesh, valid until the next packing or the atlas's drop.
pub(super) struct Mesh<'a> {
    pub(super) charts: Vec<Chart<'a>>,
    pub(super) indices: &'a [u32],
    pub(super) vertices: &'a [Vertex],
}

/// An xatlas atlas, destroyed on drop. Each has its own state, so atlases on different threads
/// need no lock.
pub(super) struct Xatlas {
    raw: *mut RawAtlas,
    /// Not `Send`: xatlas's state is not known to be safe to move between threads.
    _not_send: PhantomData<*mut ()>,
}

/// A slice from xatlas's array and count, empty for a null array.
///
/// # Safety
/// A non-null `data` must point to `count` initialized `T`s that live for `'a`.
unsafe fn slice<'a, T>(data: *const T, count: u32) -> &'a [T] {
    if data.is_null() || count == 0 {
        &[]
    } else {
        // SAFETY: by the caller's contract.
        unsafe { std::slice::from_raw_parts(data, count as usize) }
    }
}

impl Xatlas {
    /// A new, empty atlas (`None` if xatlas could not make one).
    pub(super) fn new() -> Option<Self> {
        silence_xatlas();
        // SAFETY: Create has no preconditions.
        let raw = unsafe { penumbra_xatlas_create() };
        (!raw.is_null()).then_some(Self {
            raw,
            _not_send: PhantomData,
        })
    }

    /// Adds a mesh of `positions` (scene units) and 32-bit `indices`, leaving out the triangles
    /// whose `ignore` flag is set (`ignore` is empty or one flag per triangle). Returns xatlas's
    /// `AddMeshError` code.
    pub(super) fn add_mesh(
        &mut self,
        positions: &[[f32; 3]],
        indices: &[u32],
        ignore: &[bool],
    ) -> c_int {
        assert!(ignore.is_empty() || ignore.len() * 3 == indices.len());
        let decl = RawMeshDecl {
            vertex_count: positions.len() as u32,
            vertex_position_data: positions.as_ptr().cast(),
            vertex_position_stride: 12,
            vertex_normal_data: std::ptr::null(),
            vertex_normal_stride: 0,
            vertex_uv_data: std::ptr::null(),
            vertex_uv_stride: 0,
            index_count: indices.len() as u32,
            index_data: if indices.is_empty() {
                std::ptr::null()
            } else {
                indices.as_ptr().cast()
            },
            index_offset: 0,
            index_format: 1,
            face_ignore_data: if ignore.is_empty() {
                std::ptr::null()
            } else {
                ignore.as_ptr()
            },
        };
        // SAFETY: the atlas is live; the arrays outlive the call (xatlas copies them) and hold
        // what the counts and strides say.
        unsafe { penumbra_xatlas_add_mesh(self.raw, &decl) }
    }

    /// Charts, parameterizes and packs the added meshes.
    pub(super) fn generate(
        &mut self,
        chart_options: &ChartOptions,
        pack_options: &PackOptions,
    ) -> PackInfo {
        // SAFETY: the atlas is live and the options are plain values.
        unsafe { penumbra_xatlas_generate(self.raw, chart_options, pack_options) };
        self.info()
    }

    /// Packs the charts again (after [`Self::generate`]; xatlas restores the chart UVs first).
    /// Frees the previous output meshes: `&mut self` ends their views' borrows.
    pub(super) fn pack_charts(&mut self, pack_options: &PackOptions) -> PackInfo {
        // SAFETY: the atlas is live and was generated; no view of its output outlives this.
        unsafe { penumbra_xatlas_pack_charts(self.raw, pack_options) };
        self.info()
    }

    fn info(&self) -> PackInfo {
        // SAFETY: the atlas is live.
        let a = unsafe { &*self.raw };
        PackInfo {
            width: a.width,
            height: a.height,
            atlas_count: a.atlas_count,
            chart_count: a.chart_count,
            texels_per_unit: a.texels_per_unit,
        }
    }

    /// Views of the output meshes, one per added mesh.
    pub(super) fn meshes(&self) -> Vec<Mesh<'_>> {
        // SAFETY: the atlas is live; its output arrays hold the counts it says, and live until
        // the next packing or the drop, both of which need `&mut self`.
        unsafe {
            let a = &*self.raw;
            slice(a.meshes, a.mesh_count)
                .iter()
                .map(|m| Mesh {
                    charts: slice(m.chart_array, m.chart_count)
                        .iter()
                        .map(|c| Chart {
                            atlas_index: c.atlas_index,
                            indices: slice(c.index_array, c.index_count),
                        })
                        .collect(),
                    indices: slice(m.index_array, m.index_count),
                    vertices: slice(m.vertex_array, m.vertex_count),
                })
                .collect()
        }
    }
}

impl Drop for Xatlas {
    fn drop(&mut self) {
        // SAFETY: the atlas is live and dropped once.
        unsafe { penumbra_xatlas_destroy(self.raw) }
    }
}

#[cfg(test)]
/// Whether xatlas was built with its worker-thread scheduler (build.rs builds it without).
pub(super) fn multithreaded() -> bool {
    // SAFETY: returns a constant.
    unsafe { penumbra_xatlas_multithreaded() != 0 }
}

#[cfg(test)]
/// `(name, C++ sizeof, Rust size_of)` of every mirrored struct.
pub(super) fn layouts() -> Vec<(&'static str, usize, usize)> {
    let rust = [
        ("Atlas", size_of::<RawAtlas>()),
        ("Mesh", size_of::<RawMesh>()),
        ("Chart", size_of::<RawChart>()),
        ("Vertex", size_of::<Vertex>()),
        ("MeshDecl", size_of::<RawMeshDecl>()),
        ("ChartOptions", size_of::<ChartOptions>()),
        ("PackOptions", size_of::<PackOptions>()),
    ];
    rust.iter()
        .enumerate()
        // SAFETY: returns a constant.
        .map(|(k, &(name, size))| (name, unsafe { penumbra_xatlas_sizeof(k as c_int) }, size))
        .collect()
}
