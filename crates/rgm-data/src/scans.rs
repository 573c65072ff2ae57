//! Real range scans with ground-truth poses (a folder in the layout of the Stanford 3D Scanning
//! Repository), and the registration pairs made of them.
//!
//! A scan folder holds the scans (`.ply`, `.ply.gz`, or any format [`crate::io`] reads) and one
//! `.conf` file whose `bmesh FILE tx ty tz qx qy qz qw` lines give each scan's pose; other lines
//! (`camera`, `mesh`) are skipped. The pose maps the scan's points into the common (world) frame
//! by `p_world = R(q)ᵀ · p + t`, `R(q)` the rotation of the unit quaternion with scalar part `qw`
//! (Stanford's convention, checked in `../shared/data/stanford/README.md`).
//!
//! Pairs are made as the ModelNet40 protocol makes them, from real views:
//! 1. every two scans `a` < `b` (in the `.conf` order) whose [`overlap`] with the ground truth is
//!    at least [`ScanPairConfig::min_overlap`] form a pair, source `a`, target `b`, each in its
//!    own scanner frame;
//! 2. the source is then moved by a random rigid motion drawn from pair `k`'s own seed `k`:
//!    a rotation by an angle uniform in [0, [`ScanPairConfig::max_angle_deg`]] about a uniformly
//!    random axis through the source's centroid, and a shift in a uniformly random direction of
//!    a length uniform in [0, [`ScanPairConfig::max_shift`] × the object's radius];
//! 3. the ground truth is `t_target_source = T_b⁻¹ · T_a · P⁻¹` (`T` the poses, `P` the motion).
//!
//! The object's size is the diagonal of the bounding box of all its scans in the world frame;
//! its radius is half that diagonal.

use std::path::{Path, PathBuf};

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rgm_geom::{KnnIndex, Matrix3, Point3, PointCloud, RigidTransform, Vector3};

use crate::io::{read_point_cloud_warned, Warning};
use crate::{DataError, Result};

/// One scan: its points in the scanner's frame and its ground-truth pose.
#[derive(Clone, Debug)]
pub struct Scan {
    /// The scan's file name as the `.conf` file gives it (`bun000.ply`).
    pub name: String,
    /// The points, in the scanner's frame. // (N,)
    pub cloud: PointCloud,
    /// `t_world_scan`: maps the scan's points into the common frame.
    pub pose: RigidTransform,
}

/// The scans of one object.
#[derive(Clone, Debug)]
pub struct ScanFolder {
    pub path: PathBuf,
    /// The scans, in the `.conf` file's order.
    pub scans: Vec<Scan>,
    /// What reading the scans warned of (stray PLY header lines).
    pub warnings: Vec<Warning>,
}

/// The rotation of the quaternion `(x, y, z, w)`, scalar part `w` last, normalised first.
pub fn quaternion_rotation(x: f64, y: f64, z: f64, w: f64) -> Matrix3<f64> {
    let n = (x * x + y * y + z * z + w * w).sqrt();
    let (x, y, z, w) = (x / n, y / n, z / n, w / n);
    Matrix3::new(
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y - z * w),
        2.0 * (x * z + y * w),
        2.0 * (x * y + z * w),
        1.0 - 2.0 * (x * x + z * z),
        2.0 * (y * z - x * w),
        2.0 * (x * z - y * w),
        2.0 * (y * z + x * w),
        1.0 - 2.0 * (x * x + y * y),
    )
}

