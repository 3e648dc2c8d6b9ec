//! Builds the one-function C++ shim (`shim/stream_tell.cpp`) against the vendored LibRaw
//! headers of the version rsraw-sys builds (rsraw-sys is pinned to that version).

fn main() {
    println!("cargo:rerun-if-changed=shim/stream_tell.cpp");
    println!("cargo:rerun-if-changed=vendor/libraw-0.21.3/libraw");
    cc::Build::new()
        .cpp(true)
        .include("vendor/libraw-0.21.3")
        .file("shim/stream_tell.cpp")
        .warnings(false)
        .compile("skinbrdf_libraw_shim");
}
