//! Registration pairs as spec §1 makes them, in the reference order:
//! 1. sample [`PairConfig::num_points`] points when the shape has more (without replacement);
//!    source and target start as the same points;
//! 2. draw G ([`RigidTransform::random`]) and apply it to the source;
//! 3. partial only: crop the source, then the target, each with its own random direction
//!    ([`crop_indices`]);
//! 4. noise and partial: jitter the source, then the target ([`jitter`]);
//! 5. shuffle the target, then the source (the reference draws the target permutation first);
//! 6. ground truth: `t_target_source` = G⁻¹; correspondences exact for clean, rebuilt from
//!    distances ([`Correspondence::rebuild`]) for noise and partial.
//!
//! All draws come from one RNG per pair. Test pair `i` uses `StdRng::seed_from_u64(i)`, so every
//! run and every method sees the same pairs; training pair `i` of epoch `e` uses a seed made of
//! both (see [`train_seed`]), so epochs differ and pairs can be made in parallel.
//!
//! The file is long because its unit tests sit beside the code they check (as everywhere in
//! rgm); the code itself is one job, kept in one place.

use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rgm_geom::{Point3, PointCloud, RigidTransform, Vector3};

use crate::correspondence::Correspondence;
use crate::modelnet::Shape;
use crate::{DataError, Result};

/// The three settings of the benchmark.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Setting {
    /// Same points, random pose: the correspondence is an exact permutation.
    Clean,
    /// Gaussian jitter (σ 0.01, clipped at 0.05) on both clouds.
    Noise,
    /// Each cloud cropped to 70 % of its points by a random plane, then jittered.
    Partial,
}

impl Setting {
    /// All settings, in table order.
    pub const ALL: [Setting; 3] = [Setting::Clean, Setting::Noise, Setting::Partial];

    /// Lower-case name, as the command line spells it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Clean => "clean",
            Self::Noise => "noise",
            Self::Partial => "partial",
        }
    }
}

impl std::str::FromStr for Setting {
    type Err = DataError;

    fn from_str(s: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| DataError::UnknownSetting {
                name: s.to_string(),
            })
    }
}

/// The protocol's constants; [`Default`] gives spec §1's values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairConfig {
    /// Points per shape before cropping (default 1,024).
    pub num_points: usize,
    /// Upper bound of each of the three Euler angles of G, degrees (default 45).
    pub max_angle_deg: f64,
    /// Upper bound of |t| per axis of G (default 0.5).
    pub max_translation: f64,
    /// Share of points the crop keeps (default 0.7: 717 of 1,024).
    pub keep_ratio: f64,
    /// Standard deviation of the jitter per coordinate (default 0.01).
    pub noise_std: f64,
    /// Jitter is clipped to ±this (default 0.05).
    pub noise_clip: f64,
}

impl Default for PairConfig {
    fn default() -> Self {
        Self {
            num_points: 1024,
            max_angle_deg: 45.0,
            max_translation: 0.5,
            keep_ratio: 0.7,
            noise_std: 0.01,
            noise_clip: 0.05,
        }
    }
}

impl PairConfig {
    /// Checks every field: `num_points` ≥ 2, `keep_ratio` in (0, 1], the others finite and ≥ 0.
    pub fn validate(&self) -> Result<()> {
        let invalid =
            |field: &'static str, value: f64| Err(DataError::InvalidConfig { field, value });
        if self.num_points < 2 {
            return invalid("num_points", self.num_points as f64);
        }
        if !(self.keep_ratio > 0.0 && self.keep_ratio <= 1.0) {
            return invalid("keep_ratio", self.keep_ratio);
        }
        for (field, value) in [
            ("max_angle_deg", self.max_angle_deg),
            ("max_translation", self.max_translation),
            ("noise_std", self.noise_std),
            ("noise_clip", self.noise_clip),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return invalid(field, value);
            }
        }
        Ok(())
    }
}

/// One registration problem with its ground truth.
#[derive(Clone, Debug)]
pub struct Pair {
    /// X: the moved (and cropped, jittered) source, shuffled. // (N,)
    pub source: PointCloud,
    /// Y: the target, shuffled. // (M,)
    pub target: PointCloud,
    /// Ground truth (R, t) = G⁻¹: `y = R x + t` maps the source onto the target.
    pub t_target_source: RigidTransform,
    /// Ground-truth correspondences between `source` and `target`.
    pub correspondence: Correspondence,
    /// Index of the shape in the list the pair was made from.
    pub shape_index: usize,
    /// Category label of the shape.
    pub label: usize,
}

