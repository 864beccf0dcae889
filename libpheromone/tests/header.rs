//! `include/pheromone.h` is what cbindgen generates from this crate: CI fails when the ABI
//! changed and the committed header did not follow. With `PHEROMONE_BLESS_HEADER=1` the test
//! writes the generated header instead.

use std::path::Path;

#[test]
fn the_committed_header_equals_the_generated_one() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).expect("cbindgen.toml");
    let mut generated = Vec::new();
    cbindgen::Builder::new()
        .with_crate(dir)
        .with_config(config)
        .generate()
        .expect("cbindgen generates the header")
        .write(&mut generated);
    let generated = String::from_utf8(generated).expect("the header is UTF-8");
    let path = dir.join("include/pheromone.h");
    if std::env::var_os("PHEROMONE_BLESS_HEADER").is_some() {
        std::fs::write(&path, &generated).expect("write include/pheromone.h");
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "{} differs from what cbindgen generates from libpheromone/src: regenerate it with \
         PHEROMONE_BLESS_HEADER=1 cargo test -p pheromone-c --test header, and commit it",
        path.display()
    );
}
