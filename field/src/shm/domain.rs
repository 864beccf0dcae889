//! iceoryx2 domains, one per user (docs/reliability.md, "A hostile or careless local user").
//!
//! iceoryx2 keeps a host-wide management segment (`/dev/shm/<prefix>…_node.<version>.global_mgmt`)
//! that it creates mode 0666, and its root directory (`/tmp/iceoryx2/`) mode 0750 for whoever
//! made it first. So with iceoryx2's defaults one local user could stop every other user's nodes
//! (16 bytes written into the segment: `UnableToGenerateUniqueNodeId`), and a second user could
//! not run at all. The model here: **a domain belongs to one user.**
//! - root (uid 0) keeps iceoryx2's own prefix and root directory, so iceoryx2's tools and
//!   existing deployments see the same entries;
//! - any other user gets the prefix `iox2u<uid>_` and the root directory `/tmp/iceoryx2-u<uid>/`
//!   (0700, checked to be theirs), unless their own iceoryx2 config file set others;
//! - `--iox-domain D` puts `D_` before that prefix;
//! - before a node is created, a management segment under the domain's prefix that belongs to
//!   someone else is refused (another user made it first, and could write to it); after, the
//!   owner makes it 0600, so nobody else can write to it.
//!
//! Two users therefore share no iceoryx2 resource; to share a field between two users run both
//! under one account (or bridge the field, docs/mirrors.md).

use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
use std::path::{Path as StdPath, PathBuf};

use iceoryx2::prelude::*;

use super::error::{DomainError, Iceoryx, NameError};

/// The environment variable naming this process's iceoryx2 domain (`--iox-domain`).
pub const IOX_DOMAIN_ENV: &str = "PHEROMONE_IOX_DOMAIN";

/// iceoryx2's built-in prefix and root directory, which a non-root user's domain replaces.
const ICEORYX2_PREFIX: &str = "iox2_";
const ICEORYX2_ROOT: &str = "/tmp/iceoryx2/";

/// Where POSIX shared memory lives on Linux (iceoryx2's segments among it).
const SHM_DIR: &str = "/dev/shm";

/// The iceoryx2 configuration of this process's domain (`PHEROMONE_IOX_DOMAIN`, else the
/// default one) for the user running it.
pub fn domain_config() -> Result<Config, NameError> {
    domain_config_of(std::env::var(IOX_DOMAIN_ENV).ok().as_deref())
}

/// The iceoryx2 configuration of domain `domain` (`None` or empty: the default one) for the
/// user running this process.
pub fn domain_config_of(domain: Option<&str>) -> Result<Config, NameError> {
    domain_config_for(domain, nix::unistd::geteuid().as_raw())
}

/// The iceoryx2 configuration of domain `domain` for user `uid`: iceoryx2's global
/// configuration (its config file, if any), with this module's per-user prefix and root
/// directory. `D` follows the field-name rules.
pub fn domain_config_for(domain: Option<&str>, uid: u32) -> Result<Config, NameError> {
    let mut config = Config::global_config().clone();
    let domain = domain.filter(|d| !d.is_empty());
    let base = config.global.prefix.to_string();
    let user_prefix = match uid {
        0 => ICEORYX2_PREFIX.to_string(),
        _ => format!("iox2u{uid}_"),
    };
    let prefix = match domain {
        Some(d) => {
            super::check_name(d)?;
            format!("{d}_{user_prefix}")
        }
        None if base == ICEORYX2_PREFIX => user_prefix,
        None => base,
    };
    config.global.prefix = FileName::new(prefix.as_bytes()).map_err(|e| NameError::Iceoryx {
        name: prefix.clone(),
        source: Box::new(Iceoryx(e)),
    })?;
    let root_path = config.global.root_path().to_string();
    if uid != 0 && root_path == ICEORYX2_ROOT {
        let root = format!("/tmp/iceoryx2-u{uid}/");
        let path = Path::new(root.as_bytes()).map_err(|e| NameError::Iceoryx {
            name: root.clone(),
            source: Box::new(Iceoryx(e)),
        })?;
        config.global.set_root_path(&path);
    }
    Ok(config)
}

/// Checks, before a node of `config`'s domain is created, that what the domain already has is
/// this user's own: the root directory (a non-root user's is made here, 0700) and, with
/// `segments`, the management segments under its prefix. A sim's children skip the segments
/// (`CLEANED_BY_SUPERVISOR_ENV`): the sim checked and sealed them as it created its node, before
/// it started them, and each walk lists all of `/dev/shm`, which holds every connection of the
/// run (N walks of N-sized listings: issue 52).
pub(crate) fn guard_domain(config: &Config, segments: bool) -> Result<(), DomainError> {
    let uid = nix::unistd::geteuid().as_raw();
    if uid != 0 {
        let root = PathBuf::from(config.global.root_path().to_string());
        private_root(&root, uid)?;
    }
    if !segments {
        return Ok(());
    }
    for segment in management_segments(config) {
        let meta = match std::fs::symlink_metadata(&segment) {
            Ok(m) => m,
            Err(_) => continue, // removed meanwhile
        };
        if meta.uid() != uid {
            return Err(DomainError::NotPrivate {
                path: segment,
                problem: format!("belongs to uid {}, not to uid {uid}", meta.uid()),
            });
        }
    }
    Ok(())
}

