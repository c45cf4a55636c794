//! This user's own iceoryx2 root directory, where iceoryx2 keeps the node and service files
//! and the event sockets of every run (shared memory itself lives in `/dev/shm`).
//!
//! iceoryx2's default root, `/tmp/iceoryx2/`, is one directory for every user of a machine:
//! the first user to run anything over iceoryx2 creates it (mode 0750), and every other
//! user's runs then fail to create their node. So each user gets `/tmp/flockstep-<euid>/`,
//! created 0700, and a directory of that name that another user could have planted or can
//! write to is refused instead of trusted.

use super::TransportError;
use std::io::ErrorKind;
use std::os::unix::fs::{DirBuilderExt, MetadataExt};
use std::path::{Path, PathBuf};

/// This user's root. Fixed under `/tmp` rather than `std::env::temp_dir()`: every process of
/// a run, including an `agent --attach` a user starts later from another shell, must find the
/// same files, so the path may not depend on a process's environment (`TMPDIR`); and the
/// event sockets under it must stay within the 108 bytes of a Unix socket path.
pub fn iceoryx_root() -> PathBuf {
    PathBuf::from(format!("/tmp/flockstep-{}", effective_uid()))
}

/// The files are created with the effective uid, so that is the owner the root must have.
pub(super) fn effective_uid() -> u32 {
    // SAFETY: geteuid takes no arguments and cannot fail.
    unsafe { libc::geteuid() }
}

/// Creates this user's root if it is missing and checks it; see [`prepare`].
pub(super) fn ensure_root() -> Result<PathBuf, TransportError> {
    let root = iceoryx_root();
    prepare(&root, effective_uid())?;
    Ok(root)
}

/// Creates `dir` with mode 0700 if it is missing, then refuses it unless it is a real
/// directory (not a symlink) owned by `uid` that neither group nor others can write. In the
/// sticky `/tmp` no other user can remove or rename a directory `uid` owns, so a checked root
/// stays checked; one another user created first fails the check.
fn prepare(dir: &Path, uid: u32) -> Result<(), TransportError> {
    match std::fs::DirBuilder::new().mode(0o700).create(dir) {
        Ok(()) => {}
        // Someone (another process of this user, or not) created it first: the check decides.
        Err(e) if e.kind() == ErrorKind::AlreadyExists => {}
        Err(cause) => {
            return Err(TransportError::Io {
                what: format!("creating the iceoryx2 root {}", dir.display()),
                cause,
            })
        }
    }
    let meta = std::fs::symlink_metadata(dir).map_err(|cause| TransportError::Io {
        what: format!("inspecting the iceoryx2 root {}", dir.display()),
        cause,
    })?;
    let problem = if meta.file_type().is_symlink() {
        "is a symbolic link".to_string()
    } else if !meta.is_dir() {
        "is not a directory".to_string()
    } else if meta.uid() != uid {
        format!("is owned by uid {}, not by this user (uid {uid})", meta.uid())
    } else if meta.mode() & 0o022 != 0 {
        format!("is writable by group or others (mode {:04o})", meta.mode() & 0o7777)
    } else {
        return Ok(());
    };
    Err(TransportError::UnsafeRoot { path: dir.to_path_buf(), problem })
}

#[cfg(test)]
mod tests {
    //! Each test prepares a directory inside its own temporary directory, never the real root,
    //! so they run in parallel and as any user.

    use super::*;
    use std::os::unix::fs::PermissionsExt;

    fn refusal(dir: &Path, uid: u32) -> String {
        let error = prepare(dir, uid).expect_err("the root must be refused");
        assert!(matches!(error, TransportError::UnsafeRoot { .. }), "{error}");
        let text = error.to_string();
        assert!(text.contains(&dir.display().to_string()), "names the path: {text}");
        text
    }

    #[test]
    fn a_missing_root_is_created_private_and_owned_by_this_user() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("root");
        prepare(&root, effective_uid()).unwrap();
        let meta = std::fs::symlink_metadata(&root).unwrap();
        assert!(meta.is_dir());
        assert_eq!(meta.uid(), effective_uid());
        assert_eq!(meta.mode() & 0o7777, 0o700);
        // A second process of the run finds it and accepts it.
        prepare(&root, effective_uid()).unwrap();
    }

    #[test]
    fn a_root_that_is_a_symlink_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let target = tmp.path().join("target");
        std::fs::DirBuilder::new().mode(0o700).create(&target).unwrap();
        let root = tmp.path().join("root");
        std::os::unix::fs::symlink(&target, &root).unwrap();
        assert!(refusal(&root, effective_uid()).contains("is a symbolic link"));
    }

    #[test]
    fn a_root_that_is_a_file_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("root");
        std::fs::write(&root, b"").unwrap();
        assert!(refusal(&root, effective_uid()).contains("is not a directory"));
    }

    #[test]
    fn a_root_owned_by_another_user_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("root");
        std::fs::DirBuilder::new().mode(0o700).create(&root).unwrap();
        let other = effective_uid().wrapping_add(1);
        let text = refusal(&root, other);
        assert!(text.contains(&format!("is owned by uid {}", effective_uid())), "{text}");
        assert!(text.contains(&format!("not by this user (uid {other})")), "{text}");
    }

    #[test]
    fn a_root_writable_by_group_or_others_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("root");
        std::fs::DirBuilder::new().mode(0o700).create(&root).unwrap();
        for mode in [0o770, 0o702, 0o1777] {
            std::fs::set_permissions(&root, std::fs::Permissions::from_mode(mode)).unwrap();
            let text = refusal(&root, effective_uid());
            assert!(text.contains(&format!("is writable by group or others (mode {mode:04o})")));
        }
    }
}
