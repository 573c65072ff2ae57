//! Files that a kill or a power cut never leaves half written, and files for one process at a
//! time: the one place rgm replaces a file (written clouds, the outputs of pair lists,
//! evaluation records, training checkpoints, the runner's packs and tables) and locks one (a
//! pair list's output, a training run).
//!
//! A file is replaced through a temporary file beside it: written, flushed to the disk, given
//! the permissions of the file it replaces, renamed over it, and the folder flushed, so that
//! afterwards the path holds the old file or the new one, whole, and the rename itself
//! outlasts a power cut. On an error the temporary is removed and the old file stands.

use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

/// The temporary file beside `path` that a replacement writes first: hidden, and named for
/// this process, so that two processes never write the same one.
pub fn temporary_beside(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or_else(|| "output".into(), |n| n.to_string_lossy().into_owned());
    path.with_file_name(format!(".{name}.rgm-{}.tmp", std::process::id()))
}

/// Flushes the file or folder at `path` to the disk.
pub fn sync(path: &Path) -> io::Result<()> {
    File::open(path)?.sync_all()
}

/// Flushes the folder that holds `path`, so that a rename in it is on the disk.
fn sync_folder_of(path: &Path) -> io::Result<()> {
    match path.parent().filter(|p| !p.as_os_str().is_empty()) {
        Some(folder) => sync(folder),
        None => sync(Path::new(".")),
    }
}

/// Puts the written `temporary` (open as `file`) in the place of `path`.
fn commit(temporary: &Path, path: &Path, file: &File) -> io::Result<()> {
    file.sync_all()?;
    if let Ok(existing) = fs::metadata(path) {
        fs::set_permissions(temporary, existing.permissions())?;
    }
    fs::rename(temporary, path)?;
    sync_folder_of(path)
}

/// Replaces `path` with what `write` puts in a new file beside it, opened by `options`
/// (`create_new` is added): the module's protocol. The file comes back open, as `write` left
/// it, for a caller that goes on appending to it or holds its lock (taken in `write`, before
/// the rename, so that no other process finds the new file unlocked).
pub fn replace_with(
    path: &Path,
    options: &OpenOptions,
    write: impl FnOnce(&mut File) -> io::Result<()>,
) -> io::Result<File> {
    let temporary = temporary_beside(path);
    let replaced = (|| {
        let mut file = options.clone().create_new(true).open(&temporary)?;
        write(&mut file)?;
        commit(&temporary, path, &file)?;
        Ok(file)
    })();
    if replaced.is_err() {
        let _ = fs::remove_file(&temporary); // may not exist; the write's error is the one to tell
    }
    replaced
}

/// Replaces `path` with what `write` writes, through a buffer.
pub fn replace(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> io::Result<()> {
    replace_with(path, OpenOptions::new().write(true), |file| {
        let mut out = BufWriter::new(file);
        write(&mut out)?;
        out.flush()
    })
    .map(drop)
}

/// Replaces `path` with the file `write` makes at the path it is given (the temporary beside
/// `path`), for writers that take a path rather than a stream.
pub fn replace_via<E: From<io::Error>>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), E> {
    let temporary = temporary_beside(path);
    let replaced = write(&temporary).and_then(|()| {
        let file = File::open(&temporary)?;
        commit(&temporary, path, &file).map_err(E::from)
    });
    if replaced.is_err() {
        let _ = fs::remove_file(&temporary);
    }
    replaced
}

/// Why [`lock`] holds no lock.
#[derive(Debug)]
pub enum LockError {
    /// Another process holds it.
    Busy,
    /// The file could not be opened or locked.
    Io(io::Error),
}

/// `path` opened by `options` and locked for this process alone (an advisory lock, let go when
/// the file is closed); [`LockError::Busy`] when another process holds it. A lock taken on a
/// file that another process's [`replace_with`] renamed away meanwhile is let go and taken
/// again on the file now at `path`.
pub fn lock(path: &Path, options: &OpenOptions) -> Result<File, LockError> {
    loop {
        let file = options.open(path).map_err(LockError::Io)?;
        match file.try_lock() {
            Ok(()) => {}
            Err(fs::TryLockError::WouldBlock) => return Err(LockError::Busy),
            Err(fs::TryLockError::Error(error)) => return Err(LockError::Io(error)),
        }
        if same_file(&file, path) {
            return Ok(file);
        }
    }
}

#[cfg(unix)]
fn same_file(file: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (file.metadata(), fs::metadata(path)) {
        (Ok(a), Ok(b)) => (a.dev(), a.ino()) == (b.dev(), b.ino()),
        _ => false,
    }
}

#[cfg(not(unix))]
fn same_file(_: &File, _: &Path) -> bool {
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("rgm-durable-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn a_replacement_keeps_the_permissions_and_leaves_no_temporary() {
        let dir = scratch("replace");
        let path = dir.join("out.txt");
        fs::write(&path, "old").unwrap();
        fs::set_permissions(&path, fs::Permissions::from_mode(0o640)).unwrap();
        replace(&path, |out| out.write_all(b"new")).unwrap();
        assert_eq!(fs::read_to_string(&path).unwrap(), "new");
        assert_eq!(
            fs::metadata(&path).unwrap().permissions().mode() & 0o777,
            0o640
        );
        assert_eq!(fs::read_dir(&dir).unwrap().count(), 1);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_failed_write_leaves_the_old_file_whole_and_no_temporary() {
        let dir = scratch("fail");
        let path = dir.join("out.txt");
        fs::write(&path, "old").unwrap();
        let failed = replace(&path, |out| {
            out.write_all(b"half")?;
            Err(io::Error::other("disk full"))
        });
        assert_eq!(failed.unwrap_err().to_string(), "disk full");
        let via: io::Result<()> = replace_via(&path, |temporary| {
            fs::write(temporary, "half")?;
            Err(io::Error::other("killed"))
        });
        assert!(via.is_err());
        assert_eq!(fs::read_to_string(&path).unwrap(), "old");
        assert_eq!(fs::read_dir(&dir).unwrap().count(), 1);
        replace_via(&path, |temporary| fs::write(temporary, "new")).unwrap();
        assert_eq!(fs::read_to_string(&path).unwrap(), "new");
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_lock_is_for_one_holder_and_follows_a_replacement() {
        let dir = scratch("lock");
        let path = dir.join("held");
        let options = OpenOptions::new()
            .read(true)
            .append(true)
            .create(true)
            .clone();
        let held = lock(&path, &options).unwrap();
        assert!(matches!(lock(&path, &options), Err(LockError::Busy)));
        // The holder replaces the file, locking the new one before the rename: the lock stays
        // with it, and the old file's lock no longer counts.
        let replaced = replace_with(&path, OpenOptions::new().read(true).append(true), |file| {
            file.try_lock().map_err(io::Error::other)?;
            file.write_all(b"new")
        })
        .unwrap();
        drop(held);
        assert!(matches!(lock(&path, &options), Err(LockError::Busy)));
        drop(replaced);
        assert!(lock(&path, &options).is_ok());
        fs::remove_dir_all(&dir).unwrap();
    }
}
