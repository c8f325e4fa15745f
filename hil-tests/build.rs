//! The board suite's test binaries need embedded-test's linker script (its test table).
fn main() {
    println!("cargo::rustc-link-arg-tests=-Tembedded-test.x");
    // embedded-test's macro emits `cfg(rust_analyzer)`.
    println!("cargo::rustc-check-cfg=cfg(rust_analyzer)");
}
