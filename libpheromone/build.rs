//! Gives `libpheromone.so` the SONAME `libpheromone.so`, so programs linked against it by path
//! (CMake) record that name and find it through their rpath or the loader's path.
fn main() {
    if std::env::var("CARGO_CFG_TARGET_OS").as_deref() == Ok("linux") {
        println!("cargo:rustc-cdylib-link-arg=-Wl,-soname,libpheromone.so");
    }
}
