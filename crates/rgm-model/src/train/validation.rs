//! The validation after every epoch: loss and matching accuracy of C̃, and the test-time
//! procedure's metrics alone and refined ([`Validation`]), on pairs seeded like test pairs.

use rand::rngs::StdRng;
use rand::SeedableRng;
use rayon::prelude::*;
use rgm_data::{Pair, PairGenerator, Shape};
use rgm_geom::metrics::PairMetrics;
use rgm_geom::RigidTransform;
use rgm_match::bce_forward;
use rgm_nn::Scalar;
use rgm_registration::compose::Normalised;
use rgm_registration::methods::refine::{refine, RefineConfig};
use serde::{Deserialize, Serialize};

use super::config::{BestBy, ValSample};
use super::trainer::{ground_truth, Trainer};
use super::Result;
use crate::evaluate::{evaluate_pair, PairRecord, Summary};
use crate::method::Method;
use crate::network::Mode;
use crate::policy::TUNED;
use crate::procedure::{as_rows, ProcedureConfig, RgmRegistrar};

/// The validation result of one epoch.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Validation {
    pub epoch: usize,
    pub pairs: usize,
    /// The shapes validated on ([`ValSample::First`] in records written before the field).
    #[serde(default)]
    pub sample: ValSample,
    /// Mean BCE per pair (spec §3), network in evaluation mode.
    pub loss: f64,
    /// Fraction of ground-truth matched source points whose largest entry of C̃ is their match.
    pub match_accuracy: f64,
    pub mie_r_deg: f64,
    pub mie_t: f64,
    pub mae_r_deg: f64,
    pub mae_t: f64,
    /// Fraction of pairs registered (spec §5: MAE(R) < 1° and MAE(t) < 0.1).
    pub recall: f64,
    /// Fraction registered once `refined_with` refines the procedure's transform on the full
    /// pair (what `--refine` does); 0 in logs that lack the field.
    #[serde(default)]
    pub recall_refined: f64,
    /// The refinement behind `recall_refined`.
    #[serde(default)]
    pub refined_with: Refinement,
    /// Pairs on which the test-time procedure found no correspondences.
    pub failures: usize,
}

/// The refinements `recall_refined` has been measured with, so that logs stay readable after
/// `--refine` changed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Refinement {
    /// Point-to-point ICP (0.1, 30 iterations): what logs without the field measured.
    #[default]
    PointToPointIcp,
    /// [`rgm_registration::methods::refine`]'s trimmed point-to-plane ICP stages alone, coarse to fine.
    TrimmedPointToPlane,
    /// [`rgm_registration::methods::refine`] with its defaults: the point-to-plane stages, then point-to-point
    /// ICP stages (what validation measures).
    PlaneThenPoint,
}

impl Validation {
    /// Whether `self` beats `other` by `by`'s figure: by [`BestBy::Refined`], higher recall
    /// after refinement, then higher recall, then lower loss, recall after refinement counting
    /// only when both were refined alike (a new refinement must not make a newer checkpoint
    /// look better); by [`BestBy::Alone`], higher recall, then lower loss. A validation on
    /// another sample of shapes than `other`'s always beats it: the two are not comparable, and
    /// `self` is on the sample the run validates on now.
    pub(super) fn beats(&self, other: &Self, by: BestBy) -> bool {
        if self.sample != other.sample {
            return true;
        }
        let refined = |v: &Self| match by {
            BestBy::Refined if self.refined_with == other.refined_with => v.recall_refined,
            _ => 0.0,
        };
        (refined(self), self.recall, -self.loss) > (refined(other), other.recall, -other.loss)
    }
}

/// Whether the refinement (default settings) from `transform` registers `pair` (spec §5's
/// recall).
pub(super) fn refined_recall(pair: &Pair, transform: &RigidTransform) -> Result<bool> {
    let config = RefineConfig::default();
    let found = refine(&pair.source, &pair.target, transform, &config)?.t_target_source;
    let metrics = PairMetrics::compute(&found, &pair.t_target_source, &pair.source, &pair.target)?;
    Ok(metrics.recall)
}