impl Pair {
    /// The pair with each cloud cut independently to at most `points` points drawn at random
    /// from `rng` (source first; a cloud already that small is kept whole), and its
    /// correspondences rebuilt from distances ([`Correspondence::rebuild`]). Matching on fewer
    /// points is how RGM trains and registers cheaply: its cost grows with N·M.
    pub fn subsampled(&self, points: usize, rng: &mut impl Rng) -> Self {
        let mut cut = |cloud: &PointCloud| {
            if cloud.len() <= points {
                cloud.clone()
            } else {
                let mut kept = rand::seq::index::sample(rng, cloud.len(), points).into_vec();
                kept.sort_unstable();
                cloud.select(&kept)
            }
        };
        let (source, target) = (cut(&self.source), cut(&self.target));
        let correspondence = Correspondence::rebuild(
            &source.transformed(&self.t_target_source).points,
            &target.points,
        );
        Self {
            source,
            target,
            correspondence,
            ..self.clone()
        }
    }
}

/// Makes the pairs of one setting.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairGenerator {
    /// Which corruptions apply.
    pub setting: Setting,
    /// The protocol's constants.
    pub config: PairConfig,
}

impl PairGenerator {
    /// A generator with spec §1's constants.
    pub fn new(setting: Setting) -> Self {
        Self {
            setting,
            config: PairConfig::default(),
        }
    }

    /// Test pair `i`: shape `shapes[i]`, RNG seeded from `i`.
    pub fn test_pair(&self, shapes: &[&Shape], i: usize) -> Result<Pair> {
        self.pair_of_shape(shapes, i, &mut StdRng::seed_from_u64(i as u64))
    }

    /// Training pair `i` of `epoch`: shape `shapes[i]`, RNG seeded from [`train_seed`].
    pub fn train_pair(&self, shapes: &[&Shape], epoch: usize, i: usize) -> Result<Pair> {
        self.pair_of_shape(shapes, i, &mut StdRng::seed_from_u64(train_seed(epoch, i)))
    }

    fn pair_of_shape(&self, shapes: &[&Shape], i: usize, rng: &mut StdRng) -> Result<Pair> {
        let shape = shapes.get(i).ok_or(DataError::IndexOutOfRange {
            op: "pair",
            index: i,
            len: shapes.len(),
        })?;
        let (source, target, t_target_source, correspondence) =
            self.pair_from_points(&PointCloud::from_f32_rows(&shape.points), rng)?;
        Ok(Pair {
            source,
            target,
            t_target_source,
            correspondence,
            shape_index: i,
            label: shape.label,
        })
    }

    /// Source, target, `t_target_source` and correspondences made from `points` with `rng`.
    pub fn pair_from_points(
        &self,
        points: &PointCloud,
        rng: &mut impl Rng,
    ) -> Result<(PointCloud, PointCloud, RigidTransform, Correspondence)> {
        let c = &self.config;
        c.validate()?;
        if points.len() < 2 {
            return Err(DataError::Geom(rgm_geom::GeomError::TooFewPoints {
                op: "pair_from_points",
                needed: 2,
                got: points.len(),
            }));
        }
        let points = if points.len() > c.num_points {
            points.select(&rand::seq::index::sample(rng, points.len(), c.num_points).into_vec())
        } else {
            points.clone()
        };
        let g = RigidTransform::random(rng, c.max_angle_deg, c.max_translation);
        let mut source = points.transformed(&g);
        let mut target = points;
        // Original index of each point. // (N,), (M,)
        let mut source_origin: Vec<usize> = (0..source.len()).collect();
        let mut target_origin: Vec<usize> = (0..target.len()).collect();

        if self.setting == Setting::Partial {
            for (cloud, origin) in [
                (&mut source, &mut source_origin),
                (&mut target, &mut target_origin),
            ] {
                let kept = crop_indices(&cloud.points, &random_direction(rng), c.keep_ratio);
                *cloud = cloud.select(&kept);
                *origin = kept.iter().map(|&k| origin[k]).collect();
            }
        }
        if self.setting != Setting::Clean {
            let noise = Normal::new(0.0, c.noise_std).expect("validated: finite, non-negative");
            jitter(&mut source.points, &noise, c.noise_clip, rng);
            jitter(&mut target.points, &noise, c.noise_clip, rng);
        }
        for (cloud, origin) in [
            (&mut target, &mut target_origin),
            (&mut source, &mut source_origin),
        ] {
            let mut order: Vec<usize> = (0..cloud.len()).collect();
            order.shuffle(rng);
            *cloud = cloud.select(&order);
            *origin = order.iter().map(|&k| origin[k]).collect();
        }

        let t_target_source = g.inverse();
        let correspondence = match self.setting {
            Setting::Clean => Correspondence::from_origins(&source_origin, &target_origin),
            Setting::Noise | Setting::Partial => Correspondence::rebuild(
                &source.transformed(&t_target_source).points,
                &target.points,
            ),
        };
        Ok((source, target, t_target_source, correspondence))
    }
}

