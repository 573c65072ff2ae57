//! A second-order compatibility estimator on FPFH correspondences, for scene-scale pairs where
//! the right matches are too few for RANSAC's random triples to find (a room at low overlap):
//! after SC²-PCR (Chen et al., CVPR 2022), deterministic.
//!
//! 1–3. The pair thinned, its FPFH features and their matches ([`crate::methods::feature_matches`]).
//! 4. Compatibility: two matches are compatible when the distance between their source points
//!    and the distance between their target points differ by less than
//!    [`Sc2Config::compatibility`] inlier distances (a rigid motion keeps lengths). Right
//!    matches are all compatible with one another; wrong ones only by chance.
//! 5. Seeds: the [`Sc2Config::seeds`] matches compatible with the most others.
//! 6. Each seed's hypothesis: the Kabsch fit of the seed and its [`Sc2Config::mates`]
//!    compatible matches that share the most compatible matches with it (the second order:
//!    two right matches share every other right match, two that agree by chance share few).
//! 7. The [`Sc2Config::judged`] hypotheses most matches agree with, each refitted on its
//!    inliers, judged by [`Matched::fitness`]; the best is refined
//!    ([`crate::methods::feature_matches`]).

use rayon::prelude::*;
use rgm_geom::{kabsch, GeomError, PointCloud, Result, RigidTransform};

use crate::fit::Fit;
use crate::methods::feature_matches::{
    inliers_of, refitted, register_matched, Consensus, Matched, MatchingConfig,
};
use crate::registrar::{MethodId, Progress, Registrar, Registration};
use crate::Prepared;

/// The method's name ([`crate::registrar::MethodId`]).
pub const NAME: &str = "sc2";

/// Settings of [`register`].
#[derive(Clone, Debug, PartialEq)]
pub struct Sc2Config {
    pub matching: MatchingConfig,
    /// Two matches are compatible when their lengths differ by less than this many inlier
    /// distances (default 1).
    pub compatibility: f64,
    /// Seeds, the matches compatible with the most others (default 200).
    pub seeds: usize,
    /// Matches fitted with each seed (default 30).
    pub mates: usize,
    /// Hypotheses refitted and judged by fitness (default 10).
    pub judged: usize,
    /// Refits of each judged hypothesis on its inliers, at most (default 5).
    pub refits: usize,
}

impl Default for Sc2Config {
    fn default() -> Self {
        Self {
            matching: MatchingConfig::default(),
            compatibility: 1.0,
            seeds: 200,
            mates: 30,
            judged: 10,
            refits: 5,
        }
    }
}

/// Registers `source` onto `target` by second-order compatibility on FPFH matches of the
/// thinned pair (steps 1–7 of the module). The result is scored on the thinned pair at the
/// inlier distance.
pub fn register(source: &PointCloud, target: &PointCloud, config: &Sc2Config) -> Result<Fit> {
    register_prepared(&Prepared::new(source), &Prepared::new(target), config)
}

/// [`register`] on prepared clouds.
pub fn register_prepared(source: &Prepared, target: &Prepared, config: &Sc2Config) -> Result<Fit> {
    const OP: &str = "sc2::register";
    if config.seeds == 0 || config.mates < 2 || config.judged == 0 {
        return Err(GeomError::Degenerate {
            op: OP,
            why: format!(
                "seeds and judged must be at least 1 and mates at least 2, got {}, {} and {}",
                config.seeds, config.judged, config.mates
            ),
        });
    }
    register_matched(OP, source, target, &config.matching, |matched: &Matched| {
        let squared = matched.distance * matched.distance;
        let graph = Compatibility::new(
            &matched.from,
            &matched.to,
            config.compatibility * matched.distance,
        );
        let hypotheses = graph.hypotheses(&matched.from, &matched.to, squared, config);
        let judged: Vec<(f64, Consensus)> = hypotheses
            .par_iter()
            .take(config.judged)
            .map(|(_, t)| {
                let found = refitted(
                    &matched.from,
                    &matched.to,
                    *t,
                    squared,
                    config.refits,
                    hypotheses.len(),
                );
                (matched.fitness(&found.t_target_source), found)
            })
            .collect();
        // The fittest; ties to the hypothesis more matches agree with.
        judged
            .into_iter()
            .reduce(|best, next| if next.0 > best.0 { next } else { best })
            .map(|(_, found)| found)
            .ok_or_else(|| GeomError::Degenerate {
                op: OP,
                why: format!(
                    "no seed's matches among the {} fitted a transform",
                    matched.from.len()
                ),
            })
    })
}

