//! Turns the backend switches into cfgs, so a case for a backend that is not enabled is an
//! *ignored* test (counted as such in the run's totals) rather than one that passes without
//! running. Cargo rebuilds the tests when either variable changes.

fn main() {
    println!("cargo:rustc-check-cfg=cfg(skinbrdf_hil)");
    println!("cargo:rustc-check-cfg=cfg(skinbrdf_emulator)");
    println!("cargo:rerun-if-env-changed=SKINBRDF_HIL_PORT");
    println!("cargo:rerun-if-env-changed=SKINBRDF_EMULATOR");
    if std::env::var_os("SKINBRDF_HIL_PORT").is_some_and(|p| !p.is_empty()) {
        println!("cargo:rustc-cfg=skinbrdf_hil");
    }
    if std::env::var("SKINBRDF_EMULATOR").as_deref() == Ok("1") {
        println!("cargo:rustc-cfg=skinbrdf_emulator");
    }
}
