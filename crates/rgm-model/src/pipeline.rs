//! RGM at test time (spec §4): the network's soft correspondences, inlier selection, linear
//! assignment, cycle consistency and weighted Kabsch, iterated on the moved source.

use ndarray::Array2;
use rgm_geom::kabsch::kabsch;
use rgm_geom::{Point3, PointCloud, RegistrationResult, RigidTransform};
use rgm_match::{hard_match, Correspondences, MatchConfig};

use crate::method::MethodError;
use crate::network::{Mode, Rgm, RgmCache};

/// Test-time settings; the defaults are the paper's.
#[derive(Clone, Debug, PartialEq)]
pub struct PipelineConfig {
    /// Passes of network → matching → Kabsch, each on the source moved by the passes before
    /// (2 in the paper's tables).
    pub passes: usize,
    /// Keep only correspondences found both from (X, Y) and from (Y, X) (on in the reference).
    pub cycle_consistency: bool,
    /// Rows and columns of C̃ whose sums exceed this are inliers (0.5).
    pub inlier_threshold: f64,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            passes: 2,
            cycle_consistency: true,
            inlier_threshold: 0.5,
        }
    }
}

/// The RGM network (f32) with its test-time settings and reusable buffers.
#[derive(Clone, Debug)]
pub struct RgmRegistrar {
    /// The network, in evaluation mode at test time.
    pub network: Rgm<f32>,
    /// Passes, cycle consistency, inlier threshold.
    pub config: PipelineConfig,
    forward: RgmCache<f32>, // (X, Y) pass
    reverse: RgmCache<f32>, // (Y, X) pass
}

/// A cloud as the network's (N, 3) f32 input.
fn as_rows(cloud: &PointCloud) -> Array2<f32> {
    Array2::from_shape_fn((cloud.len(), 3), |(i, c)| cloud.points[i][c] as f32) // (N, 3)
}

impl RgmRegistrar {
    /// A registrar around `network`.
    pub fn new(network: Rgm<f32>, config: PipelineConfig) -> Self {
        Self {
            network,
            config,
            forward: RgmCache::default(),
            reverse: RgmCache::default(),
        }
    }

    /// The hard correspondences of one pass on (moved source, target).
    fn correspondences(
        &mut self,
        x: &Array2<f32>,
        y: &Array2<f32>,
    ) -> Result<Correspondences, MethodError> {
        let matching = MatchConfig {
            inlier_threshold: self.config.inlier_threshold,
        };
        self.network
            .forward(x.view(), y.view(), Mode::Eval, &mut self.forward)?;
        let found = hard_match(self.forward.c_soft(), &matching)?;
        if !self.config.cycle_consistency {
            return Ok(found);
        }
        self.network
            .forward(y.view(), x.view(), Mode::Eval, &mut self.reverse)?;
        let reverse = hard_match(self.reverse.c_soft(), &matching)?;
        Ok(found.cycle_consistent(&reverse)?)
    }

    /// The transform that maps `source` onto `target`: the composition of every pass's
    /// Kabsch solution. `inlier_count` is the number of correspondences of the last pass, and
    /// `inlier_rmse` their distance after the final transform.
    pub fn register(
        &mut self,
        source: &PointCloud,
        target: &PointCloud,
    ) -> Result<RegistrationResult, MethodError> {
        let y = as_rows(target); // (M, 3)
        let mut total = RigidTransform::identity();
        let mut used: Vec<(usize, usize)> = Vec::new();
        for pass in 0..self.config.passes {
            let moved = source.transformed(&total);
            let found = self.correspondences(&as_rows(&moved), &y)?;
            if found.pairs().is_empty() {
                return Err(MethodError::NoCorrespondences { pass: pass + 1 });
            }
            let src: Vec<Point3<f64>> = found
                .pairs()
                .iter()
                .map(|&(i, _)| moved.points[i])
                .collect();
            let tgt: Vec<Point3<f64>> = found
                .pairs()
                .iter()
                .map(|&(_, j)| target.points[j])
                .collect();
            let step = kabsch(&src, &tgt, &vec![1.0; src.len()])?;
            total = step.compose(&total);
            used = found.pairs().to_vec();
        }
        let sum_d2: f64 = used
            .iter()
            .map(|&(i, j)| (total.apply(&source.points[i]) - target.points[j]).norm_squared())
            .sum();
        Ok(RegistrationResult {
            t_target_source: total,
            iterations: self.config.passes,
            converged: true,
            inlier_count: used.len(),
            fitness: used.len() as f64 / source.len().max(1) as f64,
            inlier_rmse: if used.is_empty() {
                0.0
            } else {
                (sum_d2 / used.len() as f64).sqrt()
            },
        })
    }
}
