//! Output files: checked against the inputs and each other, written to temporary files first
//! and renamed into place together, and cleaned up when the process is interrupted.
//!
//! The rules every command follows:
//!
//! - **The input is never written.** An output that is the input file, by any path (`./a/../in.glb`,
//!   a symbolic link, a hard link), or any file the input reads (a `.gltf`'s external buffers and
//!   images), is refused before any work starts. So is one output named twice (`--exr OUT`).
//! - **Links are followed.** An output path that is a symbolic link is written through: its
//!   target is replaced and the link stays a link.
//! - **Only regular files are replaced.** An output that exists must be a regular file (or a
//!   link to one): a directory, a device (`/dev/null`, `/dev/full`), a FIFO or a socket is
//!   refused, never replaced by a regular file.
//! - **Short temporary names.** A temporary file's name keeps at most [`TMP_STEM_BYTES`] bytes
//!   of its destination's, so it stays within the 255-byte limit of a file name whatever the
//!   destination's.
//! - **All or nothing.** Every output is written to a temporary file beside its destination
//!   ([`Staged::add`]); only when all are written are they renamed into place ([`Staged::commit`]).
//!   A failure, a panic or a SIGINT/SIGTERM/SIGHUP ([`clean_up_on_signals`]) removes the
//!   temporary files and leaves the destinations as they were.

use crate::error::{Error, Result};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Temporary files written but not yet renamed into place, removed on a signal. Held locked
/// while [`Staged::commit`] renames, so a signal lands before or after all the renames.
static PENDING: Mutex<BTreeSet<PathBuf>> = Mutex::new(BTreeSet::new());

fn pending() -> std::sync::MutexGuard<'static, BTreeSet<PathBuf>> {
    PENDING.lock().unwrap_or_else(|e| e.into_inner())
}

/// Removes every pending temporary file.
fn remove_pending() {
    let mut files = pending();
    for f in files.iter() {
        let _ = std::fs::remove_file(f);
    }
    files.clear();
}

/// The error of a signal handler that could not be installed.
fn handler_error(source: std::io::Error) -> Error {
    Error::Write {
        path: PathBuf::from("(signal handlers)"),
        source,
    }
}

/// Installs handlers for SIGINT, SIGTERM and SIGHUP that remove every pending temporary file,
/// then end the process as the signal's default action would (so the exit status still says
/// which signal it was). Call once, early in `main`.
#[cfg(unix)]
pub fn clean_up_on_signals() -> Result<()> {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    let mut signals =
        signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]).map_err(handler_error)?;
    std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || {
            if let Some(signal) = signals.forever().next() {
                remove_pending();
                let _ = signal_hook::low_level::emulate_default_handler(signal);
                std::process::exit(128 + signal);
            }
        })
        .map_err(handler_error)?;
    Ok(())
}

/// Installs a console handler (the `ctrlc` crate) for Ctrl+C, Ctrl+Break and the console's
/// close, logoff and shutdown events that removes every pending temporary file, then ends the
/// process with `STATUS_CONTROL_C_EXIT`, as Windows ends a process on Ctrl+C. On a close,
/// logoff or shutdown Windows ends the process soon after the event, so the removal there is
/// a race it may lose. Call once, early in `main`.
#[cfg(windows)]
pub fn clean_up_on_signals() -> Result<()> {
    /// `STATUS_CONTROL_C_EXIT`, 0xC000013A, as an exit code.
    const CONTROL_C_EXIT: i32 = 0xC000_013A_u32 as i32;
    ctrlc::set_handler(|| {
        remove_pending();
        std::process::exit(CONTROL_C_EXIT);
    })
    .map_err(|e| handler_error(std::io::Error::other(e)))
}

/// Where the platform has neither Unix signals nor Windows console events, nothing to install.
#[cfg(not(any(unix, windows)))]
pub fn clean_up_on_signals() -> Result<()> {
    Ok(())
}

/// What identifies a file on disk: device and inode where it exists, else the canonical path of
/// its directory plus its name.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Identity {
    #[cfg(unix)]
    Inode(u64, u64),
    Path(PathBuf),
}

