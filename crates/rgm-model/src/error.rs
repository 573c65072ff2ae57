//! Why a registration method found no transform (one error type for every method of this crate).

use std::path::PathBuf;

use rgm_geom::GeomError;
use rgm_match::MatchError;

use crate::network::NetworkError;

/// Why a method found no transform.
#[derive(Debug, thiserror::Error)]
pub enum MethodError {
    /// A geometric step failed (too few points, degenerate Kabsch, ...).
    #[error(transparent)]
    Geom(#[from] GeomError),
    /// Every candidate of a composite method failed.
    #[error(transparent)]
    AllCandidatesFailed(#[from] rgm_registration::AllCandidatesFailed),
    /// The network could not be built, loaded or run.
    #[error(transparent)]
    Network(#[from] NetworkError),
    /// Matching failed.
    #[error(transparent)]
    Match(#[from] MatchError),
    /// No correspondence survived inlier selection (or cycle consistency) at `stage`.
    #[error("rgm: no correspondences found in {stage} (no row and column of C̃ above the inlier threshold agree)")]
    NoCorrespondences { stage: String },
    /// A cloud too small for the network's neighbour graph.
    #[error("rgm: the {cloud} cloud has {points} points to match; the network needs at least {needed} (K + 1)")]
    TooFewPoints {
        cloud: &'static str,
        points: usize,
        needed: usize,
    },
    /// Matching this many points would need more memory than this process may take
    /// ([`rgm_data::memory::available`]; the network's memory grows with the square of the
    /// matched points).
    #[error(
        "rgm: matching {} × {} points would need about {:.1} GiB, more than the {:.1} GiB \
         this process may take (free memory, ulimit -v, cgroup limit); match on fewer points \
         (the `match_points` setting)",
        points.0, points.1, *estimate as f64 / (1u64 << 30) as f64, *available as f64 / (1u64 << 30) as f64
    )]
    TooMuchMemory {
        points: (usize, usize),
        estimate: u64,
        available: u64,
    },
    /// The method's transform or score is not a finite number (a degenerate pair, or clouds
    /// at a scale the method cannot work at): reported as an error, never as a result.
    /// A cloud of copies of one point: every rotation about it fits as well.
    #[error("the {cloud} cloud's {points} points all lie at one place: a rigid pose has no rotation to find from it")]
    OnePlace { cloud: &'static str, points: usize },
    #[error("{method} found no finite transform (found {found})")]
    NotFinite { method: String, found: String },
    /// Options that do not fit the method ([`crate::options::MethodOptions`]).
    #[error("{0}")]
    InvalidOptions(String),
    /// A test-time setting that cannot run.
    #[error("rgm: invalid settings: {why}")]
    InvalidConfig { why: String },
    /// A weights manifest could not be read or is not valid.
    #[error("weights manifest {path}: {why}")]
    Manifest { path: PathBuf, why: String },
}
