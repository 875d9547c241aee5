//! The xatlas FFI: xatlas's C++ API by its Itanium (gcc/clang) symbol names, the shims that
//! export it under the MSVC names xatlas-rs's bindings import (see the module doc of
//! [`crate::atlas`] for why), and the thread-local stash where the shims keep what xatlas-rs
//! drops. Every `unsafe` of the crate's atlas is here or next to a call into this module.

use std::cell::Cell;
use std::ffi::{c_int, c_void};
use std::ptr;

/// `atlasIndex` -1 (as xatlas-rs's `u32`): a vertex of a triangle xatlas left out of every chart.
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

pub(super) fn positions_as_bytes(positions: &[[f32; 3]]) -> &[u8] {
    // SAFETY: [f32; 3] has no padding and any initialized bytes are valid u8s; same extent.
    unsafe { std::slice::from_raw_parts(positions.as_ptr().cast(), size_of_val(positions)) }
}

pub(super) fn indices_as_bytes(indices: &[u32]) -> &[u8] {
    // SAFETY: u32 has no padding and any initialized bytes are valid u8s; same extent.
    unsafe { std::slice::from_raw_parts(indices.as_ptr().cast(), size_of_val(indices)) }
}

/// Turns off xatlas's `printf` to stdout, once per process, before any atlas is made.
pub(super) fn silence_xatlas() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    // SAFETY: SetPrint only stores the function pointer and flag in globals; Once makes this
    // happen before any xatlas call of this module, on any thread.
    ONCE.call_once(|| unsafe { set_print(ptr::null(), false) });
}

/// What xatlas reports after packing: fields of `xatlas::Atlas` that xatlas-rs hides.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct PackInfo {
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) atlas_count: u32,
    pub(super) chart_count: u32,
    pub(super) texels_per_unit: f32,
}

impl PackInfo {
    /// Reads the packing results from an atlas.
    ///
    /// # Safety
    /// `atlas` must be a live atlas from `xatlas::Create`.
    pub(super) unsafe fn read(atlas: *const Atlas) -> Self {
        // SAFETY: by the caller's contract.
        let a = unsafe { &*atlas };
        Self {
            width: a.width,
            height: a.height,
            atlas_count: a.atlas_count,
            chart_count: a.chart_count,
            texels_per_unit: a.texels_per_unit,
        }
    }
}

thread_local! {
    /// The atlas the `Create` shim last returned on this thread.
    pub(super) static LAST_HANDLE: Cell<*mut Atlas> = const { Cell::new(ptr::null_mut()) };
    /// The code the `AddMesh` shim last returned on this thread.
    pub(super) static LAST_ADD_MESH: Cell<Option<c_int>> = const { Cell::new(None) };
    /// What the `Generate` shim last read from its atlas on this thread.
    pub(super) static LAST_GENERATE: Cell<Option<PackInfo>> = const { Cell::new(None) };
}

// The xatlas C++ API, by its Itanium (gcc/clang) symbol names, and `#[repr(C)]` mirrors of the
// structs it takes by value or that we read, in the field order of `vendor/xatlas.h`.

/// `struct xatlas::Atlas`.
#[repr(C)]
pub(super) struct Atlas {
    pub width: u32,
    pub height: u32,
    pub(crate) atlas_count: u32,
    pub(crate) chart_count: u32,
    pub(crate) mesh_count: u32,
    pub meshes: *mut c_void,
    pub(crate) utilization: *mut f32,
    pub texels_per_unit: f32,
}

/// `struct xatlas::ChartOptions`, passed by value. xatlas-rs's bindings have the same field
/// order as the header, and its `convert()` fills them by name.
#[repr(C)]
#[derive(Clone, Copy)]
pub(super) struct ChartOptions {
    pub(crate) max_chart_area: f32,
    pub(crate) max_boundary_length: f32,
    pub(crate) proxy_fit_metric_weight: f32,
    pub(crate) roundness_metric_weight: f32,
    pub(crate) straightness_metric_weight: f32,
    pub(crate) normal_seam_metric_weight: f32,
    pub(crate) texture_seam_metric_weight: f32,
    pub(crate) max_threshold: f32,
    pub(crate) grow_face_count: u32,
    pub(crate) max_iterations: u32,
}

/// `struct xatlas::PackOptions`, passed by value. Same field order in xatlas-rs's bindings.
#[repr(C)]
#[derive(Clone, Copy)]
pub(super) struct PackOptions {
    pub attempts: c_int,
    pub texels_per_unit: f32,
    pub resolution: u32,
    pub(crate) max_chart_size: u32,
    pub(crate) block_align: bool,
    pub(crate) conservative: bool,
    pub padding: u32,
}

impl PackOptions {
    pub(super) fn to_xatlas_rs(self) -> xatlas_rs::PackOptions {
        xatlas_rs::PackOptions {
            attempts: self.attempts,
            texels_per_unit: self.texels_per_unit,
            resolution: self.resolution,
            max_chart_size: self.max_chart_size,
            block_align: self.block_align,
            conservative: self.conservative,
            padding: self.padding,
        }
    }
}

