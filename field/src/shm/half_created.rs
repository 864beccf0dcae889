//! Services a process was killed in the middle of creating.
//!
//! iceoryx2 0.10 creates a service by writing its static config first (a file in its service
//! directory, owner read-write while it is written, read-only once it is finished), then the
//! service's resources and its dynamic config (in /dev/shm). A process SIGKILLed in between (a
//! `sim` killed while it sets up its run: 2 of 4 kills right after its world started, measured)
//! leaves the static file alone. iceoryx2 reports such a service as still in creation (an
//! unfinished file) or corrupted (no dynamic config): no one can open or create it, no listing
//! shows the unfinished ones, and no dead-node cleanup removes it, since no node was registered
//! in it. [`remove_half_created_services`] removes those files.

use std::time::Duration;

use iceoryx2::prelude::*;

/// A static config without a dynamic config for longer than this is left by a dead creator:
/// iceoryx2 gives its own creators `creation_timeout` (1 s by default) before openers report a
/// service that hangs in creation.
fn stale_after(config: &iceoryx2::config::Config) -> Duration {
    (config.global.creation_timeout * 2).max(Duration::from_secs(2))
}

/// Removes `config`'s static service configs older than twice iceoryx2's creation timeout (at
/// least 2 s) that were never finished (still owner read-write, iceoryx2's mode while it writes
/// them) or have no dynamic config: services whose creator died before finishing them. Returns
/// how many it removed.
pub fn remove_half_created_services(config: &iceoryx2::config::Config) -> u64 {
    use std::os::unix::fs::PermissionsExt;
    let dir = config.global.service_dir().to_string();
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return 0;
    };
    let (prefix, suffix) = (
        config.global.prefix.to_string(),
        config
            .global
            .service
            .static_config_storage_suffix
            .to_string(),
    );
    let older_than = stale_after(config);
    let stale: Vec<_> = entries
        .flatten()
        .filter(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            name.starts_with(&prefix) && name.ends_with(&suffix)
        })
        .filter_map(|e| {
            let meta = e.metadata().ok()?;
            let age = meta.modified().ok()?.elapsed().ok()?;
            (age > older_than).then(|| (e.path(), meta.permissions().mode() & 0o777 == 0o600))
        })
        .collect();
    if stale.is_empty() {
        return 0;
    }
    let no_dynamic = finished_without_dynamic_config(config);
    let mut removed = 0;
    for (file, unfinished) in stale {
        let name = file.file_name().map(|n| n.to_string_lossy().into_owned());
        let orphan =
            unfinished || name.is_some_and(|n| no_dynamic.iter().any(|h| n.contains(h.as_str())));
        if orphan && std::fs::remove_file(&file).is_ok() {
            removed += 1;
        }
    }
    removed
}

/// The hashes of `config`'s finished services that have no dynamic config.
fn finished_without_dynamic_config(config: &iceoryx2::config::Config) -> Vec<String> {
    let mut hashes = Vec::new();
    // Listing fails only on an unreadable service directory: then none.
    let _ = ipc::Service::list(config, |s| {
        if s.dynamic_details.is_none() {
            hashes.push(s.static_details.service_hash().as_str().to_string());
        }
        CallbackProgression::Continue
    });
    hashes
}