impl ScanFolder {
    /// Reads the folder's one `.conf` file and every scan it names: `FILE` itself, or
    /// `FILE.gz` when only the compressed file is there.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let dataset_error = |why: String| DataError::Dataset {
            path: path.to_path_buf(),
            why,
        };
        let entries = std::fs::read_dir(path).map_err(|source| DataError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let mut confs: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "conf"))
            .collect();
        confs.sort();
        let conf = match confs.as_slice() {
            [one] => one.clone(),
            [] => return Err(dataset_error("no `.conf` pose file in the folder".into())),
            _ => {
                let names: Vec<String> = confs.iter().map(|c| c.display().to_string()).collect();
                return Err(dataset_error(format!(
                    "more than one `.conf` pose file: {}",
                    names.join(", ")
                )));
            }
        };
        let text = String::from_utf8(crate::read_regular_file(&conf)?).map_err(|_| {
            DataError::Dataset {
                path: conf.clone(),
                why: "not UTF-8 text".into(),
            }
        })?;
        let mut scans = Vec::new();
        let mut warnings = Vec::new();
        for (line_no, (name, pose)) in parse_conf(&text, &conf)? {
            let plain = path.join(&name);
            let file = if plain.exists() {
                plain
            } else {
                path.join(format!("{name}.gz"))
            };
            if !file.exists() {
                return Err(DataError::Line {
                    path: conf.clone(),
                    line: line_no,
                    text: name.clone(),
                    why: format!("neither {name} nor {name}.gz is in the folder"),
                });
            }
            let (cloud, mut warned) = read_point_cloud_warned(&file)?;
            warnings.append(&mut warned);
            scans.push(Scan { name, cloud, pose });
        }
        if scans.len() < 2 {
            return Err(DataError::Dataset {
                path: conf,
                why: format!("{} `bmesh` scan lines; a pair needs 2", scans.len()),
            });
        }
        Ok(Self {
            path: path.to_path_buf(),
            scans,
            warnings,
        })
    }

    /// The diagonal of the bounding box of every scan in the world frame.
    pub fn diagonal(&self) -> f64 {
        let world = self
            .scans
            .iter()
            .flat_map(|scan| scan.cloud.points.iter().map(|p| scan.pose.apply(p)));
        let (low, high) = rgm_geom::cloud::bounds(world);
        (high - low).norm()
    }

    /// The median distance from a point of the scans to its nearest neighbour in its own scan.
    pub fn spacing(&self) -> f64 {
        let mut gaps: Vec<f64> = self
            .scans
            .iter()
            .flat_map(|scan| {
                let index = KnnIndex::new(&scan.cloud.points);
                // The nearest neighbour other than the point itself (duplicates give 0).
                scan.cloud
                    .points
                    .iter()
                    .map(move |p| index.k_nearest(p, 2)[1].1)
                    .collect::<Vec<f64>>()
            })
            .collect();
        let middle = gaps.len() / 2;
        *gaps.select_nth_unstable_by(middle, f64::total_cmp).1
    }

    /// The pairs of scans that overlap by at least `config.min_overlap` (see [`overlap`],
    /// within `config.overlap_spacings` × [`ScanFolder::spacing`]), each source moved as the
    /// module documentation says.
    pub fn pairs(&self, config: &ScanPairConfig) -> Vec<ScanPair> {
        let diagonal = self.diagonal();
        let reach = config.overlap_spacings * self.spacing();
        let world: Vec<PointCloud> = self
            .scans
            .iter()
            .map(|s| s.cloud.transformed(&s.pose))
            .collect();
        let indices: Vec<KnnIndex> = world.iter().map(|c| KnnIndex::new(&c.points)).collect();
        let mut pairs = Vec::new();
        for a in 0..world.len() {
            for b in a + 1..world.len() {
                let shared = overlap((&world[a], &indices[a]), (&world[b], &indices[b]), reach);
                if shared < config.min_overlap {
                    continue;
                }
                let (sa, sb) = (&self.scans[a], &self.scans[b]);
                let k = pairs.len();
                let mut rng = StdRng::seed_from_u64(k as u64);
                let motion = random_motion(
                    &mut rng,
                    &sa.cloud.centroid(),
                    config.max_angle_deg,
                    config.max_shift * diagonal / 2.0,
                );
                pairs.push(ScanPair {
                    index: k,
                    source_name: sa.name.clone(),
                    target_name: sb.name.clone(),
                    source: sa.cloud.transformed(&motion),
                    target: sb.cloud.clone(),
                    t_target_source: sb
                        .pose
                        .inverse()
                        .compose(&sa.pose)
                        .compose(&motion.inverse()),
                    overlap: shared,
                    diagonal,
                });
            }
        }
        pairs
    }
}