/// `xatlas::ParameterizeFunc`.
pub(super) type ParameterizeFunc = Option<
    unsafe extern "C" fn(
        positions: *const f32,
        texcoords: *mut f32,
        vertex_count: u32,
        indices: *const u32,
        index_count: u32,
        is_planar: bool,
    ),
>;

/// `xatlas::ProgressFunc`.
pub(super) type ProgressFunc =
    Option<unsafe extern "C" fn(category: c_int, progress: c_int, user_data: *mut c_void)>;

unsafe extern "C" {
    /// `xatlas::Create()`.
    #[link_name = "_ZN6xatlas6CreateEv"]
    pub(super) fn create() -> *mut Atlas;
    /// `xatlas::Destroy(Atlas*)`.
    #[link_name = "_ZN6xatlas7DestroyEPNS_5AtlasE"]
    pub(super) fn destroy(atlas: *mut Atlas);
    /// `xatlas::AddMesh(Atlas*, const MeshDecl&)`; the `MeshDecl` is xatlas-rs's.
    #[link_name = "_ZN6xatlas7AddMeshEPNS_5AtlasERKNS_8MeshDeclE"]
    pub(super) fn add_mesh(atlas: *mut Atlas, mesh_decl: *const c_void) -> c_int;
    /// `xatlas::Generate(Atlas*, ChartOptions, ParameterizeFunc, PackOptions, ProgressFunc,
    /// void*)`.
    #[link_name = "_ZN6xatlas8GenerateEPNS_5AtlasENS_12ChartOptionsEPFvPKfPfjPKjjbENS_11PackOptionsEPFvNS_16ProgressCategory4EnumEiPvESD_"]
    pub(super) fn generate(
        atlas: *mut Atlas,
        chart_options: ChartOptions,
        param_func: ParameterizeFunc,
        pack_options: PackOptions,
        progress_func: ProgressFunc,
        progress_user_data: *mut c_void,
    );
    /// `xatlas::PackCharts(Atlas*, PackOptions, ProgressFunc, void*)`.
    #[link_name = "_ZN6xatlas10PackChartsEPNS_5AtlasENS_11PackOptionsEPFvNS_16ProgressCategory4EnumEiPvES5_"]
    pub(super) fn pack_charts(
        atlas: *mut Atlas,
        pack_options: PackOptions,
        progress_func: ProgressFunc,
        progress_user_data: *mut c_void,
    );
    /// `xatlas::SetPrint(PrintFunc, bool)`; `print` is an `int (*)(const char*, ...)` or null.
    #[link_name = "_ZN6xatlas8SetPrintEPFiPKczEb"]
    pub(super) fn set_print(print: *const c_void, verbose: bool);
}

// The shims: xatlas-rs's bindings import these MSVC names (as `\u{1}?Create@...`: the name as is,
// which on ELF is the same symbol as `?Create@...`); each forwards to the Itanium symbol with the
// same signature, and keeps what xatlas-rs would drop in this thread's stash.

#[unsafe(export_name = "?Create@xatlas@@YAPEAUAtlas@1@XZ")]
unsafe extern "C" fn xatlas_create_shim() -> *mut Atlas {
    // SAFETY: forwards the call xatlas-rs made, with the same signature.
    let atlas = unsafe { create() };
    let _ = LAST_HANDLE.try_with(|h| h.set(atlas));
    atlas
}

#[unsafe(export_name = "?Destroy@xatlas@@YAXPEAUAtlas@1@@Z")]
unsafe extern "C" fn xatlas_destroy_shim(atlas: *mut Atlas) {
    let _ = LAST_HANDLE.try_with(|h| {
        if h.get() == atlas {
            h.set(ptr::null_mut());
        }
    });
    // SAFETY: forwards the call xatlas-rs made, with the same signature.
    unsafe { destroy(atlas) }
}

#[unsafe(export_name = "?AddMesh@xatlas@@YA?AW4Enum@AddMeshError@1@PEAUAtlas@1@AEBUMeshDecl@1@@Z")]
unsafe extern "C" fn xatlas_add_mesh_shim(atlas: *mut Atlas, mesh_decl: *const c_void) -> c_int {
    // SAFETY: forwards the call xatlas-rs made, with the same signature.
    let result = unsafe { add_mesh(atlas, mesh_decl) };
    let _ = LAST_ADD_MESH.try_with(|r| r.set(Some(result)));
    result
}

#[unsafe(export_name = "?Generate@xatlas@@YAXPEAUAtlas@1@UChartOptions@1@P6AXPEBMPEAMIPEBII_N@ZUPackOptions@1@P6AXW4Enum@ProgressCategory@1@HPEAX@Z9@Z")]
unsafe extern "C" fn xatlas_generate_shim(
    atlas: *mut Atlas,
    chart_options: ChartOptions,
    param_func: ParameterizeFunc,
    pack_options: PackOptions,
    progress_func: ProgressFunc,
    progress_user_data: *mut c_void,
) {
    // SAFETY: forwards the call xatlas-rs made, with the same signature; `atlas` is then live.
    unsafe {
        generate(
            atlas,
            chart_options,
            param_func,
            pack_options,
            progress_func,
            progress_user_data,
        );
        if !atlas.is_null() {
            let info = PackInfo::read(atlas);
            let _ = LAST_GENERATE.try_with(|g| g.set(Some(info)));
        }
    }
}
