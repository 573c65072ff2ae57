//! The registration methods rgm can run, behind one interface.

use std::path::{Path, PathBuf};
use std::time::Instant;

use rgm_geom::fgr::{self, FgrConfig};
use rgm_geom::icp::{self, IcpConfig};
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
    /// FGR, then point-to-point ICP from FGR's transform (the classical coarse-to-fine pair).
    FgrIcp { fgr: FgrConfig, icp: IcpConfig },
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

    /// This method followed by point-to-point ICP from its transform (`icp.initial` is
    /// replaced by it). RGM refines in its own frame, on the full clouds (so the distances of
    /// `icp` are in unit-sphere units for any input); ICP, already its own refinement, is
    /// returned unchanged.
    pub fn refined(self, icp: IcpConfig) -> Self {
        match self {
            Self::Fgr(fgr) | Self::FgrIcp { fgr, .. } => Self::FgrIcp { fgr, icp },
            Self::Rgm(mut registrar) => {
                registrar.config.refine = Some(icp);
                Self::Rgm(registrar)
            }
            icp_alone @ Self::Icp(_) => icp_alone,
        }
    }

    /// Whether ICP refines the method's transform ([`Method::refined`]).
    pub fn is_refined(&self) -> bool {
        match self {
            Self::Icp(_) | Self::Fgr(_) => false,
            Self::FgrIcp { .. } => true,
            Self::Rgm(registrar) => registrar.config.refine.is_some(),
        }
    }

    /// The method's short name, as the command line and the tables spell it (`+icp` when
    /// refined).
    pub fn name(&self) -> &'static str {
        match self {
            Self::Icp(_) => "icp",
            Self::Fgr(_) => "fgr",
            Self::FgrIcp { .. } => "fgr+icp",
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
        let start = Instant::now();
        let result = match self {
            Self::Icp(config) => icp::register(source, target, config)?,
            Self::Fgr(config) => fgr::register(source, target, config)?,
            Self::FgrIcp { fgr, icp } => {
                let coarse = fgr::register(source, target, fgr)?;
                let config = IcpConfig {
                    initial: coarse.t_target_source,
                    ..*icp
                };
                let fine = icp::register(source, target, &config)?;
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