/// The quaternion `(x, y, z, w)` of a rotation matrix (the inverse of [`quaternion_rotation`],
/// `w` ≥ 0), by the largest of its four squared components (Shepperd's method: no division by
/// a small number).
pub fn rotation_quaternion(r: &Matrix3<f64>) -> [f64; 4] {
    let trace = r.trace();
    let (x, y, z, w);
    if trace > r[(0, 0)].max(r[(1, 1)]).max(r[(2, 2)]) {
        let s = 2.0 * (1.0 + trace).sqrt(); // 4w
        (w, x, y, z) = (
            s / 4.0,
            (r[(2, 1)] - r[(1, 2)]) / s,
            (r[(0, 2)] - r[(2, 0)]) / s,
            (r[(1, 0)] - r[(0, 1)]) / s,
        );
    } else if r[(0, 0)] >= r[(1, 1)] && r[(0, 0)] >= r[(2, 2)] {
        let s = 2.0 * (1.0 + r[(0, 0)] - r[(1, 1)] - r[(2, 2)]).sqrt(); // 4x
        (w, x, y, z) = (
            (r[(2, 1)] - r[(1, 2)]) / s,
            s / 4.0,
            (r[(0, 1)] + r[(1, 0)]) / s,
            (r[(0, 2)] + r[(2, 0)]) / s,
        );
    } else if r[(1, 1)] >= r[(2, 2)] {
        let s = 2.0 * (1.0 + r[(1, 1)] - r[(0, 0)] - r[(2, 2)]).sqrt(); // 4y
        (w, x, y, z) = (
            (r[(0, 2)] - r[(2, 0)]) / s,
            (r[(0, 1)] + r[(1, 0)]) / s,
            s / 4.0,
            (r[(1, 2)] + r[(2, 1)]) / s,
        );
    } else {
        let s = 2.0 * (1.0 + r[(2, 2)] - r[(0, 0)] - r[(1, 1)]).sqrt(); // 4z
        (w, x, y, z) = (
            (r[(1, 0)] - r[(0, 1)]) / s,
            (r[(0, 2)] + r[(2, 0)]) / s,
            (r[(1, 2)] + r[(2, 1)]) / s,
            s / 4.0,
        );
    }
    let sign = if w < 0.0 { -1.0 } else { 1.0 };
    [sign * x, sign * y, sign * z, sign * w]
}

/// A `.conf` file of `scans` (file name, `t_world_scan`): one `bmesh FILE tx ty tz qx qy qz qw`
/// line each, in Stanford's convention (`p_world = R(q)ᵀ · p + t`, as [`ScanFolder::open`]
/// reads it), at full f64 precision.
pub fn conf_text<'a>(scans: impl IntoIterator<Item = (&'a str, &'a RigidTransform)>) -> String {
    let mut text = String::new();
    for (name, pose) in scans {
        let t = pose.translation;
        // The file's rotation is the pose's transposed.
        let [qx, qy, qz, qw] = rotation_quaternion(&pose.rotation.transpose());
        text.push_str(&format!(
            "bmesh {name} {} {} {} {qx} {qy} {qz} {qw}\n",
            t.x, t.y, t.z
        ));
    }
    text
}

/// The `bmesh` lines of a `.conf` file: (line number, file name, pose).
fn parse_conf(text: &str, conf: &Path) -> Result<Vec<(usize, (String, RigidTransform))>> {
    let mut scans = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let tokens: Vec<&str> = line.split_whitespace().collect();
        if tokens.first() != Some(&"bmesh") {
            continue;
        }
        let bad = |why: String| DataError::Line {
            path: conf.to_path_buf(),
            line: i + 1,
            text: line.trim().to_string(),
            why,
        };
        let [_, name, numbers @ ..] = tokens.as_slice() else {
            unreachable!("the first token is `bmesh`")
        };
        if numbers.len() != 7 {
            return Err(bad(format!(
                "expected `bmesh FILE tx ty tz qx qy qz qw`, found {} numbers",
                numbers.len()
            )));
        }
        let mut v = [0.0; 7];
        for (value, token) in v.iter_mut().zip(numbers) {
            *value = token
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| bad(format!("`{token}` is not a finite number")))?;
        }
        // Its squared norm, which normalising divides by: past f64's range the quaternion
        // would come out as zero, the identity rotation.
        let squared: f64 = v[3..].iter().map(|q| q * q).sum();
        if !squared.is_finite() {
            return Err(bad(format!(
                "the quaternion ({}, {}, {}, {}) is too large to normalise (its squared norm \
                 overflows)",
                numbers[3], numbers[4], numbers[5], numbers[6]
            )));
        }
        let rotation = quaternion_rotation(v[3], v[4], v[5], v[6]);
        if !rotation.iter().all(|x| x.is_finite()) {
            return Err(bad("the quaternion is zero".into()));
        }
        let pose = RigidTransform::new(rotation.transpose(), Vector3::new(v[0], v[1], v[2]));
        scans.push((i + 1, (name.to_string(), pose)));
    }
    Ok(scans)
}

