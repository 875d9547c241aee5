// penumbra's C interface to xatlas (the 2019 xatlas that xatlas-rs 0.1.3 vendors, in this folder
// unchanged). The functions have C names, so Rust links them the same way on every platform and
// C++ ABI (gcc/clang's Itanium names, MSVC's decorated names): see src/atlas/ffi.rs.
//
// One translation unit: xatlas is compiled here, with the flags build.rs passes
// (XA_MULTITHREADED=0: xatlas's own task scheduler can lose a wakeup at Destroy and hang).

#include "xatlas.cpp"

extern "C" {

xatlas::Atlas *penumbra_xatlas_create() { return xatlas::Create(); }

void penumbra_xatlas_destroy(xatlas::Atlas *atlas) { xatlas::Destroy(atlas); }

int penumbra_xatlas_add_mesh(xatlas::Atlas *atlas, const xatlas::MeshDecl *decl)
{
	return static_cast<int>(xatlas::AddMesh(atlas, *decl));
}

void penumbra_xatlas_generate(xatlas::Atlas *atlas, const xatlas::ChartOptions *chart_options,
                              const xatlas::PackOptions *pack_options)
{
	xatlas::Generate(atlas, *chart_options, nullptr, *pack_options, nullptr, nullptr);
}

void penumbra_xatlas_pack_charts(xatlas::Atlas *atlas, const xatlas::PackOptions *pack_options)
{
	xatlas::PackCharts(atlas, *pack_options, nullptr, nullptr);
}

void penumbra_xatlas_silence() { xatlas::SetPrint(nullptr, false); }

// The scheduler this build has: 0 (tasks run inline on the calling thread) or 1 (worker threads).
int penumbra_xatlas_multithreaded() { return XA_MULTITHREADED; }

// sizeof of the structs Rust mirrors, so that a test catches a layout mismatch.
size_t penumbra_xatlas_sizeof(int which)
{
	switch (which) {
	case 0: return sizeof(xatlas::Atlas);
	case 1: return sizeof(xatlas::Mesh);
	case 2: return sizeof(xatlas::Chart);
	case 3: return sizeof(xatlas::Vertex);
	case 4: return sizeof(xatlas::MeshDecl);
	case 5: return sizeof(xatlas::ChartOptions);
	case 6: return sizeof(xatlas::PackOptions);
	default: return 0;
	}
}

} // extern "C"