/// Which matches are compatible with which: one bit per pair, a row per match.
struct Compatibility {
    /// Words per row.
    words: usize,
    bits: Vec<u64>, // (C, ⌈C/64⌉)
}

impl Compatibility {
    /// Matches `i` and `j` compatible when `| |from[i] − from[j]| − |to[i] − to[j]| |` is below
    /// `tolerance` (a match is not compatible with itself).
    fn new(from: &[nalgebra::Point3<f64>], to: &[nalgebra::Point3<f64>], tolerance: f64) -> Self {
        let n = from.len();
        let words = n.div_ceil(64);
        // The n² lengths in f32, coordinate by coordinate so that they vectorise; each cloud
        // about its own centroid first, so that survey-size offsets keep their precision
        // (lengths do not change).
        let columns = |points: &[nalgebra::Point3<f64>]| {
            let centre = points
                .iter()
                .map(|p| p.coords)
                .sum::<nalgebra::Vector3<f64>>()
                / points.len() as f64;
            let column = |k: usize| -> Vec<f32> {
                points.iter().map(|p| (p[k] - centre[k]) as f32).collect()
            };
            [column(0), column(1), column(2)] // 3 × (C,)
        };
        let ([ax, ay, az], [bx, by, bz]) = (columns(from), columns(to));
        let tolerance = tolerance as f32;
        let mut bits = vec![0u64; n * words];
        bits.par_chunks_mut(words).enumerate().for_each_init(
            || vec![0f32; n], // (C,) this row's length differences
            |gaps, (i, row)| {
                // Slices of one length, so that the loop runs without bounds checks.
                let (ax, ay, az, bx, by, bz) =
                    (&ax[..n], &ay[..n], &az[..n], &bx[..n], &by[..n], &bz[..n]);
                let gaps = &mut gaps[..n];
                for j in 0..n {
                    let (x, y, z) = (ax[j] - ax[i], ay[j] - ay[i], az[j] - az[i]);
                    let (u, v, w) = (bx[j] - bx[i], by[j] - by[i], bz[j] - bz[i]);
                    gaps[j] =
                        ((x * x + y * y + z * z).sqrt() - (u * u + v * v + w * w).sqrt()).abs();
                }
                for (word, block) in row.iter_mut().zip(gaps.chunks(64)) {
                    *word = block
                        .iter()
                        .enumerate()
                        .fold(0, |acc, (k, &g)| acc | ((g < tolerance) as u64) << k);
                }
                row[i / 64] &= !(1 << (i % 64));
            },
        );
        Self { words, bits }
    }

    fn row(&self, i: usize) -> &[u64] {
        &self.bits[i * self.words..(i + 1) * self.words]
    }

