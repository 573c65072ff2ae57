//! Output files written without harm to what is there: a regular file through a temporary file
//! beside it, renamed over it once complete (a failed or interrupted write leaves the path as it
//! was, never a truncated file); a symbolic link followed to the file it names (the link stays
//! a link); anything else — a FIFO, a terminal, any name under `/dev` or `/proc` — written
//! directly, as a shell redirection would (`/dev/stdout` through the standard output itself).
//! Nothing is opened before the write but regular files, so a FIFO sees exactly one writer.

use std::io::Write;
use std::path::{Path, PathBuf};

/// Symbolic links followed at most this many times (Linux's own limit, `ELOOP`).
const MAX_LINKS: usize = 40;

/// The path `path` names once its symbolic links are followed: the file a write reaches, which
/// may not exist yet (a dangling link names its missing target).
fn resolved(path: &Path) -> std::io::Result<PathBuf> {
    let mut path = path.to_path_buf();
    for _ in 0..MAX_LINKS {
        match std::fs::symlink_metadata(&path) {
            Ok(meta) if meta.file_type().is_symlink() => {
                let target = std::fs::read_link(&path)?;
                path = match path.parent() {
                    Some(dir) => dir.join(target), // `target` itself when absolute
                    None => target,
                };
            }
            _ => return Ok(path),
        }
    }
    Err(std::io::Error::other(format!(
        "more than {MAX_LINKS} symbolic links"
    )))
}

/// Whether `path` is written directly: a FIFO, a device or a socket (links followed), or a name
/// under `/dev` or `/proc` (`/dev/stdout` redirected to a file names that file: replacing it
/// would leave the shell's redirection writing to the old one).
fn is_special(path: &Path) -> bool {
    path.starts_with("/dev")
        || path.starts_with("/proc")
        || std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

/// Fails now when `path` cannot be written later (its folder is missing or not writable, it is
/// a folder, the file is read-only), so a long command does not lose its result at the end.
/// Nothing changes at `path`: an existing file is opened for writing without truncation, a
/// missing one is tried as a temporary file beside it, removed again; FIFOs and devices are
/// not opened (a FIFO would block, and its reader would see an empty file).
pub fn check_writable(path: &Path) -> std::io::Result<()> {
    let target = resolved(path)?;
    if is_special(path) || is_special(&target) {
        return Ok(());
    }
    if target.is_dir() {
        return Err(std::io::Error::other("is a folder"));
    }
    if target.exists() {
        std::fs::OpenOptions::new().write(true).open(&target)?;
    }
    let probe = crate::durable::temporary_beside(&target);
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)?;
    std::fs::remove_file(&probe)
}

/// Writes `path` with `write`, as the module says: the (link-resolved) target replaced as
/// [`crate::durable`] replaces a file, keeping an existing file's permissions; FIFOs and devices directly;
/// `/dev/stdout` through the standard output.
pub fn write_file(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> std::io::Result<()> {
    if ["/dev/stdout", "/dev/fd/1", "/proc/self/fd/1"]
        .iter()
        .any(|name| path == Path::new(name))
    {
        // Through the process's own standard output, which keeps its place in a file it is
        // redirected to (a second descriptor of that file would write over what was printed).
        let mut out = std::io::stdout().lock();
        write(&mut out)?;
        return out.flush();
    }
    let target = resolved(path)?;
    if is_special(path) || is_special(&target) {
        let mut out = std::io::BufWriter::new(std::fs::OpenOptions::new().write(true).open(path)?);
        write(&mut out)?;
        return out.flush();
    }
    crate::durable::replace(&target, write)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::symlink;

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("rgm-output-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn leftovers(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    #[test]
    fn a_failed_write_leaves_the_file_as_it_was() {
        let dir = scratch("failed");
        let path = dir.join("out.xyz");
        std::fs::write(&path, "old\n").unwrap();
        let err = write_file(&path, |out: &mut dyn Write| {
            out.write_all(b"half")?;
            Err(std::io::Error::other("disk full"))
        })
        .unwrap_err();
        assert_eq!(err.to_string(), "disk full");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "old\n");
        assert_eq!(leftovers(&dir), ["out.xyz"]);
        write_file(&path, |out: &mut dyn Write| out.write_all(b"new\n")).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "new\n");
        assert_eq!(leftovers(&dir), ["out.xyz"]);
    }

    #[test]
    fn links_stay_links_and_dangling_ones_are_left_alone_by_the_check() {
        // Issue 27, case 8: the check followed a dangling link, created its target, then
        // removed the link; a write replaced the link by a regular file.
        let dir = scratch("links");
        let (link, target) = (dir.join("link.ply"), dir.join("real.ply"));
        symlink("real.ply", &link).unwrap();
        check_writable(&link).unwrap();
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert!(!target.exists());
        write_file(&link, |out: &mut dyn Write| out.write_all(b"points")).unwrap();
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "points");
        assert_eq!(leftovers(&dir), ["link.ply", "real.ply"]);
    }

    #[test]
    fn folders_and_missing_folders_are_refused() {
        let dir = scratch("folders");
        assert_eq!(check_writable(&dir).unwrap_err().to_string(), "is a folder");
        let nowhere = dir.join("missing/out.ply");
        assert!(check_writable(&nowhere).is_err());
        assert!(write_file(&nowhere, |out: &mut dyn Write| out.write_all(b"x")).is_err());
        assert!(leftovers(&dir).is_empty());
    }

    #[test]
    fn devices_are_written_directly() {
        check_writable(Path::new("/dev/null")).unwrap();
        write_file(Path::new("/dev/null"), |out: &mut dyn Write| {
            out.write_all(b"gone")
        })
        .unwrap();
    }
}
