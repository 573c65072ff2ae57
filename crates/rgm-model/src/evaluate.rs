//! Running a method over the benchmark's test pairs and scoring it (spec §5).

use std::time::Instant;

use rgm_data::Pair;
use rgm_geom::metrics::{MetricsSummary, PairMetrics};
use rgm_geom::RigidTransform;

use crate::Method;

/// One test pair's outcome.
#[derive(Clone, Debug)]
pub struct PairRecord {
    /// Index of the pair in the test split (its RNG seed).
    pub index: usize,
    /// The predicted `t_target_source` (the identity when the method failed).
    pub transform: RigidTransform,
    /// The ground-truth `t_target_source`.
    pub ground_truth: RigidTransform,
    /// The method's own time, in milliseconds.
    pub time_ms: f64,
    /// Correspondences (inliers) the method used.
    pub correspondences: usize,
    /// The paper's metrics of `transform`.
    pub metrics: PairMetrics,
    /// Why the method failed on this pair, if it did; the pair is then scored as the identity.
    pub failure: Option<String>,
}

impl PairRecord {
    /// The record of `transform` (found in `time_ms`) on `pair`.
    pub fn score(
        index: usize,
        pair: &Pair,
        transform: RigidTransform,
        time_ms: f64,
        correspondences: usize,
        failure: Option<String>,
    ) -> rgm_geom::Result<Self> {
        let metrics = PairMetrics::compute(
            &transform,
            &pair.t_target_source,
            &pair.source,
            &pair.target,
        )?;
        Ok(Self {
            index,
            transform,
            ground_truth: pair.t_target_source,
            time_ms,
            correspondences,
            metrics,
            failure,
        })
    }
}

/// Runs `method` on test pair `index` and scores it. A method error is recorded as a failure
/// scored as the identity transform, not returned: one bad pair must not stop an evaluation.
pub fn evaluate_pair(
    method: &mut Method,
    index: usize,
    pair: &Pair,
) -> rgm_geom::Result<PairRecord> {
    let start = Instant::now();
    match method.register(&pair.source, &pair.target) {
        Ok(reg) => PairRecord::score(
            index,
            pair,
            reg.result.t_target_source,
            reg.time_ms,
            reg.result.inlier_count,
            None,
        ),
        Err(err) => {
            let time_ms = start.elapsed().as_secs_f64() * 1e3;
            PairRecord::score(
                index,
                pair,
                RigidTransform::identity(),
                time_ms,
                0,
                Some(err.to_string()),
            )
        }
    }
}

/// Means over an evaluation, as the paper's tables report them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Summary {
    /// The metrics averaged over the pairs (recall as a fraction).
    pub metrics: MetricsSummary,
    /// Pairs on which the method failed (scored as the identity).
    pub failures: usize,
    /// Mean time per pair, in milliseconds.
    pub time_ms: f64,
}

impl Summary {
    /// The summary of `records`; an error when there is none.
    pub fn from_records(records: &[PairRecord]) -> rgm_geom::Result<Self> {
        let metrics: Vec<PairMetrics> = records.iter().map(|r| r.metrics).collect();
        let metrics = MetricsSummary::from_pairs(&metrics)?;
        let failures = records.iter().filter(|r| r.failure.is_some()).count();
        let time_ms = records.iter().map(|r| r.time_ms).sum::<f64>() / records.len() as f64;
        Ok(Self {
            metrics,
            failures,
            time_ms,
        })
    }
}
