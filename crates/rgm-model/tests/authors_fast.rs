//! rgm against the authors' own code on weights their code trained (`../shared/fixtures/
//! authors-fast`, see its README): the same C̃ on the first pass of pair 0, and the same
//! transforms and final correspondences from the test-time procedure (spec §4: two chains of
//! 2 passes, cycle consistency, one Kabsch of the original clouds) on 21 partial test pairs
//! (every 123rd pair of `rgm pairs --setting partial`, all 717 points of each cloud).

use std::path::{Path, PathBuf};

use ndarray::Array2;
use rgm_data::{ModelNet40, PairGenerator, Setting, Split};
use rgm_geom::{Matrix3, PointCloud, RigidTransform, Vector3};
use rgm_model::network::{Config, Mode, Rgm, RgmCache};
use rgm_model::policy::TUNED;
use rgm_model::{ProcedureConfig, Registrar, RgmRegistrar};
use rgm_registration::compose::Normalised;
use serde::Deserialize;

fn shared() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared")
}

fn fixture(name: &str) -> PathBuf {
    shared().join("fixtures/authors-fast").join(name)
}

/// The authors' weights in rgm's safetensors, with their batch-norm running statistics.
fn network() -> Rgm<f32> {
    Rgm::load(Config::fast(), &fixture("weights.safetensors")).unwrap()
}

/// Test pair `index` of the partial setting, as `rgm pairs` writes it.
fn partial_pair(index: usize) -> (PointCloud, PointCloud) {
    let dataset = ModelNet40::open(shared().join("data/modelnet40_npy1024")).unwrap();
    let shapes = dataset.split(Split::Test, false);
    let pair = PairGenerator::new(Setting::Partial)
        .test_pair(&shapes, index)
        .unwrap();
    (pair.source, pair.target)
}

/// A cloud as the network's (N, 3) input.
fn as_rows(cloud: &PointCloud) -> Array2<f32> {
    Array2::from_shape_fn((cloud.len(), 3), |(i, c)| cloud.points[i][c] as f32)
}

/// A little-endian float32 C-order 2-D `.npy` array.
fn read_npy_f32(path: &Path) -> Array2<f32> {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..6], b"\x93NUMPY");
    let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = std::str::from_utf8(&bytes[10..10 + header_len]).unwrap();
    assert!(header.contains("'<f4'") && header.contains("'fortran_order': False"));
    let dims: Vec<usize> = header[header.find("'shape': (").unwrap() + 10..]
        .split(')')
        .next()
        .unwrap()
        .split(',')
        .filter_map(|d| d.trim().parse().ok())
        .collect();
    let values = bytes[10 + header_len..]
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    Array2::from_shape_vec((dims[0], dims[1]), values).unwrap()
}

#[derive(Deserialize)]
struct Expected {
    pairs: Vec<ExpectedPair>,
}

#[derive(Deserialize)]
struct ExpectedPair {
    index: usize,
    t_target_source: [[f64; 4]; 4],
    correspondences: Vec<(usize, usize)>,
}

fn expected() -> Expected {
    serde_json::from_slice(&std::fs::read(fixture("expected.json")).unwrap()).unwrap()
}

fn transform(rows: &[[f64; 4]; 4]) -> RigidTransform {
    RigidTransform::new(
        Matrix3::from_fn(|r, c| rows[r][c]),
        Vector3::new(rows[0][3], rows[1][3], rows[2][3]),
    )
}

/// The largest |a − b| over two equally shaped arrays.
fn largest_difference(a: &Array2<f64>, b: &Array2<f64>) -> f64 {
    a.iter()
        .zip(b)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max)
}

#[test]
fn the_first_pass_gives_the_authors_c_soft() {
    // Both compute in float32, so they differ by rounding; the same network in float64 is the
    // exact value. The test prints the three largest differences; summing the instance norm's
    // N·M entries in f32 alone would break the bound.
    let (source, target) = partial_pair(0);
    let authors = read_npy_f32(&fixture("pair0_first_pass_soft.npy")).mapv(f64::from); // (717, 717)
    let mut cache = RgmCache::default();
    network()
        .forward(
            as_rows(&source).view(),
            as_rows(&target).view(),
            Mode::Eval,
            &mut cache,
        )
        .unwrap();
    let ours = cache.c_soft().mapv(f64::from); // (717, 717)
    let mut exact_network =
        Rgm::<f64>::load(Config::fast(), &fixture("weights.safetensors")).unwrap();
    let mut exact_cache = RgmCache::default();
    exact_network
        .forward(
            as_rows(&source).mapv(f64::from).view(),
            as_rows(&target).mapv(f64::from).view(),
            Mode::Eval,
            &mut exact_cache,
        )
        .unwrap();
    let exact = exact_cache.c_soft().to_owned(); // (717, 717)
    assert_eq!(ours.dim(), authors.dim());
    let (between, ours_off, authors_off) = (
        largest_difference(&ours, &authors),
        largest_difference(&ours, &exact),
        largest_difference(&authors, &exact),
    );
    eprintln!("largest |ΔC̃|: rgm–authors {between:.2e}, rgm–f64 {ours_off:.2e}, authors–f64 {authors_off:.2e}");
    assert!(between <= 1e-5, "rgm–authors {between}");
    assert!(
        ours_off <= 1e-5,
        "rgm–f64 {ours_off}, authors–f64 {authors_off}"
    );
}

#[test]
fn the_procedure_gives_the_authors_transforms_and_correspondences() {
    let mut registrar = Normalised::new(
        RgmRegistrar::new(network(), ProcedureConfig::default()),
        TUNED.frame,
    );
    let expected = expected();
    assert_eq!(expected.pairs.len(), 21);
    let mut report = Vec::new();
    for pair in &expected.pairs {
        let (source, target) = partial_pair(pair.index);
        let found = registrar.register(&source, &target).unwrap();
        let found_t = found.result.t_target_source;
        let theirs = transform(&pair.t_target_source);
        // The angle of R_theirsᵀ R_ours from its antisymmetric part (sin θ), which stays exact
        // near 0 where acos of the trace loses half the digits.
        let r = theirs.rotation.transpose() * found_t.rotation;
        let axis = Vector3::new(
            r[(2, 1)] - r[(1, 2)],
            r[(0, 2)] - r[(2, 0)],
            r[(1, 0)] - r[(0, 1)],
        );
        let angle_deg = (axis.norm() / 2.0).asin().to_degrees();
        let offset = (found_t.translation - theirs.translation).norm();
        let mut ours = found.correspondences;
        ours.sort_unstable();
        let mut authors = pair.correspondences.clone();
        authors.sort_unstable();
        if angle_deg > 0.01 || offset > 1e-4 || ours != authors {
            report.push(format!(
                "pair {}: rotation off by {angle_deg:.4}°, translation by {offset:.2e}, \
                 {} correspondences against the authors' {} ({} shared)",
                pair.index,
                ours.len(),
                authors.len(),
                ours.iter()
                    .filter(|p| authors.binary_search(p).is_ok())
                    .count()
            ));
        }
    }
    assert!(report.is_empty(), "{}", report.join("\n"));
}