/// How two clouds in one frame overlap: the share of the points of each that lie within
/// `reach` of the other, the smaller of the two (0 to 1).
pub fn overlap(a: (&PointCloud, &KnnIndex), b: (&PointCloud, &KnnIndex), reach: f64) -> f64 {
    let share = |from: &PointCloud, to: &KnnIndex| {
        let near = from
            .points
            .iter()
            .filter(|p| to.nearest_within(p, reach).is_some())
            .count();
        near as f64 / from.len() as f64
    };
    share(a.0, b.1).min(share(b.0, a.1))
}

/// A rotation by an angle uniform in [0, `max_angle_deg`] about a uniformly random axis through
/// `centre`, then a shift in a uniformly random direction of length uniform in [0, `max_shift`].
pub fn random_motion(
    rng: &mut StdRng,
    centre: &Point3<f64>,
    max_angle_deg: f64,
    max_shift: f64,
) -> RigidTransform {
    let mut direction = || loop {
        let v = Vector3::from_fn(|_, _| StandardNormal.sample(&mut *rng));
        if v.norm() > 1e-9 {
            break v.normalize();
        }
    };
    let axis = direction();
    let along = direction();
    let angle = rng.gen_range(0.0..=max_angle_deg).to_radians();
    let shift = rng.gen_range(0.0..=max_shift);
    let rotation = axis_angle(&axis, angle);
    // p ↦ R (p − c) + c + shift·along
    let translation = centre.coords - rotation * centre.coords + along * shift;
    RigidTransform::new(rotation, translation)
}

/// The rotation by `radians` about the unit vector `axis` (Rodrigues: R = I + sin θ K +
/// (1 − cos θ) K², K the cross-product matrix of the axis).
pub(crate) fn axis_angle(axis: &Vector3<f64>, radians: f64) -> Matrix3<f64> {
    let k = axis.cross_matrix();
    Matrix3::identity() + k * radians.sin() + k * k * (1.0 - radians.cos())
}

/// The protocol's constants; [`Default`] gives the benchmark's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScanPairConfig {
    /// Least [`overlap`] of a pair (default 0.45).
    pub min_overlap: f64,
    /// The reach of [`overlap`] in units of the scans' median point spacing (default 3).
    pub overlap_spacings: f64,
    /// Largest rotation of the source, degrees (default 45).
    pub max_angle_deg: f64,
    /// Largest shift of the source, in object radii (default 0.5).
    pub max_shift: f64,
}

impl Default for ScanPairConfig {
    fn default() -> Self {
        Self {
            min_overlap: 0.45,
            overlap_spacings: 3.0,
            max_angle_deg: 45.0,
            max_shift: 0.5,
        }
    }
}

/// One registration problem made of two real scans.
#[derive(Clone, Debug)]
pub struct ScanPair {
    /// The pair's number in its folder (also its seed).
    pub index: usize,
    pub source_name: String,
    pub target_name: String,
    /// Scan `a`, moved. // (N,)
    pub source: PointCloud,
    /// Scan `b`, in its scanner's frame. // (M,)
    pub target: PointCloud,
    /// Ground truth: maps the source's points onto the target's.
    pub t_target_source: RigidTransform,
    /// The scans' [`overlap`].
    pub overlap: f64,
    /// The object's bounding-box diagonal, the unit of translation errors.
    pub diagonal: f64,
}