fn identity(path: &Path) -> Option<Identity> {
    if let Ok(meta) = std::fs::metadata(path) {
        #[cfg(unix)]
        {
            use std::os::unix::fs::MetadataExt;
            return Some(Identity::Inode(meta.dev(), meta.ino()));
        }
        #[cfg(not(unix))]
        {
            let _ = meta;
            return std::fs::canonicalize(path).ok().map(Identity::Path);
        }
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = path.file_name()?;
    Some(Identity::Path(std::fs::canonicalize(dir).ok()?.join(name)))
}

/// Checks output paths before any work starts, and returns them with symbolic links resolved
/// (each to the file it finally points at, which is what gets replaced).
///
/// `inputs`: every file the command reads. `outputs`: `(what, path)`, where `what` names the
/// output in messages (`"OUT"`, `"--exr"`). Refused, with [`Error::Output`]: an output that is
/// an input, one file named by two outputs, a directory, a dangling link, a missing directory.
pub fn check_outputs(
    inputs: &[PathBuf],
    outputs: &[(&'static str, &Path)],
) -> Result<Vec<PathBuf>> {
    let refuse = |what: &'static str, reason: String| Error::Output { what, reason };
    let input_ids: Vec<(Identity, &PathBuf)> = inputs
        .iter()
        .filter_map(|p| identity(p).map(|id| (id, p)))
        .collect();
    let mut seen: Vec<(Identity, &'static str)> = Vec::new();
    let mut resolved = Vec::new();
    for &(what, path) in outputs {
        let is_link = std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink());
        let target = if is_link {
            std::fs::canonicalize(path).map_err(|e| {
                refuse(
                    what,
                    format!(
                        "{} is a symbolic link that leads nowhere ({e})",
                        path.display()
                    ),
                )
            })?
        } else {
            path.to_path_buf()
        };
        if target.is_dir() {
            return Err(refuse(
                what,
                format!("{} is a directory, not a file", path.display()),
            ));
        }
        if let Ok(meta) = std::fs::metadata(&target)
            && !meta.is_file()
        {
            return Err(refuse(
                what,
                format!(
                    "{} is {}, not a regular file (penumbra writes a file beside it and renames \
                     it into place, which would replace it)",
                    path.display(),
                    crate::load::uri::kind_of(&meta)
                ),
            ));
        }
        let id = identity(&target).ok_or_else(|| {
            refuse(
                what,
                format!(
                    "cannot write {}: its directory does not exist",
                    path.display()
                ),
            )
        })?;
        if let Some((_, input)) = input_ids.iter().find(|(i, _)| *i == id) {
            return Err(refuse(
                what,
                format!(
                    "{} is the input file {} (penumbra never overwrites its input; choose another output)",
                    path.display(),
                    input.display()
                ),
            ));
        }
        if let Some((_, other)) = seen.iter().find(|(i, _)| *i == id) {
            return Err(refuse(
                what,
                format!(
                    "{} is also the {other} output; each output needs its own file",
                    path.display()
                ),
            ));
        }
        seen.push((id, what));
        resolved.push(target);
    }
    Ok(resolved)
}

/// Outputs written to temporary files, renamed into place together by [`Staged::commit`];
/// dropped uncommitted (an error, a panic), it removes its temporary files.
#[derive(Default)]
pub struct Staged {
    /// `(temporary, destination)`, in the order added.
    files: Vec<(PathBuf, PathBuf)>,
}

impl Staged {
    pub fn new() -> Staged {
        Staged::default()
    }

    /// Writes `bytes` to a temporary file beside `path` (registered for cleanup on signals).
    pub fn add(&mut self, path: &Path, bytes: &[u8]) -> Result<()> {
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "out".into());
        let tmp = dir.join(format!(
            ".{}.penumbra-{}-{}.tmp",
            truncated(&name, TMP_STEM_BYTES),
            std::process::id(),
            self.files.len()
        ));
        pending().insert(tmp.clone());
        self.files.push((tmp.clone(), path.to_path_buf()));
        std::fs::write(&tmp, bytes).map_err(|source| Error::Write {
            path: path.to_path_buf(),
            source,
        })
    }

    /// Renames every temporary file into place. Signals wait until all are renamed.
    pub fn commit(mut self) -> Result<()> {
        let mut files = pending();
        let staged = std::mem::take(&mut self.files);
        let mut result = Ok(());
        for (tmp, path) in &staged {
            if result.is_ok() {
                result = std::fs::rename(tmp, path).map_err(|source| Error::Write {
                    path: path.clone(),
                    source,
                });
            }
            if result.is_err() {
                let _ = std::fs::remove_file(tmp);
            }
            files.remove(tmp);
        }
        result
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        let mut files = pending();
        for (tmp, _) in self.files.drain(..) {
            let _ = std::fs::remove_file(&tmp);
            files.remove(&tmp);
        }
    }
}

/// The most bytes of a destination's name that its temporary file's name keeps: with the dot,
/// the process id and the counter, the name stays well within 255 bytes.
pub(crate) const TMP_STEM_BYTES: usize = 128;

/// The longest prefix of `name` of at most `max` bytes that ends on a character boundary.
fn truncated(name: &str, max: usize) -> &str {
    let mut end = name.len().min(max);
    while !name.is_char_boundary(end) {
        end -= 1;
    }
    &name[..end]
}

/// Writes `bytes` to `path` through a temporary file and a rename, so a failure never leaves a
/// partial file.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut staged = Staged::new();
    staged.add(path, bytes)?;
    staged.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("penumbra-files-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[cfg(unix)]
    #[test]
    fn the_input_is_refused_by_any_path() {
        let dir = scratch("input");
        let input = dir.join("in.glb");
        std::fs::write(&input, b"x").unwrap();
        std::fs::create_dir(dir.join("a")).unwrap();
        let dotted = dir.join("a").join("..").join("in.glb");
        let link = dir.join("link.glb");
        std::os::unix::fs::symlink(&input, &link).unwrap();
        let hard = dir.join("hard.glb");
        std::fs::hard_link(&input, &hard).unwrap();
        for out in [&input, &dotted, &link, &hard] {
            let e = check_outputs(std::slice::from_ref(&input), &[("OUT", out)]).unwrap_err();
            assert!(e.to_string().contains("never overwrites its input"), "{e}");
        }
        let fine = dir.join("out.glb");
        assert_eq!(
            check_outputs(std::slice::from_ref(&input), &[("OUT", &fine)]).unwrap(),
            vec![fine.clone()]
        );
        // Two outputs naming one file, existing or not.
        let e = check_outputs(
            std::slice::from_ref(&input),
            &[("OUT", &fine), ("--exr", &fine)],
        )
        .unwrap_err();
        assert!(e.to_string().contains("also the OUT output"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn a_link_output_is_written_through() {
        let dir = scratch("link");
        let target = dir.join("target.glb");
        std::fs::write(&target, b"old").unwrap();
        let link = dir.join("link.glb");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        let out = check_outputs(&[], &[("OUT", &link)]).unwrap();
        write_atomically(&out[0], b"new").unwrap();
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        let dangling = dir.join("dangling.glb");
        std::os::unix::fs::symlink(dir.join("nowhere/x.glb"), &dangling).unwrap();
        assert!(check_outputs(&[], &[("OUT", &dangling)]).is_err());
        assert!(check_outputs(&[], &[("OUT", &dir)]).is_err());
        assert!(check_outputs(&[], &[("OUT", &dir.join("no/such/dir.glb"))]).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn temporary_names_stay_short() {
        assert_eq!(truncated("abc", 2), "ab");
        // Never inside a character: "é" is two bytes.
        assert_eq!(truncated("aé", 2), "a");
        let dir = scratch("long-name");
        let long = dir.join(format!("{}.glb", "é".repeat(125)));
        write_atomically(&long, b"x").unwrap();
        assert_eq!(std::fs::read(&long).unwrap(), b"x");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn staged_outputs_appear_together_or_not_at_all() {
        let dir = scratch("staged");
        let a = dir.join("a.bin");
        let b = dir.join("b.bin");
        {
            let mut s = Staged::new();
            s.add(&a, b"1").unwrap();
            s.add(&b, b"2").unwrap();
            assert!(!a.exists() && !b.exists());
            // Dropped without commit: nothing appears, nothing is left.
        }
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
        let mut s = Staged::new();
        s.add(&a, b"1").unwrap();
        s.add(&b, b"2").unwrap();
        s.commit().unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), b"1");
        assert_eq!(std::fs::read(&b).unwrap(), b"2");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 2);
        assert!(pending().iter().all(|p| !p.starts_with(&dir)));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
