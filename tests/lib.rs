//! Helpers for the cross-crate tests.

pub mod mutation;

use std::path::PathBuf;

use rgm_data::ModelNet40;

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
