//! The registration methods rgm can run, behind one interface.

use std::time::Instant;

use rgm_geom::fgr::{self, FgrConfig};
use rgm_geom::icp::{self, IcpConfig};
use rgm_geom::{PointCloud, RegistrationResult};

/// A registration method with its configuration.
#[derive(Clone, Debug)]
pub enum Method {
    /// Point-to-point ICP.
    Icp(IcpConfig),
    /// Fast Global Registration on FPFH features.
    Fgr(FgrConfig),
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

    /// The method's short name, as the command line and the tables spell it.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Icp(_) => "icp",
            Self::Fgr(_) => "fgr",
        }
    }

    /// The transform that maps `source` onto `target`, timed.
    pub fn register(
        &self,
        source: &PointCloud,
        target: &PointCloud,
    ) -> rgm_geom::Result<Registration> {
        let start = Instant::now();
        let result = match self {
            Self::Icp(config) => icp::register(source, target, config)?,
            Self::Fgr(config) => fgr::register(source, target, config)?,
        };
        Ok(Registration {
            result,
            time_ms: start.elapsed().as_secs_f64() * 1e3,
        })
    }
}
