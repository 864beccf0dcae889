//! Gives `libpheromone.so` the SONAME `libpheromone.so.MAJOR` (the crate's major version), so
//! programs linked against it record that name and find it through their rpath or the loader's
//! path, and a library of another major version (another ABI) is never taken for it.
//! `install.sh` installs `libpheromone.so.MAJOR.MINOR.PATCH` with the links `libpheromone.so.MAJOR`
//! and `libpheromone.so`.
fn main() {
    if std::env::var("CARGO_CFG_TARGET_OS").as_deref() == Ok("linux") {
        let major = std::env::var("CARGO_PKG_VERSION_MAJOR").unwrap_or_else(|_| "0".into());
        println!("cargo:rustc-cdylib-link-arg=-Wl,-soname,libpheromone.so.{major}");
    }
}
