//! Helpers for the cross-crate tests.

pub mod mutation;

use std::ops::Deref;
use std::path::{Path, PathBuf};

use rgm_data::ModelNet40;

/// A fresh folder for one test's files (`rgm-NAME-PID` in the temporary folder), removed with
/// everything in it when dropped, a failed test's too: test runs leave nothing behind.
#[derive(Debug)]
pub struct Scratch(PathBuf);

impl Scratch {
    /// The folder for `name`, unique within the test binary's run; what an earlier run of the
    /// same process id left there is removed first.
    pub fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("rgm-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Self(dir)
    }
}

impl Deref for Scratch {
    type Target = Path;

    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The repository root.
pub fn project_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ has a parent")
        .to_path_buf()
}

/// The shared ModelNet40 tree: `$RGM_DATA`, else `../shared/data/modelnet40_npy1024` beside
/// the repository.
pub fn modelnet() -> ModelNet40 {
    let dir = std::env::var_os("RGM_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| project_root().join("../shared/data/modelnet40_npy1024"));
    ModelNet40::open(&dir)
        .unwrap_or_else(|e| panic!("the tests need ModelNet40 at {}: {e}", dir.display()))
}