/// Seed of training pair `i` in `epoch`: the high bit set (never a test seed), the epoch in the
/// next 31 bits, `i` in the low 32.
pub fn train_seed(epoch: usize, i: usize) -> u64 {
    (1 << 63) | ((epoch as u64 & 0x7fff_ffff) << 32) | (i as u64 & 0xffff_ffff)
}

/// A direction uniform on the unit sphere, drawn as RPM-Net's `uniform_2_sphere`:
/// φ uniform in [0, 2π), cos θ uniform in [−1, 1].
pub fn random_direction(rng: &mut impl Rng) -> Vector3<f64> {
    let phi = rng.gen_range(0.0..std::f64::consts::TAU);
    let cos_theta: f64 = rng.gen_range(-1.0..1.0);
    let sin_theta = (1.0 - cos_theta * cos_theta).sqrt();
    Vector3::new(sin_theta * phi.cos(), sin_theta * phi.sin(), cos_theta)
}

/// Indices (ascending) of the points the crop keeps: projections `p_i = (x_i − centroid)·n`,
/// threshold = NumPy's `percentile(p, (1 − keep_ratio)·100)` with linear interpolation
/// (sorted `s`, rank `r = (1 − keep_ratio)(N − 1)`, `s[⌊r⌋] + (r − ⌊r⌋)(s[⌊r⌋+1] − s[⌊r⌋])`),
/// kept: `p_i > threshold`. With distinct projections that keeps `N − ⌊r⌋ − 1` points
/// whenever r is not an integer: 1,024 − 306 − 1 = 717 for N = 1,024, keep_ratio 0.7.
pub fn crop_indices(
    points: &[Point3<f64>],
    direction: &Vector3<f64>,
    keep_ratio: f64,
) -> Vec<usize> {
    if points.is_empty() {
        return Vec::new();
    }
    let centroid = PointCloud::new(points.to_vec()).centroid();
    let projections: Vec<f64> = points
        .iter()
        .map(|p| (p - centroid).dot(direction))
        .collect(); // (N,)
    let mut sorted = projections.clone();
    sorted.sort_by(f64::total_cmp);
    let rank = (1.0 - keep_ratio).clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let lo = rank.floor() as usize;
    let hi = (lo + 1).min(sorted.len() - 1);
    let threshold = sorted[lo] + (rank - lo as f64) * (sorted[hi] - sorted[lo]);
    (0..points.len())
        .filter(|&i| projections[i] > threshold)
        .collect()
}