    /// The matches compatible with `i`.
    fn compatible(&self, i: usize) -> impl Iterator<Item = usize> + '_ {
        self.row(i).iter().enumerate().flat_map(|(w, &word)| {
            (0..64)
                .filter(move |b| word >> b & 1 == 1)
                .map(move |b| w * 64 + b)
        })
    }

    /// How many matches `i` and `j` are both compatible with.
    fn shared(&self, i: usize, j: usize) -> u32 {
        self.row(i)
            .iter()
            .zip(self.row(j))
            .map(|(a, b)| (a & b).count_ones())
            .sum()
    }

    /// Each seed's hypothesis (steps 5–6), as (matches within √`squared`, transform), the most
    /// first (ties to the seed of higher degree, then lower index).
    fn hypotheses(
        &self,
        from: &[nalgebra::Point3<f64>],
        to: &[nalgebra::Point3<f64>],
        squared: f64,
        config: &Sc2Config,
    ) -> Vec<(usize, RigidTransform)> {
        let n = from.len();
        let degree: Vec<u32> = (0..n)
            .map(|i| self.row(i).iter().map(|w| w.count_ones()).sum())
            .collect(); // (C,)
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by_key(|&i| std::cmp::Reverse(degree[i]));
        let mut found: Vec<(usize, RigidTransform)> = order
            .par_iter()
            .take(config.seeds)
            .filter_map(|&seed| {
                let mut mates: Vec<(u32, usize)> = self
                    .compatible(seed)
                    .map(|j| (self.shared(seed, j), j))
                    .collect();
                mates.sort_by_key(|&(shared, j)| (std::cmp::Reverse(shared), j));
                let set: Vec<usize> = std::iter::once(seed)
                    .chain(mates.iter().take(config.mates).map(|&(_, j)| j))
                    .collect();
                if set.len() < 3 {
                    return None;
                }
                let a: Vec<_> = set.iter().map(|&c| from[c]).collect(); // (K, 3)
                let b: Vec<_> = set.iter().map(|&c| to[c]).collect(); // (K, 3)
                let t = kabsch(&a, &b, &vec![1.0; a.len()]).ok()?;
                Some((inliers_of(from, to, &t, squared).count(), t))
            })
            .collect();
        // A stable sort keeps the seeds' order among equal counts.
        found.sort_by_key(|&(count, _)| std::cmp::Reverse(count));
        found
    }
}

/// Second-order compatibility on FPFH matches ([`register`]).
impl<E: From<GeomError>> Registrar<E> for Sc2Config {
    /// `sc2+refine`: its last step is point-to-plane ICP ([`MatchingConfig::refinement`]).
    fn id(&self) -> MethodId {
        self.matching.method_id(NAME)
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        _: &mut dyn FnMut(Progress),
    ) -> std::result::Result<Registration, E> {
        MatchingConfig::registration(|| register_prepared(source, target, self))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::far_pose as pose;
    use nalgebra::Point3;
    use rand::{rngs::StdRng, SeedableRng};
    use rgm_geom::testing::uniform_cube;

    /// 30 right matches among 970 wrong ones (97 % outliers, too many for RANSAC's triples:
    /// 1 draw in 37,000 is three right ones): the right ones are the seeds' consensus.
    #[test]
    fn second_order_compatibility_finds_the_few_right_matches() {
        let mut rng = StdRng::seed_from_u64(5);
        let from = uniform_cube(1000, &mut rng);
        let truth = pose();
        let wrong = uniform_cube(970, &mut rng);
        let to: Vec<Point3<f64>> = from
            .iter()
            .enumerate()
            .map(|(c, p)| {
                if c < 30 {
                    truth.apply(p)
                } else {
                    wrong[c - 30]
                }
            })
            .collect();
        let graph = Compatibility::new(&from, &to, 0.01);
        // Right matches are compatible with one another.
        assert!((1..30).all(|j| graph.compatible(0).any(|k| k == j)));
        assert!(graph.shared(0, 1) >= 28);
        let found = graph.hypotheses(&from, &to, 1e-4, &Sc2Config::default());
        let (count, t) = &found[0];
        assert_eq!(*count, 30);
        let angle = t.inverse().compose(&truth).rotation_angle_deg();
        assert!(angle < 1e-6, "{angle}°");
        assert!((t.translation - truth.translation).norm() < 1e-6);
    }

    /// A room registered at its own scale and at 1,024 times it
    /// ([`crate::testing::assert_registers_a_room_at_any_scale`]).
    #[test]
    fn a_dense_scene_is_registered_at_any_scale() {
        let config = Sc2Config {
            matching: MatchingConfig {
                max_points: 1500,
                ..MatchingConfig::default()
            },
            ..Sc2Config::default()
        };
        crate::testing::assert_registers_a_room_at_any_scale(|s, t| {
            register(s, t, &config).unwrap()
        });
    }

    #[test]
    fn bad_settings_are_refused() {
        let cloud = PointCloud::new(uniform_cube(50, &mut StdRng::seed_from_u64(1)));
        let config = Sc2Config {
            mates: 1,
            ..Sc2Config::default()
        };
        let err = register(&cloud, &cloud, &config).unwrap_err();
        assert!(err.to_string().contains("mates at least 2"), "{err}");
    }
}
