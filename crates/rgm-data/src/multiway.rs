//! The multiway protocol on a scan folder ([`crate::ScanFolder`]): every scan moved by its own
//! random rigid motion and the scans shuffled (seeded), so that a merge starts from no pose and
//! no order; and the errors of the poses a merge found, after the one rigid motion that best
//! maps its frame onto the ground truth's.

use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rgm_geom::cloud::evenly;
use rgm_geom::{kabsch, Point3, PointCloud, RigidTransform};

use crate::scans::random_motion;
use crate::ScanFolder;

/// One scan as a merge is given it.
#[derive(Clone, Debug)]
pub struct MovedScan {
    /// Its place in the folder's `.conf` order.
    pub original: usize,
    /// The scan's points moved by its motion. // (N,)
    pub cloud: PointCloud,
    /// `t_world_input`: maps the moved points into the ground truth's world frame.
    pub truth: RigidTransform,
}

/// The folder's scans in a shuffled order, each moved about its centroid by a rotation of an
/// angle uniform in [0°, 180°] about a uniformly random axis and shifted by up to half the
/// object's diagonal, all drawn from `seed`.
pub fn moved_and_shuffled(folder: &ScanFolder, seed: u64) -> Vec<MovedScan> {
    let mut rng = StdRng::seed_from_u64(seed);
    let diagonal = folder.diagonal();
    let mut moved: Vec<MovedScan> = folder
        .scans
        .iter()
        .enumerate()
        .map(|(original, scan)| {
            let motion = random_motion(&mut rng, &scan.cloud.centroid(), 180.0, diagonal / 2.0);
            MovedScan {
                original,
                cloud: scan.cloud.transformed(&motion),
                truth: scan.pose.compose(&motion.inverse()),
            }
        })
        .collect();
    moved.shuffle(&mut rng);
    moved
}

/// Points of each scan used to align the frames and measure displacements: at most this many,
/// at an even stride.
pub const SAMPLE: usize = 2000;

/// The errors of one placed scan.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseError {
    /// The angle of the rotation between the found pose and the truth, degrees.
    pub rotation_deg: f64,
    /// The RMS distance between where the found pose and the truth put the scan's points.
    pub rms: f64,
}

/// The errors of `found` (`model ← input` per scan, `None` for an unplaced one), each
/// `component` (per scan) aligned on its own: the rigid motion `world ← model` that best maps
/// its scans' points as `found` places them onto where `scans`' truths put them (Kabsch over at
/// most [`SAMPLE`] points of each), then each scan's rotation error and RMS displacement.
pub fn pose_errors(
    scans: &[MovedScan],
    found: &[Option<RigidTransform>],
    component: &[Option<usize>],
) -> Vec<Option<PoseError>> {
    let sample = |cloud: &PointCloud| -> Vec<Point3<f64>> {
        evenly(&cloud.points, SAMPLE).copied().collect()
    };
    let samples: Vec<Vec<Point3<f64>>> = scans.iter().map(|s| sample(&s.cloud)).collect();
    let components = component.iter().flatten().max().map_or(0, |c| c + 1);
    let mut errors = vec![None; scans.len()];
    for c in 0..components {
        let members: Vec<usize> = (0..scans.len())
            .filter(|&s| component[s] == Some(c) && found[s].is_some())
            .collect();
        let (mut model, mut world) = (Vec::new(), Vec::new());
        for &s in &members {
            let pose = found[s].expect("placed");
            model.extend(samples[s].iter().map(|q| pose.apply(q)));
            world.extend(samples[s].iter().map(|q| scans[s].truth.apply(q)));
        }
        let Ok(world_from_model) = kabsch(&model, &world, &vec![1.0; model.len()]) else {
            continue;
        };
        for &s in &members {
            let placed = world_from_model.compose(&found[s].expect("placed"));
            let truth = scans[s].truth;
            let squared: f64 = samples[s]
                .iter()
                .map(|q| (placed.apply(q) - truth.apply(q)).norm_squared())
                .sum();
            errors[s] = Some(PoseError {
                rotation_deg: truth.inverse().compose(&placed).rotation_angle_deg(),
                rms: (squared / samples[s].len() as f64).sqrt(),
            });
        }
    }
    errors
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scans::Scan;
    use rgm_geom::Vector3;

    fn folder() -> ScanFolder {
        let cloud = |shift: f64| {
            PointCloud::new(
                (0..50)
                    .map(|i| {
                        let t = i as f64 * 0.1;
                        Point3::new(t.sin() + shift, t.cos(), 0.3 * t)
                    })
                    .collect(),
            )
        };
        let scans = (0..4)
            .map(|k| Scan {
                name: format!("s{k}"),
                cloud: cloud(0.1 * k as f64),
                pose: RigidTransform::new(
                    rgm_geom::euler::rotation_xyz_intrinsic(0.1 * k as f64, 0.0, 0.2),
                    Vector3::new(0.0, k as f64, 0.0),
                ),
            })
            .collect();
        ScanFolder {
            path: "f".into(),
            scans,
            warnings: Vec::new(),
        }
    }

    #[test]
    fn the_truth_seen_from_any_frame_scores_zero_each_component_on_its_own() {
        let folder = folder();
        let scans = moved_and_shuffled(&folder, 7);
        let order: Vec<usize> = scans.iter().map(|s| s.original).collect();
        assert_ne!(order, vec![0, 1, 2, 3], "shuffled");
        // The moved points are the scan's: the truth maps them where the pose maps the original.
        for s in &scans {
            let original = &folder.scans[s.original];
            let p = s.truth.apply(&s.cloud.points[3]);
            assert!((p - original.pose.apply(&original.cloud.points[3])).norm() < 1e-12);
        }
        // The truth seen from another frame: every error zero.
        let frame = RigidTransform::new(
            rgm_geom::euler::rotation_xyz_intrinsic(1.0, -0.5, 2.0),
            Vector3::new(3.0, -1.0, 0.5),
        );
        let mut found: Vec<Option<RigidTransform>> = scans
            .iter()
            .map(|s| Some(frame.compose(&s.truth)))
            .collect();
        let component = vec![Some(0); 4];
        for e in pose_errors(&scans, &found, &component) {
            let e = e.unwrap();
            assert!(e.rotation_deg < 1e-6 && e.rms < 1e-9, "{e:?}");
        }
        // One scan left out and one in a component of its own: that one scores zero too (its
        // own frame aligned alone), the left-out one has no error.
        found[0] = None;
        let component = vec![None, Some(0), Some(0), Some(1)];
        let errors = pose_errors(&scans, &found, &component);
        assert_eq!(errors[0], None);
        assert!(errors[3].unwrap().rms < 1e-9);
    }
}
