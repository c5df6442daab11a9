//! Passes the target triple to the crate: the model is compiled at run time for it.
fn main() {
    let target = std::env::var("TARGET").expect("cargo sets TARGET");
    println!("cargo:rustc-env=SKINBOX_COSIM_TARGET={target}");
    println!("cargo:rerun-if-changed=build.rs");
}