/// Adds `noise` (N(0, σ²)) clipped to ±`clip` to every coordinate, point by point, x then y
/// then z.
pub fn jitter(points: &mut [Point3<f64>], noise: &Normal<f64>, clip: f64, rng: &mut impl Rng) {
    for p in points {
        for v in p.coords.iter_mut() {
            *v += noise.sample(rng).clamp(-clip, clip);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 1,024 distinct points scattered in the unit cube.
    fn scattered(n: usize, seed: u64) -> PointCloud {
        let mut rng = StdRng::seed_from_u64(seed);
        PointCloud::new(
            (0..n)
                .map(|_| Point3::new(rng.gen(), rng.gen(), rng.gen()))
                .collect(),
        )
    }

    #[test]
    fn subsampled_pairs_keep_the_pose_and_rebuild_correspondences() {
        let points = scattered(400, 3);
        let generator = PairGenerator::new(Setting::Clean);
        let (source, target, t, correspondence) = generator
            .pair_from_points(&points, &mut StdRng::seed_from_u64(5))
            .unwrap();
        let pair = Pair {
            source,
            target,
            t_target_source: t,
            correspondence,
            shape_index: 7,
            label: 2,
        };
        let cut = pair.subsampled(100, &mut StdRng::seed_from_u64(9));
        assert_eq!((cut.source.len(), cut.target.len()), (100, 100));
        assert_eq!((cut.shape_index, cut.label), (7, 2));
        assert_eq!(cut.t_target_source, pair.t_target_source);
        // Every kept point is one of the pair's points, and every rebuilt correspondence joins
        // points that the true pose puts within the rescue radius.
        assert!(cut
            .source
            .points
            .iter()
            .all(|p| pair.source.points.contains(p)));
        assert!(cut
            .target
            .points
            .iter()
            .all(|p| pair.target.points.contains(p)));
        let moved = cut.source.transformed(&cut.t_target_source);
        assert!(!cut.correspondence.pairs.is_empty());
        for &(i, j) in &cut.correspondence.pairs {
            assert!((moved.points[i] - cut.target.points[j]).norm() < 0.1);
        }
        // Independent cuts of 100 from 400: exact twins survive in both for about 1/16 of the
        // points; the clean pair's exact matches among them are all found.
        let twins = cut
            .source
            .points
            .iter()
            .filter(|p| {
                let q = cut.t_target_source.apply(p);
                cut.target.points.iter().any(|t| (t - q).norm() < 1e-9)
            })
            .count();
        assert!(cut.correspondence.pairs.len() >= twins);
        // A cloud already small enough is kept whole and in order.
        let whole = pair.subsampled(1000, &mut StdRng::seed_from_u64(9));
        assert_eq!(whole.source.points, pair.source.points);
        assert_eq!(whole.correspondence.pairs, pair.correspondence.pairs);
    }

    fn shape(points: &PointCloud, label: usize) -> Shape {
        Shape {
            name: "s".into(),
            label,
            points: points.to_f32_rows(),
        }
    }

    #[test]
    fn crop_keeps_717_of_1024() {
        let cloud = scattered(1024, 1);
        let mut rng = StdRng::seed_from_u64(2);
        for _ in 0..50 {
            assert_eq!(
                crop_indices(&cloud.points, &random_direction(&mut rng), 0.7).len(),
                717
            );
        }
    }

    #[test]
    fn crop_threshold_is_numpys_linear_percentile() {
        // Projections 0..=4 onto x (centroid 2 → −2..=2): percentile 50 is the median 0, kept 1, 2.
        let points: Vec<_> = (0..5).map(|i| Point3::new(i as f64, 0.0, 0.0)).collect();
        assert_eq!(crop_indices(&points, &Vector3::x(), 0.5), [3, 4]);
        // Percentile 30 of −2..=2: rank 1.2 → −1 + 0.2 = −0.8; kept 0, 1, 2 → indices 2, 3, 4.
        assert_eq!(crop_indices(&points, &Vector3::x(), 0.7), [2, 3, 4]);
        // Along −x the far side is kept.
        assert_eq!(crop_indices(&points, &-Vector3::x(), 0.7), [0, 1, 2]);
    }

    #[test]
    fn jitter_is_clipped_and_has_the_right_spread() {
        let mut points = vec![Point3::origin(); 20_000];
        let noise = Normal::new(0.0, 0.01).unwrap();
        jitter(&mut points, &noise, 0.05, &mut StdRng::seed_from_u64(3));
        let values: Vec<f64> = points.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
        assert!(values.iter().all(|v| v.abs() <= 0.05));
        let std = (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt();
        assert!((std - 0.01).abs() < 2e-4, "{std}");
        // With a tiny clip every value is clipped.
        let mut points = vec![Point3::origin(); 100];
        jitter(&mut points, &noise, 1e-9, &mut StdRng::seed_from_u64(4));
        assert!(points
            .iter()
            .all(|p| p.coords.iter().all(|v| v.abs() == 1e-9)));
    }

    #[test]
    fn random_directions_are_unit_and_centred() {
        let mut rng = StdRng::seed_from_u64(5);
        let dirs: Vec<_> = (0..20_000).map(|_| random_direction(&mut rng)).collect();
        assert!(dirs.iter().all(|d| (d.norm() - 1.0).abs() < 1e-12));
        let mean: Vector3<f64> = dirs.iter().sum::<Vector3<f64>>() / dirs.len() as f64;
        assert!(mean.norm() < 0.02, "{mean}");
    }

    #[test]
    fn clean_pairs_are_exact_permutations_under_the_true_transform() {
        let cloud = scattered(1024, 6);
        let shapes = [shape(&cloud, 7)];
        let shapes: Vec<&Shape> = shapes.iter().collect();
        let pair = PairGenerator::new(Setting::Clean)
            .test_pair(&shapes, 0)
            .unwrap();
        assert_eq!(
            (pair.source.len(), pair.target.len(), pair.label),
            (1024, 1024, 7)
        );
        assert_eq!(pair.correspondence.pairs.len(), 1024);
        let moved = pair.source.transformed(&pair.t_target_source);
        for &(i, j) in &pair.correspondence.pairs {
            assert!((moved.points[i] - pair.target.points[j]).norm() < 1e-12);
        }
        // Shuffled: the identity order would put most pairs on the diagonal.
        assert!(
            pair.correspondence
                .pairs
                .iter()
                .filter(|(i, j)| i == j)
                .count()
                < 20
        );
        // The source was moved by G, at most 135° and 0.5·√3 away.
        assert!(pair.t_target_source.rotation_angle_deg() > 1.0);
    }

    #[test]
    fn test_pairs_are_deterministic_and_differ_by_index_and_epoch() {
        let cloud = scattered(1024, 8);
        let owned = [shape(&cloud, 0), shape(&cloud, 0)];
        let shapes: Vec<&Shape> = owned.iter().collect();
        let generator = PairGenerator::new(Setting::Partial);
        let a = generator.test_pair(&shapes, 1).unwrap();
        let b = generator.test_pair(&shapes, 1).unwrap();
        assert_eq!(
            (a.source, a.target, a.t_target_source),
            (b.source, b.target, b.t_target_source)
        );
        let c = generator.test_pair(&shapes, 0).unwrap();
        assert_ne!(a.t_target_source, c.t_target_source);
        let train0 = generator.train_pair(&shapes, 0, 1).unwrap();
        let train1 = generator.train_pair(&shapes, 1, 1).unwrap();
        assert_ne!(train0.t_target_source, train1.t_target_source);
        assert_ne!(train0.t_target_source, a.t_target_source);
        let err = generator.test_pair(&shapes, 2).unwrap_err().to_string();
        assert_eq!(err, "pair: index 2 out of range for length 2");
    }

    #[test]
    fn partial_pairs_keep_717_points_and_one_to_one_close_correspondences() {
        let cloud = scattered(1024, 9);
        let owned = [shape(&cloud, 0)];
        let shapes: Vec<&Shape> = owned.iter().collect();
        let generator = PairGenerator::new(Setting::Partial);
        let pair = generator.test_pair(&shapes, 0).unwrap();
        assert_eq!((pair.source.len(), pair.target.len()), (717, 717));
        let c = &pair.correspondence;
        assert_eq!(
            Correspondence::new(c.n_source, c.n_target, c.pairs.clone()).unwrap(),
            *c
        );
        // Matched points lie within the rescue radius once the source is moved back.
        let moved = pair.source.transformed(&pair.t_target_source);
        let farthest = c
            .pairs
            .iter()
            .map(|&(i, j)| (moved.points[i] - pair.target.points[j]).norm());
        assert!(farthest.fold(0.0, f64::max) < 0.1);
        assert!(
            c.matched_source_fraction() > 0.3,
            "{}",
            c.matched_source_fraction()
        );
    }

    #[test]
    fn shapes_with_more_points_are_sampled_down() {
        let cloud = scattered(2048, 10);
        let generator = PairGenerator::new(Setting::Noise);
        let (source, target, _, c) = generator
            .pair_from_points(&cloud, &mut StdRng::seed_from_u64(0))
            .unwrap();
        assert_eq!((source.len(), target.len(), c.n_source), (1024, 1024, 1024));
        let tiny = PointCloud::new(vec![Point3::origin()]);
        assert!(generator
            .pair_from_points(&tiny, &mut StdRng::seed_from_u64(0))
            .is_err());
    }

    #[test]
    fn invalid_configs_are_named() {
        let cloud = scattered(10, 11);
        for (config, message) in [
            (
                PairConfig {
                    keep_ratio: 0.0,
                    ..Default::default()
                },
                "pair config: keep_ratio = 0 is out of range",
            ),
            (
                PairConfig {
                    noise_std: -0.01,
                    ..Default::default()
                },
                "pair config: noise_std = -0.01 is out of range",
            ),
            (
                PairConfig {
                    max_angle_deg: f64::NAN,
                    ..Default::default()
                },
                "pair config: max_angle_deg = NaN is out of range",
            ),
            (
                PairConfig {
                    num_points: 1,
                    ..Default::default()
                },
                "pair config: num_points = 1 is out of range",
            ),
        ] {
            let generator = PairGenerator {
                setting: Setting::Partial,
                config,
            };
            let err = generator
                .pair_from_points(&cloud, &mut StdRng::seed_from_u64(0))
                .unwrap_err();
            assert_eq!(err.to_string(), message);
        }
    }

    #[test]
    fn setting_names_round_trip() {
        for s in Setting::ALL {
            assert_eq!(s.name().parse::<Setting>().unwrap(), s);
        }
        assert_eq!(
            "crop".parse::<Setting>().unwrap_err().to_string(),
            "unknown setting `crop` (expected clean, noise or partial)"
        );
    }
}
