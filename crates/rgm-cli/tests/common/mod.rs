//! What the command's end-to-end test files share: running `rgm`, the data, a known pair.
// Each test file compiles this module on its own and uses only some of it.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use rgm_data::{read_point_cloud, write_point_cloud};
use rgm_geom::euler::rotation_xyz_intrinsic;
use rgm_geom::{Matrix4, RigidTransform, Vector3};

pub fn rgm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rgm"))
        .args(args)
        .output()
        .expect("the rgm binary runs")
}

pub fn stdout(out: &Output) -> String {
    assert!(
        out.status.success(),
        "rgm failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout.clone()).expect("utf-8 output")
}

pub fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/modelnet40_npy1024")
}

pub fn airplane() -> PathBuf {
    data_dir().join("airplane/test/airplane_0627.npy")
}

/// A known pose within the protocol's range (20°, 10°, 30°; t = (0.2, −0.1, 0.3)).
pub fn known_pose() -> RigidTransform {
    let r = rotation_xyz_intrinsic(20f64.to_radians(), 10f64.to_radians(), 30f64.to_radians());
    RigidTransform::new(r, Vector3::new(0.2, -0.1, 0.3))
}

pub fn parse_transform(value: &serde_json::Value) -> RigidTransform {
    let rows = value["transform"].as_array().expect("transform rows");
    let m = Matrix4::from_fn(|r, c| rows[r][c].as_f64().expect("a number"));
    RigidTransform::from_matrix4(&m, 1e-6).expect("a rigid transform")
}

/// The airplane and its copy at `known_pose`, as files in `dir`.
pub fn known_pair(dir: &Path) -> (PathBuf, PathBuf) {
    let source = read_point_cloud(airplane()).unwrap();
    let (src, tgt) = (dir.join("src.npy"), dir.join("tgt.npy"));
    write_point_cloud(&src, &source).unwrap();
    write_point_cloud(&tgt, &source.transformed(&known_pose())).unwrap();
    (src, tgt)
}
