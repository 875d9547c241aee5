//! The files a glTF's URIs name, confined to the input's folder.
//!
//! A relative URI is resolved against the folder of the glTF file; the path it leads to, with
//! every symbolic link followed, must lie inside that folder or inside a folder allowed on
//! purpose ([`super::LoadOptions::allow_outside`], `--allow-outside DIR`). An absolute path, a `..` that climbs
//! out, or a link that leads out is refused, and so is anything that is not a regular file (a
//! FIFO, a device, a directory): its metadata is checked before it is opened, it is opened
//! without blocking, and checked again through the open handle. At most the input limit
//! ([`super::Limits::input_bytes`]) is read from it, so a file that never ends is refused
//! once it passes the limit.

use std::io::Read;
use std::path::{Component, Path, PathBuf};

/// Why a URI was refused, or what reading its file found.
pub(crate) type Refusal = String;

/// The folders a glTF's URIs may lead into: the input's own, plus the ones allowed on purpose
/// (`--allow-outside DIR`).
pub(crate) struct Confinement<'a> {
    /// Folders allowed besides the input's own, as given.
    pub(crate) allow: &'a [PathBuf],
}

impl Confinement<'_> {
    /// The canonical folders a URI of `gltf_path` may lead into (the input's folder first).
    fn roots(&self, dir: &Path) -> Result<Vec<PathBuf>, Refusal> {
        let mut roots = Vec::with_capacity(1 + self.allow.len());
        let own = std::fs::canonicalize(dir)
            .map_err(|e| format!("cannot resolve the input's folder {}: {e}", dir.display()))?;
        roots.push(own);
        for extra in self.allow {
            // A folder that does not exist allows nothing.
            if let Ok(c) = std::fs::canonicalize(extra) {
                roots.push(c);
            }
        }
        Ok(roots)
    }

    /// The regular file a (percent-decoded) relative URI names, checked against the roots.
    pub(crate) fn resolve(&self, gltf_path: &Path, decoded: &str) -> Result<PathBuf, Refusal> {
        let dir = match gltf_path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let named = Path::new(decoded);
        let absolute = named.has_root() || named.is_absolute();
        let joined = if absolute {
            named.to_path_buf()
        } else {
            dir.join(named)
        };
        let roots = self.roots(dir)?;
        let outside_word = if self.allow.is_empty() {
            format!("outside the input's folder {}", roots[0].display())
        } else {
            format!(
                "outside the input's folder {} and the --allow-outside folders",
                roots[0].display()
            )
        };
        let hint = "penumbra reads only files in the input's folder; \
                    --allow-outside DIR allows another folder on purpose";
        if absolute && !self.inside_lexically(&roots, named) {
            return Err(format!("is an absolute path {outside_word} ({hint})"));
        }
        if !absolute && climbs_out(named) && !self.inside_lexically(&roots, &joined) {
            return Err(format!("climbs out with '..' {outside_word} ({hint})"));
        }
        let canonical = std::fs::canonicalize(&joined)
            .map_err(|e| format!("cannot read {}: {e}", joined.display()))?;
        if !roots.iter().any(|r| canonical.starts_with(r)) {
            return Err(format!(
                "leads through a symbolic link to {}, {outside_word} ({hint})",
                canonical.display()
            ));
        }
        let meta = std::fs::metadata(&canonical)
            .map_err(|e| format!("cannot read {}: {e}", canonical.display()))?;
        if !meta.is_file() {
            return Err(format!(
                "names {}, which is {}, not a regular file",
                canonical.display(),
                kind_of(&meta)
            ));
        }
        Ok(canonical)
    }

    /// Whether `path` (with `..` taken lexically) lies in one of the roots; for messages that
    /// tell an absolute or climbing URI from an allowed one before the file is looked at.
    fn inside_lexically(&self, roots: &[PathBuf], path: &Path) -> bool {
        let Ok(abs) = std::path::absolute(path) else {
            return false;
        };
        let mut clean = PathBuf::new();
        for c in abs.components() {
            match c {
                Component::ParentDir => {
                    clean.pop();
                }
                Component::CurDir => {}
                other => clean.push(other),
            }
        }
        let canon_prefix = |p: &Path| {
            // The roots are canonical; so is the part of `clean` that exists.
            let mut existing = p.to_path_buf();
            let mut rest = Vec::new();
            while !existing.exists() {
                match (
                    existing.file_name().map(|n| n.to_os_string()),
                    existing.parent(),
                ) {
                    (Some(n), Some(parent)) => {
                        rest.push(n);
                        existing = parent.to_path_buf();
                    }
                    _ => break,
                }
            }
            let mut out = std::fs::canonicalize(&existing).unwrap_or(existing);
            for n in rest.into_iter().rev() {
                out.push(n);
            }
            out
        };
        let clean = canon_prefix(&clean);
        roots.iter().any(|r| clean.starts_with(r))
    }
}

