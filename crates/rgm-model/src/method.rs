//! The registration methods rgm can run, behind one interface.

use std::path::Path;
use std::time::Instant;

use rgm_geom::fgr::{self, FgrConfig};
use rgm_geom::icp::{self, IcpConfig};
use rgm_geom::refine::{self, RefineConfig};
use rgm_geom::registration::score;
use rgm_geom::{KnnIndex, PointCloud, RegistrationResult};

use crate::combined::{Candidate, CombinedRegistrar};
use crate::error::MethodError;
use crate::network::{Config, Rgm};
use crate::pipeline::{PipelineConfig, RgmRegistrar};

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
    /// RGM and FGR, each refined when asked, and the better by a score without ground truth
    /// ([`crate::combined`]): `rgm register`'s default.
    Combined(Box<CombinedRegistrar>),
}

/// A method's result on one pair and the time the method itself took.
#[derive(Clone, Debug)]
pub struct Registration {
    /// The transform found, its iterations and inlier statistics.
    pub result: RegistrationResult,
    /// Wall time of the method alone (no file reading), in milliseconds.
    pub time_ms: f64,
    /// The combined method's candidates, each with its score (empty for the other methods),
    /// and the index of the one returned.
    pub candidates: Vec<Candidate>,
    pub chosen: Option<usize>,
    /// Why the result is not to be trusted, when it is not (the combined method's best
    /// candidate overlaps too little, [`crate::combined::MIN_OVERLAP`]): the caller reports the
    /// pair as not registered, with this reason.
    pub doubt: Option<String>,
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
            Self::Combined(mut combined) => {
                combined.refine = Some(refine);
                Self::Combined(combined)
            }
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
            Self::Combined(combined) => combined.refine.is_some(),
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
            Self::Combined(_) if self.is_refined() => "auto+icp",
            Self::Combined(_) => "auto",
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
            Self::Combined(combined) => combined.register(source, target)?,
        };
        let t = &result.t_target_source;
        let values = t.rotation.iter().chain(t.translation.iter());
        if !values
            .chain([&result.fitness, &result.inlier_rmse])
            .all(|v| v.is_finite())
        {
            return Err(MethodError::NotFinite {
                method: self.name(),
                found: format!("{:?}", t.to_rows()),
            });
        }
        let (candidates, chosen, doubt) = match self {
            Self::Combined(combined) => (
                combined.candidates().to_vec(),
                combined.chosen(),
                combined.doubt(),
            ),
            _ => (Vec::new(), None, None),
        };
        Ok(Registration {
            result,
            time_ms: start.elapsed().as_secs_f64() * 1e3,
            candidates,
            chosen,
            doubt,
        })
    }

    /// The (source index, target index) pairs behind `result.inlier_count`, for `result` found
    /// by [`Method::register`] on `source` and `target` just before: RGM's hard matches of its
    /// last pass; for the others, the source points that `result`'s transform brings within the
    /// method's scoring distance of their nearest target point (Open3D's correspondence set).
    pub fn correspondences(
        &self,
        source: &PointCloud,
        target: &PointCloud,
        result: &RegistrationResult,
    ) -> Vec<(usize, usize)> {
        let max_distance = match self {
            Self::Rgm(registrar) => return registrar.correspondences().to_vec(),
            Self::Combined(combined) => return combined.correspondences().to_vec(),
            Self::Icp(config) => config.max_correspondence_distance,
            Self::Fgr(config) => config.maximum_correspondence_distance,
            Self::FgrRefined { refine, .. } => refine.finest_distance(),
        };
        let mut pairs = Vec::new();
        score(
            &source.points,
            &KnnIndex::new(&target.points),
            &result.t_target_source,
            max_distance,
            Some(&mut pairs),
        );
        pairs
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rgm_geom::{Point3, RigidTransform};

    #[test]
    fn correspondences_are_the_pairs_behind_the_inlier_count() {
        // 200 points on a twisted curve, and the same points moved by 5° and 0.02.
        let source = PointCloud::new(
            (0..200)
                .map(|i| {
                    let s = i as f64 / 200.0;
                    Point3::new((7.0 * s).cos(), (5.0 * s).sin(), s * s)
                })
                .collect(),
        );
        let pose = RigidTransform::new(
            rgm_geom::euler::rotation_xyz_intrinsic(0.0, 0.0, 5f64.to_radians()),
            rgm_geom::Vector3::new(0.02, 0.0, 0.0),
        );
        let target = source.transformed(&pose);
        let refine = RefineConfig::default();
        for (mut method, max_distance) in [
            (
                Method::icp(),
                IcpConfig::default().max_correspondence_distance,
            ),
            (
                Method::fgr(),
                FgrConfig::default().maximum_correspondence_distance,
            ),
            (
                Method::fgr().refined(refine.clone()),
                refine.finest_distance(),
            ),
        ] {
            let result = method.register(&source, &target).unwrap().result;
            let pairs = method.correspondences(&source, &target, &result);
            assert_eq!(pairs.len(), result.inlier_count, "{}", method.name());
            assert!(pairs.len() > 100, "{}: {}", method.name(), pairs.len());
            for &(i, j) in &pairs {
                let d = (result.t_target_source.apply(&source.points[i]) - target.points[j]).norm();
                assert!(d < max_distance, "{}: {d}", method.name());
            }
        }
    }
}
