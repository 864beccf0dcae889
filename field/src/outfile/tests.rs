use std::os::unix::fs::PermissionsExt;

use super::*;

/// A fresh directory of this test (removed by the caller).
fn scratch(tag: &str) -> PathBuf {
    use std::sync::atomic::{AtomicU32, Ordering};
    static N: AtomicU32 = AtomicU32::new(0);
    let dir = std::env::temp_dir().join(format!(
        "outfile-{tag}-{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn names_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn mkfifo(path: &Path) {
    nix::unistd::mkfifo(path, nix::sys::stat::Mode::from_bits_truncate(0o600)).unwrap();
}

#[test]
fn a_new_file_and_a_regular_file_are_written_whole_and_no_temporary_file_is_left() {
    let dir = scratch("whole");
    let path = dir.join("out.bin");
    assert_eq!(write_file(&path, b"first").unwrap(), 5);
    assert_eq!(std::fs::read(&path).unwrap(), b"first");
    assert_eq!(write_file(&path, b"second").unwrap(), 6);
    assert_eq!(std::fs::read(&path).unwrap(), b"second");
    assert_eq!(names_in(&dir), ["out.bin"]);
    // A writer dropped before its commit leaves neither the file nor its temporary file.
    let mut partial = OutFile::create(&dir.join("partial.csv")).unwrap();
    partial.write_all(b"a,b\n").unwrap();
    drop(partial);
    assert_eq!(names_in(&dir), ["out.bin"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_symlink_a_fifo_and_a_directory_are_refused_and_left_as_they_were() {
    let dir = scratch("refuse");
    let victim = dir.join("victim");
    std::fs::write(&victim, b"precious").unwrap();
    let link = dir.join("link");
    std::os::unix::fs::symlink(&victim, &link).unwrap();
    let dangling = dir.join("dangling");
    std::os::unix::fs::symlink(dir.join("nowhere"), &dangling).unwrap();
    let fifo = dir.join("fifo");
    mkfifo(&fifo);
    let sub = dir.join("sub");
    std::fs::create_dir(&sub).unwrap();
    for (path, kind) in [
        (&link, "a symbolic link"),
        (&dangling, "a symbolic link"),
        (&fifo, "a FIFO"),
        (&sub, "a directory"),
    ] {
        for result in [
            write_file(path, b"x").map(|_| ()),
            open_in_place(path).map(|_| ()),
            open_private_append(path).map(|_| ()),
        ] {
            let e = result.expect_err("refused").to_string();
            assert!(
                e.contains(kind) && e.contains(&*path.to_string_lossy()),
                "{e}"
            );
        }
    }
    assert_eq!(std::fs::read(&victim).unwrap(), b"precious");
    assert!(std::fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
    assert!(!dir.join("nowhere").exists());
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::symlink_metadata(&fifo)
        .unwrap()
        .file_type()
        .is_fifo());
    assert_eq!(
        names_in(&dir),
        ["dangling", "fifo", "link", "sub", "victim"]
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_char_device_is_refused() {
    // /dev/null is only inspected: nothing is opened or written.
    let e = check_destination(Path::new("/dev/null")).unwrap_err();
    assert!(e.to_string().contains("a character device"), "{e}");
    let e = write_file(Path::new("/dev/null"), b"x").unwrap_err();
    assert!(e.to_string().contains("a character device"), "{e}");
}

#[test]
fn open_in_place_truncates_a_regular_file_and_creates_a_new_one() {
    let dir = scratch("inplace");
    let path = dir.join("rec.mcap");
    std::fs::write(&path, b"old contents").unwrap();
    let mut f = open_in_place(&path).unwrap();
    f.write_all(b"new").unwrap();
    drop(f);
    assert_eq!(std::fs::read(&path).unwrap(), b"new");
    let fresh = dir.join("fresh.mcap");
    drop(open_in_place(&fresh).unwrap());
    assert_eq!(std::fs::read(&fresh).unwrap(), b"");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_private_dir_is_made_0700_and_a_shared_linked_or_foreign_one_is_refused() {
    let dir = scratch("private");
    let mine = dir.join("mine");
    private_dir(&mine).unwrap();
    let m = std::fs::symlink_metadata(&mine).unwrap();
    assert_eq!(m.mode() & 0o777, 0o700);
    private_dir(&mine).unwrap();
    // Open to others.
    let open = dir.join("open");
    std::fs::create_dir(&open).unwrap();
    std::fs::set_permissions(&open, std::fs::Permissions::from_mode(0o777)).unwrap();
    let e = private_dir(&open).unwrap_err().to_string();
    assert!(e.contains("mode 777") && e.contains("open"), "{e}");
    // A symbolic link to a private directory.
    let link = dir.join("link");
    std::os::unix::fs::symlink(&mine, &link).unwrap();
    let e = private_dir(&link).unwrap_err().to_string();
    assert!(e.contains("a symbolic link"), "{e}");
    // Owned by someone else: as root, a directory given to `nobody`; otherwise root's own
    // home, which is root's and 0700.
    let foreign = if effective_uid() == 0 {
        let d = dir.join("foreign");
        std::fs::create_dir(&d).unwrap();
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o700)).unwrap();
        nix::unistd::chown(&d, Some(nix::unistd::Uid::from_raw(65534)), None).unwrap();
        d
    } else {
        PathBuf::from("/root")
    };
    let e = private_dir(&foreign).unwrap_err().to_string();
    assert!(e.contains("owned by uid"), "{e}");
    // A regular file where the directory should be.
    let file = dir.join("file");
    std::fs::write(&file, b"").unwrap();
    assert!(private_dir(&file).is_err());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn replace_symlink_makes_and_repoints_a_link_and_refuses_a_directory_or_a_file() {
    let dir = scratch("latest");
    std::fs::create_dir(dir.join("a")).unwrap();
    std::fs::create_dir(dir.join("b")).unwrap();
    let link = dir.join("latest");
    replace_symlink(&link, Path::new("a")).unwrap();
    assert_eq!(std::fs::read_link(&link).unwrap(), Path::new("a"));
    replace_symlink(&link, Path::new("b")).unwrap();
    assert_eq!(std::fs::read_link(&link).unwrap(), Path::new("b"));
    assert_eq!(names_in(&dir), ["a", "b", "latest"]);
    // A directory or a regular file under the link's name is left as it is.
    for (name, kind) in [("a", "a directory"), ("f", "a regular file")] {
        if name == "f" {
            std::fs::write(dir.join("f"), b"x").unwrap();
        }
        let e = replace_symlink(&dir.join(name), Path::new("b")).unwrap_err();
        let text = e.to_string();
        assert!(text.contains(name), "{text}");
        assert!(matches!(e, OutputError::NotSymlink { .. }), "{text}");
        assert!(text.contains(kind), "{text}");
    }
    assert!(dir.join("a").is_dir());
    assert_eq!(std::fs::read(dir.join("f")).unwrap(), b"x");
    assert_eq!(names_in(&dir), ["a", "b", "f", "latest"]);
    std::fs::remove_dir_all(&dir).unwrap();
}