/// After a node of `config`'s domain exists: makes the domain's management segments that this
/// user owns 0600 (iceoryx2 creates them 0666). Best effort: a segment removed meanwhile, or
/// one another process changes, is left to the next node's [`guard_domain`].
pub(crate) fn seal_management_segments(config: &Config) {
    let uid = nix::unistd::geteuid().as_raw();
    for segment in management_segments(config) {
        if let Ok(meta) = std::fs::symlink_metadata(&segment) {
            if meta.uid() == uid && meta.file_type().is_file() && meta.mode() & 0o077 != 0 {
                let _ = std::fs::set_permissions(&segment, std::fs::Permissions::from_mode(0o600));
            }
        }
    }
}

/// The management segments of `config`'s domain present in /dev/shm (one per iceoryx2 version
/// and service variant).
fn management_segments(config: &Config) -> Vec<PathBuf> {
    let prefix = config.global.prefix.to_string();
    let suffix = config.global.node.global_mgmt_suffix.to_string();
    let Ok(entries) = std::fs::read_dir(SHM_DIR) else {
        return Vec::new();
    };
    entries
        .filter_map(Result::ok)
        .filter_map(|e| e.file_name().into_string().ok())
        .filter(|n| n.starts_with(&prefix) && n.ends_with(&suffix))
        .map(|n| StdPath::new(SHM_DIR).join(n))
        .collect()
}

/// Makes `root` (0700) if it is missing and checks that it is a real directory of `uid`'s that
/// nobody else can enter.
fn private_root(root: &StdPath, uid: u32) -> Result<(), DomainError> {
    let io = |source| DomainError::Io {
        path: root.to_path_buf(),
        source,
    };
    match std::fs::DirBuilder::new().mode(0o700).create(root) {
        // Exactly 0700 whatever the umask (0700 less a umask of, e.g., 177 cannot be entered).
        Ok(()) => {
            std::fs::set_permissions(root, std::fs::Permissions::from_mode(0o700)).map_err(io)?
        }
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(io(e)),
    }
    let meta = std::fs::symlink_metadata(root).map_err(io)?;
    let problem = if !meta.file_type().is_dir() {
        Some("is not a directory (a symbolic link or a file)".to_string())
    } else if meta.uid() != uid {
        Some(format!("belongs to uid {}, not to uid {uid}", meta.uid()))
    } else if meta.mode() & 0o077 != 0 {
        Some(format!("is mode {:o}, not 700", meta.mode() & 0o777))
    } else {
        None
    };
    match problem {
        Some(problem) => Err(DomainError::NotPrivate {
            path: root.to_path_buf(),
            problem,
        }),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn root_keeps_iceoryx2s_names_and_other_users_get_their_own() {
        let root = domain_config_for(None, 0).unwrap();
        assert_eq!(root.global.prefix.to_string(), "iox2_");
        assert_eq!(root.global.root_path().to_string(), "/tmp/iceoryx2/");
        let bob = domain_config_for(None, 1001).unwrap();
        assert_eq!(bob.global.prefix.to_string(), "iox2u1001_");
        assert_eq!(bob.global.root_path().to_string(), "/tmp/iceoryx2-u1001/");
        let lab = domain_config_for(Some("lab"), 1001).unwrap();
        assert_eq!(lab.global.prefix.to_string(), "lab_iox2u1001_");
        assert_eq!(lab.global.root_path().to_string(), "/tmp/iceoryx2-u1001/");
        assert_eq!(
            domain_config_for(Some("lab"), 0)
                .unwrap()
                .global
                .prefix
                .to_string(),
            "lab_iox2_"
        );
        assert!(domain_config_for(Some("a/b"), 1001).is_err());
    }

    #[test]
    fn a_root_directory_that_others_can_enter_is_refused_and_named() {
        let dir = tempfile::tempdir().unwrap();
        let uid = nix::unistd::geteuid().as_raw();
        let root = dir.path().join("iox");
        private_root(&root, uid).unwrap();
        assert_eq!(
            std::fs::metadata(&root).unwrap().permissions().mode() & 0o777,
            0o700
        );
        std::fs::set_permissions(&root, std::fs::Permissions::from_mode(0o755)).unwrap();
        let err = private_root(&root, uid).unwrap_err().to_string();
        assert!(err.contains("is mode 755") && err.contains("iox"), "{err}");
        let err = private_root(&root, uid + 1).unwrap_err().to_string();
        assert!(err.contains(&format!("belongs to uid {uid}")), "{err}");
        let link = dir.path().join("link");
        std::os::unix::fs::symlink(&root, &link).unwrap();
        let err = private_root(&link, uid).unwrap_err().to_string();
        assert!(err.contains("not a directory"), "{err}");
    }
}
