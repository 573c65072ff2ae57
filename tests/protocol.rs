//! The benchmark end to end: pairs made by rgm-data, registered through rgm-model's methods,
//! scored by rgm-geom's metrics.

use rgm_data::{PairGenerator, Setting, Split};
use rgm_model::evaluate::{evaluate_pair, PairRecord, Summary};
use rgm_model::Method;
use rgm_tests::modelnet;

#[test]
fn the_ground_truth_scores_perfectly_on_partial_pairs() {
    let data = modelnet();
    let shapes = data.split(Split::Test, false);
    let generator = PairGenerator::new(Setting::Partial);
    let records: Vec<PairRecord> = (0..5)
        .map(|i| {
            let pair = generator.test_pair(&shapes, i).unwrap();
            assert_eq!((pair.source.len(), pair.target.len()), (717, 717));
            PairRecord::score(i, &pair, pair.t_target_source, 0.0, 0, None).unwrap()
        })
        .collect();
    let summary = Summary::from_records(&records).unwrap();
    assert!(summary.metrics.mie_r_deg < 1e-9 && summary.metrics.mie_t < 1e-9);
    assert_eq!(summary.metrics.recall, 1.0);
    // Cropped independently, the clouds overlap only in part: the clipped distance is not 0.
    assert!(summary.metrics.ccd > 0.01, "CCD {}", summary.metrics.ccd);
}

#[test]
fn fgr_registers_clean_test_pairs() {
    let data = modelnet();
    let shapes = data.split(Split::Test, false);
    let generator = PairGenerator::new(Setting::Clean);
    let mut method = Method::new(rgm_registration::methods::fgr::FgrConfig::default());
    for i in 0..4 {
        let pair = generator.test_pair(&shapes, i).unwrap();
        let record = evaluate_pair(&mut method, i, &pair).unwrap();
        assert!(record.failure.is_none());
        assert!(
            record.metrics.recall,
            "clean pair {i}: MAE(R) {}°, MAE(t) {}",
            record.metrics.mae_r_deg, record.metrics.mae_t
        );
    }
}

#[test]
fn a_failed_registration_is_scored_as_the_identity() {
    let data = modelnet();
    let shapes = data.split(Split::Test, false);
    let pair = PairGenerator::new(Setting::Clean)
        .test_pair(&shapes, 0)
        .unwrap();
    // ICP whose correspondence distance admits no pair fails; evaluation goes on.
    let mut method = Method::new(rgm_registration::methods::icp::IcpConfig {
        max_correspondence_distance: -1.0,
        ..Default::default()
    });
    let record = evaluate_pair(&mut method, 0, &pair).unwrap();
    assert!(record
        .failure
        .as_deref()
        .unwrap_or("")
        .contains("max_correspondence_distance"));
    assert_eq!(record.transform, rgm_geom::RigidTransform::identity());
    assert!((record.metrics.mie_r_deg - pair.t_target_source.rotation_angle_deg()).abs() < 1e-9);
}