/// One worker's share of a validation: its pairs' records, summed loss, the ground-truth
/// matches of its pairs (`matched`) of which C̃'s row maximum found the partner (`hits`), and
/// the pairs registered after ICP refinement (`refined`).
#[derive(Default)]
struct ValidationPart {
    records: Vec<PairRecord>,
    loss_sum: f64,
    hits: usize,
    matched: usize,
    refined: usize,
}

impl Trainer {
    /// Validation of `epoch` on the pairs of `shapes` (seeded like test pairs): loss and
    /// matching accuracy of C̃, and the test-time procedure's metrics.
    pub(super) fn validate(
        &mut self,
        generator: &PairGenerator,
        shapes: &[&Shape],
        epoch: usize,
    ) -> Result<Validation> {
        let total = shapes.len();
        let workers = self.workers.len();
        let match_points = self.config.match_points;
        let test_statistics = self.config.test_statistics;
        let precision = self.config.precision;
        let parts: Vec<Result<ValidationPart>> = self
            .workers
            .par_iter_mut()
            .enumerate()
            .map(|(w, worker)| {
                worker.network.featurer.test_statistics = test_statistics;
                let mut method = Method::new(Normalised::new(
                    RgmRegistrar::new(
                        worker.network.clone(),
                        ProcedureConfig {
                            precision,
                            ..ProcedureConfig::default()
                        },
                    ),
                    TUNED.frame,
                ));
                let mut part = ValidationPart::default();
                for i in (w..total).step_by(workers) {
                    let full = generator.test_pair(shapes, i)?;
                    let pair = match match_points {
                        Some(points) => {
                            full.subsampled(points, &mut StdRng::seed_from_u64(!(i as u64)))
                        }
                        None => full.clone(),
                    };
                    let gt = ground_truth(&pair)?;
                    let (x, y) = (as_rows(&pair.source), as_rows(&pair.target));
                    worker
                        .network
                        .forward(x.view(), y.view(), Mode::Eval, &mut worker.cache)?;
                    let c = worker.cache.c_soft();
                    part.loss_sum += bce_forward(c, &gt)?.to_f64();
                    part.hits += gt
                        .pairs()
                        .iter()
                        .filter(|&&(i, j)| {
                            let row = c.row(i);
                            let best = row.iter().enumerate().fold(
                                (0, f32::NEG_INFINITY),
                                |a, (k, &v)| if v > a.1 { (k, v) } else { a },
                            );
                            best.0 == j
                        })
                        .count();
                    part.matched += gt.pairs().len();
                    let record = evaluate_pair(&mut method, i, &pair)?;
                    if record.failure.is_none() {
                        part.refined += refined_recall(&full, &record.transform)? as usize;
                    }
                    part.records.push(record);
                }
                Ok(part)
            })
            .collect();
        let mut all = ValidationPart::default();
        for part in parts {
            let part = part?;
            all.records.extend(part.records);
            all.loss_sum += part.loss_sum;
            all.hits += part.hits;
            all.matched += part.matched;
            all.refined += part.refined;
        }
        let summary = Summary::from_records(&all.records)?;
        let (loss, hits, matched) = (all.loss_sum / total as f64, all.hits, all.matched);
        let m = summary.metrics;
        Ok(Validation {
            epoch,
            pairs: total,
            sample: self.config.val_sample,
            loss,
            match_accuracy: hits as f64 / matched.max(1) as f64,
            mie_r_deg: m.mie_r_deg,
            mie_t: m.mie_t,
            mae_r_deg: m.mae_r_deg,
            mae_t: m.mae_t,
            recall: m.recall,
            recall_refined: all.refined as f64 / total as f64,
            refined_with: Refinement::PlaneThenPoint,
            failures: summary.failures,
        })
    }
}
