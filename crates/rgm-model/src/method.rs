//! The registration methods rgm can run, behind one interface.

use std::path::{Path, PathBuf};
use std::time::Instant;

use rgm_geom::fgr::{self, FgrConfig};
use rgm_geom::icp::{self, IcpConfig};
use rgm_geom::refine::{self, RefineConfig};
use rgm_geom::{GeomError, PointCloud, RegistrationResult};
use rgm_match::MatchError;

use crate::network::{Config, NetworkError, Rgm};
use crate::pipeline::{PipelineConfig, RgmRegistrar};

/// Why a method found no transform.
#[derive(Debug, thiserror::Error)]
pub enum MethodError {
    /// A geometric step failed (too few points, degenerate Kabsch, ...).
    #[error(transparent)]
    Geom(#[from] GeomError),
    /// The network could not be built, loaded or run.
    #[error(transparent)]
    Network(#[from] NetworkError),
    /// Matching failed.
    #[error(transparent)]
    Match(#[from] MatchError),
    /// No correspondence survived inlier selection (and cycle consistency).
    #[error("rgm: no correspondences found in pass {pass} (no row and column of C̃ above the inlier threshold agree)")]
    NoCorrespondences { pass: usize },
    /// A cloud too small for the network's neighbour graph.
    #[error("rgm: the {cloud} cloud has {points} points to match; the network needs at least {needed} (K + 1)")]
    TooFewPoints {
        cloud: &'static str,
        points: usize,
        needed: usize,
    },
    /// A weights manifest could not be read or is not valid.
    #[error("weights manifest {path}: {why}")]
    Manifest { path: PathBuf, why: String },
}

/// A registration method with its configuration.
#[derive(Clone, Debug)]
pub enum Method {
    /// Point-to-point ICP.
    Icp(IcpConfig),
    /// Fast Global Registration on FPFH features.
    Fgr(FgrConfig),
    /// FGR, then the ICP refinement of [`rgm_geom::refine`] from FGR's transform (the
    /// classical coarse-to-fine pair).
    FgrRefined {
        fgr: FgrConfig,
        refine: RefineConfig,
    },
    /// The RGM network and the test-time procedure of spec §4.
    Rgm(Box<RgmRegistrar>),
}

/// A method's result on one pair and the time the method itself took.
#[derive(Clone, Debug)]
pub struct Registration {
    /// The transform found, its iterations and inlier statistics.
    pub result: RegistrationResult,
    /// Wall time of the method alone (no file reading), in milliseconds.
    pub time_ms: f64,
}

impl Method {
    /// ICP with its default configuration.
    pub fn icp() -> Self {
        Self::Icp(IcpConfig::default())
    }

    /// FGR with its default configuration.
    pub fn fgr() -> Self {
        Self::Fgr(FgrConfig::default())
    }

    /// RGM of `config`'s sizes with the weights in the safetensors file `weights` (the
    /// authors' parameter names), and the paper's test-time settings.
    pub fn rgm(config: Config, weights: &Path) -> Result<Self, MethodError> {
        let network = Rgm::load(config, weights)?;
        Ok(Self::Rgm(Box::new(RgmRegistrar::new(
            network,
            PipelineConfig::default(),
        ))))
    }

    /// This method followed by the ICP refinement of [`rgm_geom::refine`] (trimmed
    /// point-to-plane, coarse to fine) from its transform. RGM refines in its own frame, on the
    /// full clouds (so the distances of `refine` are in unit-sphere units for any input); ICP,
    /// already its own refinement, is returned unchanged.
    pub fn refined(self, refine: RefineConfig) -> Self {
        match self {
            Self::Fgr(fgr) | Self::FgrRefined { fgr, .. } => Self::FgrRefined { fgr, refine },
            Self::Rgm(mut registrar) => {
                registrar.config.refine = Some(refine);
                Self::Rgm(registrar)
            }
            icp_alone @ Self::Icp(_) => icp_alone,
        }
    }

    /// Whether the method's transform is refined ([`Method::refined`]).
    pub fn is_refined(&self) -> bool {
        match self {
            Self::Icp(_) | Self::Fgr(_) => false,
            Self::FgrRefined { .. } => true,
            Self::Rgm(registrar) => registrar.config.refine.is_some(),
        }
    }

    /// The method's short name, as the command line and the tables spell it (`+icp` when
    /// refined).
    pub fn name(&self) -> &'static str {
        match self {
            Self::Icp(_) => "icp",
            Self::Fgr(_) => "fgr",
            Self::FgrRefined { .. } => "fgr+icp",
            Self::Rgm(_) if self.is_refined() => "rgm+icp",
            Self::Rgm(_) => "rgm",
        }
    }

    /// The transform that maps `source` onto `target`, timed.
    pub fn register(
        &mut self,
        source: &PointCloud,
        target: &PointCloud,
    ) -> Result<Registration, MethodError> {
        self.register_with_progress(source, target, &mut |_| {})
    }

    /// [`Method::register`], telling `progress` where FGR is (for a bar on large clouds; the
    /// other methods report nothing).
    pub fn register_with_progress(
        &mut self,
        source: &PointCloud,
        target: &PointCloud,
        progress: &mut dyn FnMut(fgr::Progress),
    ) -> Result<Registration, MethodError> {
        let start = Instant::now();
        let result = match self {
            Self::Icp(config) => icp::register(source, target, config)?,
            Self::Fgr(config) => fgr::register_with_progress(source, target, config, progress)?,
            Self::FgrRefined { fgr, refine } => {
                let coarse = fgr::register_with_progress(source, target, fgr, progress)?;
                let fine = refine::refine(source, target, &coarse.t_target_source, refine)?;
                RegistrationResult {
                    iterations: coarse.iterations + fine.iterations,
                    ..fine
                }
            }
            Self::Rgm(registrar) => registrar.register(source, target)?,
        };
        Ok(Registration {
            result,
            time_ms: start.elapsed().as_secs_f64() * 1e3,
        })
    }
}