/// Whether a relative path's `..` components climb above its start.
fn climbs_out(path: &Path) -> bool {
    let mut depth = 0i64;
    for c in path.components() {
        match c {
            Component::ParentDir => {
                depth -= 1;
                if depth < 0 {
                    return true;
                }
            }
            Component::Normal(_) => depth += 1,
            _ => {}
        }
    }
    false
}

/// What a file that is not a regular file is, for messages.
pub(crate) fn kind_of(meta: &std::fs::Metadata) -> &'static str {
    let t = meta.file_type();
    if t.is_dir() {
        return "a directory";
    }
    if t.is_symlink() {
        return "a symbolic link";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_char_device() || t.is_block_device() {
            return "a device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    "a special file"
}

/// Opens `path` for reading without blocking on a FIFO, and checks through the handle that it is
/// a regular file (it may have been replaced since it was looked at).
pub(crate) fn open_regular(path: &Path) -> Result<std::fs::File, Refusal> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options
        .open(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let meta = file
        .metadata()
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    if !meta.is_file() {
        return Err(format!(
            "names {}, which is {}, not a regular file",
            path.display(),
            kind_of(&meta)
        ));
    }
    Ok(file)
}

/// Reads at most `limit` bytes from `reader`; more is refused (naming `option`, which raises
/// the limit), without reading past `limit + 1` bytes.
pub(crate) fn read_limited(
    reader: impl Read,
    limit: u64,
    option: &str,
    what: &Path,
) -> Result<Vec<u8>, Refusal> {
    let mut bytes = Vec::new();
    reader
        .take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| format!("cannot read {}: {e}", what.display()))?;
    if bytes.len() as u64 > limit {
        return Err(format!(
            "{} holds more than {}, the input limit ({option} raises it)",
            what.display(),
            size_text(limit)
        ));
    }
    Ok(bytes)
}

/// A size for messages: `2048 MiB`, or `300 bytes` below a mebibyte.
pub(crate) fn size_text(bytes: u64) -> String {
    if bytes >= super::limits::MIB {
        format!("{} MiB", bytes / super::limits::MIB)
    } else {
        format!("{bytes} bytes")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dots_that_stay_inside_do_not_climb_out() {
        assert!(!climbs_out(Path::new("a/../b.bin")));
        assert!(!climbs_out(Path::new("./a/b.bin")));
        assert!(climbs_out(Path::new("../b.bin")));
        assert!(climbs_out(Path::new("a/../../b.bin")));
    }

    #[test]
    fn only_regular_files_inside_the_folder_resolve() {
        let dir = std::env::temp_dir().join(format!("penumbra-uri-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let inside = dir.join("in");
        std::fs::create_dir_all(inside.join("a")).unwrap();
        std::fs::write(inside.join("b.bin"), b"b").unwrap();
        std::fs::write(dir.join("secret.bin"), b"s").unwrap();
        let gltf = inside.join("scene.gltf");
        let none = Confinement { allow: &[] };
        let canonical = std::fs::canonicalize(inside.join("b.bin")).unwrap();
        assert_eq!(none.resolve(&gltf, "b.bin").unwrap(), canonical);
        assert_eq!(none.resolve(&gltf, "a/../b.bin").unwrap(), canonical);
        let e = none.resolve(&gltf, "../secret.bin").unwrap_err();
        assert!(e.contains("climbs out"), "{e}");
        let secret = dir.join("secret.bin");
        let e = none.resolve(&gltf, secret.to_str().unwrap()).unwrap_err();
        assert!(e.contains("absolute path"), "{e}");
        let e = none.resolve(&gltf, "a").unwrap_err();
        assert!(e.contains("a directory"), "{e}");
        // Allowed on purpose: the parent folder.
        let allow = [dir.clone()];
        let wide = Confinement { allow: &allow };
        assert!(wide.resolve(&gltf, "../secret.bin").is_ok());
        assert!(wide.resolve(&gltf, secret.to_str().unwrap()).is_ok());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_read_stops_past_the_limit() {
        let endless = std::io::repeat(7);
        let e = read_limited(endless, 1000, "--max-input-mib", Path::new("x")).unwrap_err();
        assert!(e.contains("more than 1000 bytes"), "{e}");
        let ok = read_limited(&[1u8, 2, 3][..], 3, "--max-input-mib", Path::new("x")).unwrap();
        assert_eq!(ok, [1, 2, 3]);
    }
}
