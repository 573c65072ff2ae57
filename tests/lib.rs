//! Helpers for the end-to-end tests.

use std::path::PathBuf;

/// The repository root.
pub fn project_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().expect("tests/ has a parent").to_path_buf()
}

/// `../shared/data/modelnet40_npy1024` beside the repository, or `$RGM_DATA` when set.
pub fn modelnet_dir() -> PathBuf {
    match std::env::var_os("RGM_DATA") {
        Some(dir) => PathBuf::from(dir),
        None => project_root().join("../shared/data/modelnet40_npy1024"),
    }
}