impl ScanPair {
    /// The errors of `found` (a `t_target_source`): its rotation's angle from the truth's in
    /// degrees, and the distance between where it and the truth put the source's centroid, as
    /// a share of the object's diagonal. Measured at the centroid, the translation error does
    /// not depend on where the scanner's origin lies.
    pub fn errors(&self, found: &RigidTransform) -> (f64, f64) {
        let residual = self.t_target_source.inverse().compose(found);
        let c = self.source.centroid();
        let shift = (found.apply(&c) - self.t_target_source.apply(&c)).norm();
        (residual.rotation_angle_deg(), shift / self.diagonal)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_quaternion_rotation_is_the_usual_one() {
        // 90° about z: (0, 0, sin 45°, cos 45°) takes x to y.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let r = quaternion_rotation(0.0, 0.0, h, h);
        let x = r * Vector3::x();
        assert!((x - Vector3::y()).norm() < 1e-12, "{x}");
        // Unnormalised input is normalised; the result is a rotation.
        let r = quaternion_rotation(0.3, -1.0, 2.0, 0.5);
        assert!((r * r.transpose() - Matrix3::identity()).norm() < 1e-12);
        assert!((r.determinant() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_written_conf_reads_back_as_the_poses_it_was_written_from() {
        // Stanford's own bun.conf, read, written and read again: the same poses; and every
        // branch of the quaternion (turns of 0°, 180° about each axis, and about a diagonal).
        let path = Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../../shared/data/stanford/bunny/bun.conf"
        ));
        let text = std::fs::read_to_string(path).unwrap();
        let read = parse_conf(&text, path).unwrap();
        assert_eq!(read.len(), 10);
        let mut poses: Vec<(String, RigidTransform)> = read.into_iter().map(|(_, p)| p).collect();
        for (k, axis) in [
            Vector3::x(),
            Vector3::y(),
            Vector3::z(),
            Vector3::new(1.0, -2.0, 0.5),
        ]
        .iter()
        .enumerate()
        {
            let r = axis_angle(&axis.normalize(), std::f64::consts::PI);
            poses.push((
                format!("turn{k}"),
                RigidTransform::new(r, Vector3::new(0.1, 0.0, -2.0)),
            ));
        }
        let written = conf_text(poses.iter().map(|(n, p)| (n.as_str(), p)));
        let again = parse_conf(&written, Path::new("poses.conf")).unwrap();
        assert_eq!(again.len(), poses.len());
        for ((_, (name, back)), (original_name, original)) in again.iter().zip(&poses) {
            assert_eq!(name, original_name);
            assert!(
                (back.rotation - original.rotation).abs().max() < 1e-12,
                "{name}"
            );
            assert!(
                (back.translation - original.translation).abs().max() < 1e-15,
                "{name}"
            );
        }
        // bun000's line is the identity: `0 0 0 0 0 0 1`.
        assert!(
            written.starts_with("bmesh bun000.ply 0 0 0 0 0 0 1\n"),
            "{written}"
        );
    }

    /// Writes a scan folder of a sphere (radius 0.1) seen from three directions, 60° apart:
    /// each scan the cap of points within 80° of its direction, in its own frame.
    fn sphere_folder(name: &str) -> (PathBuf, Vec<RigidTransform>) {
        let dir = crate::io::scratch_path(name);
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let n = 3000;
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let sphere: Vec<Point3<f64>> = (0..n)
            .map(|i| {
                let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let r = (1.0 - y * y).sqrt();
                let phi = golden * i as f64;
                Point3::new(0.1 * r * phi.cos(), 0.1 * y, 0.1 * r * phi.sin())
            })
            .collect();
        let mut conf = String::from("camera 0 0 0 0 0 0 1\n");
        let mut poses = Vec::new();
        for (k, deg) in [0.0f64, 60.0, 120.0].into_iter().enumerate() {
            let view = Vector3::new(deg.to_radians().cos(), 0.0, deg.to_radians().sin());
            let q = [0.1 * k as f64, -0.2, 0.3, 0.9];
            let pose = RigidTransform::new(
                quaternion_rotation(q[0], q[1], q[2], q[3]).transpose(),
                Vector3::new(0.01 * k as f64, 0.5, -0.02),
            );
            let cap: Vec<Point3<f64>> = sphere
                .iter()
                .filter(|p| p.coords.normalize().dot(&view) > 80f64.to_radians().cos())
                .map(|p| pose.inverse().apply(p))
                .collect();
            let file = format!("view{k}.ply");
            // The first scan only compressed, as the Stanford scans come.
            let written = if k == 0 {
                format!("{file}.gz")
            } else {
                file.clone()
            };
            crate::write_point_cloud(dir.join(written), &PointCloud::new(cap)).unwrap();
            let t = pose.translation;
            conf += &format!(
                "bmesh {file} {} {} {} {} {} {} {}\n",
                t.x, t.y, t.z, q[0], q[1], q[2], q[3]
            );
            poses.push(pose);
        }
        std::fs::write(dir.join("views.conf"), conf).unwrap();
        (dir, poses)
    }

    #[test]
    fn a_scan_folder_gives_its_overlapping_pairs_with_their_ground_truth() {
        let (dir, poses) = sphere_folder("sphere_scans");
        let folder = ScanFolder::open(&dir).unwrap();
        assert_eq!(folder.scans.len(), 3);
        for (scan, pose) in folder.scans.iter().zip(&poses) {
            // The PLY stores float32: the pose is read exactly, the points to 1e-7.
            let r = scan.pose.rotation - pose.rotation;
            assert!(r.norm() < 1e-12 && (scan.pose.translation - pose.translation).norm() < 1e-12);
        }
        assert!(
            (folder.diagonal() - 0.2 * 3f64.sqrt()).abs() < 0.02,
            "{}",
            folder.diagonal()
        );
        // Caps of 80° whose directions are 60° apart share most of their points; 120° apart
        // they share a sliver.
        let pairs = folder.pairs(&ScanPairConfig::default());
        let names: Vec<(&str, &str)> = pairs
            .iter()
            .map(|p| (p.source_name.as_str(), p.target_name.as_str()))
            .collect();
        assert_eq!(
            names,
            [("view0.ply", "view1.ply"), ("view1.ply", "view2.ply")]
        );
        for pair in &pairs {
            assert!(
                pair.overlap > 0.45 && pair.overlap < 1.0,
                "{}",
                pair.overlap
            );
            let (angle, shift) = pair.errors(&pair.t_target_source);
            assert!(angle < 1e-5 && shift < 1e-15, "{angle} {shift}");
            // The truth puts each moved source point where its scan's pose puts it.
            let a = &folder.scans[pair.index];
            let b = &folder.scans[pair.index + 1];
            for (moved, original) in pair.source.points.iter().zip(&a.cloud.points) {
                let via_target = b.pose.apply(&pair.t_target_source.apply(moved));
                assert!((via_target - a.pose.apply(original)).norm() < 1e-12);
            }
            // The source was moved: by at most 45°, and not in place.
            let (angle, shift) = pair.errors(&RigidTransform::identity());
            assert!(angle > 0.0 && shift > 0.0);
        }
        // A turn of 1° about the source's centroid costs no translation.
        let pair = &pairs[0];
        let c = pair.source.centroid();
        let half = 0.5f64.to_radians();
        let turn = quaternion_rotation(0.0, 0.0, half.sin(), half.cos());
        let about_c = RigidTransform::new(turn, c.coords - turn * c.coords);
        let (angle, shift) = pair.errors(&pair.t_target_source.compose(&about_c));
        assert!(
            (angle - 1.0).abs() < 1e-6 && shift < 1e-15,
            "{angle} {shift}"
        );
    }

    #[test]
    fn a_bad_pose_line_or_missing_scan_is_named() {
        let (dir, _) = sphere_folder("sphere_scans_bad");
        let conf = dir.join("views.conf");
        std::fs::write(&conf, "bmesh view1.ply 0 0 0 0 0 1\n").unwrap();
        let err = ScanFolder::open(&dir).unwrap_err().to_string();
        assert_eq!(
            err,
            format!(
                "{}:1: expected `bmesh FILE tx ty tz qx qy qz qw`, found 6 numbers: \
                 `bmesh view1.ply 0 0 0 0 0 1`",
                conf.display()
            )
        );
        std::fs::write(&conf, "bmesh view1.ply 0 0 0 0 0 0 0\n").unwrap();
        let err = ScanFolder::open(&dir).unwrap_err().to_string();
        assert!(
            err.ends_with("the quaternion is zero: `bmesh view1.ply 0 0 0 0 0 0 0`"),
            "{err}"
        );
        std::fs::write(&conf, "bmesh view1.ply 0 0 0 1e200 0 0 1e200\n").unwrap();
        let err = ScanFolder::open(&dir).unwrap_err().to_string();
        assert_eq!(
            err,
            format!(
                "{}:1: the quaternion (1e200, 0, 0, 1e200) is too large to normalise (its \
                 squared norm overflows): `bmesh view1.ply 0 0 0 1e200 0 0 1e200`",
                conf.display()
            )
        );
        std::fs::write(
            &conf,
            "bmesh view1.ply 0 0 0 0 0 0 1\nbmesh gone.ply 0 0 0 0 0 0 1\n",
        )
        .unwrap();
        let err = ScanFolder::open(&dir).unwrap_err().to_string();
        assert_eq!(
            err,
            format!(
                "{}:2: neither gone.ply nor gone.ply.gz is in the folder: `gone.ply`",
                conf.display()
            )
        );
        std::fs::remove_file(&conf).unwrap();
        let err = ScanFolder::open(&dir).unwrap_err().to_string();
        assert!(err.ends_with("no `.conf` pose file in the folder"), "{err}");
    }

    #[test]
    fn a_random_motion_stays_within_its_bounds_about_the_centre() {
        let centre = Point3::new(1.0, -2.0, 0.5);
        for seed in 0..50 {
            let mut rng = StdRng::seed_from_u64(seed);
            let m = random_motion(&mut rng, &centre, 45.0, 0.1);
            assert!(m.rotation_angle_deg() <= 45.0 + 1e-9);
            assert!((m.apply(&centre) - centre).norm() <= 0.1 + 1e-12);
        }
    }
}
