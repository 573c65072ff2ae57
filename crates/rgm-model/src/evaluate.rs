//! Running a method over the benchmark's test pairs and scoring it (spec §5): one pair
//! ([`evaluate_pair`]), many kept in a per-pair file that a later run resumes ([`Resumable`]),
//! their means ([`Summary`]) and the tables' rows.

use std::time::Instant;

use rgm_data::scenes::{MAX_ROTATION_ERROR_DEG, MAX_TRANSLATION_ERROR};
use rgm_data::{Pair, ScanPair, ScenePair, Turn};
use rgm_geom::metrics::{MetricsSummary, PairMetrics};
use rgm_geom::RigidTransform;
use rgm_registration::Prepared;
use serde::Serialize;

use rgm_registration::compose::Normalised;
use rgm_registration::refiner::Refiner;
use rgm_registration::Registrar;

use crate::policy::TUNED;
use crate::Method;

mod resumable;

pub use resumable::{EvaluateError, Resumable, TestPairs};

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

    /// This record's transform refined by `refiner` as `rgm+refine` composes it
    /// (`Normalised<Refined<RgmRegistrar>>`: in the network's frame), scored: the record
    /// `rgm eval --refine` would give, without running the network again (its correspondences
    /// the refinement's inliers). Its time adds the refinement's to this record's. A failed
    /// record stays as it is; a failed refinement is recorded as a failure (the identity), as
    /// the pipeline reports it.
    pub fn refined(&self, pair: &Pair, refiner: &impl Refiner) -> rgm_geom::Result<Self> {
        if self.failure.is_some() {
            return Ok(self.clone());
        }
        let start = Instant::now();
        let refined = Normalised::new(refiner, TUNED.frame).refine(
            &Prepared::new(&pair.source),
            &Prepared::new(&pair.target),
            &self.transform,
        );
        let time_ms = self.time_ms + start.elapsed().as_secs_f64() * 1e3;
        let (transform, correspondences, failure) = match refined {
            Ok(r) => (r.result.t_target_source, r.result.inlier_count, None),
            Err(e) => (
                RigidTransform::identity(),
                self.correspondences,
                Some(e.to_string()),
            ),
        };
        Self::score(
            self.index,
            pair,
            transform,
            time_ms,
            correspondences,
            failure,
        )
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

/// One real-scan pair's outcome ([`rgm_data::scans`]).
#[derive(Clone, Debug, Serialize)]
pub struct ScanRecord {
    /// The pair's number in its folder.
    pub index: usize,
    /// The scans' file names.
    pub source: String,
    pub target: String,
    /// The predicted `t_target_source` as 4×4 rows (the identity when the method failed).
    pub transform: [[f64; 4]; 4],
    /// Rotation error, degrees ([`ScanPair::errors`]).
    pub rotation_error_deg: f64,
    /// Translation error at the source's centroid, a share of the object's diagonal.
    pub translation_error: f64,
    /// Whether the method trusts its result (it reports no doubt; a tool that reports none,
    /// scored by `rgm score`, trusts every result).
    pub registered: bool,
    /// The method's own time, in milliseconds.
    pub time_ms: f64,
    /// Why the method failed, if it did.
    pub failure: Option<String>,
}

impl ScanRecord {
    /// The record of `transform` (found in `time_ms`, trusted or not: `registered`) on `pair`.
    pub fn score(
        pair: &ScanPair,
        transform: &RigidTransform,
        registered: bool,
        time_ms: f64,
        failure: Option<String>,
    ) -> Self {
        let (rotation_error_deg, translation_error) = pair.errors(transform);
        Self {
            index: pair.index,
            source: pair.source_name.clone(),
            target: pair.target_name.clone(),
            transform: transform.to_rows(),
            rotation_error_deg,
            translation_error,
            registered,
            time_ms,
            failure,
        }
    }

    /// Whether the rotation error is below `degrees` and the translation error below `share`
    /// of the object's diagonal.
    pub fn succeeds(&self, degrees: f64, share: f64) -> bool {
        self.rotation_error_deg < degrees && self.translation_error < share
    }
}

/// Runs `method` on a real-scan pair and scores it; a method error is a failure scored as the
/// identity.
pub fn evaluate_scan_pair(method: &mut Method, pair: &ScanPair) -> ScanRecord {
    let start = Instant::now();
    match method.register(&pair.source, &pair.target) {
        Ok(reg) => ScanRecord::score(
            pair,
            &reg.result.t_target_source,
            reg.doubt.is_none(),
            reg.time_ms,
            None,
        ),
        Err(err) => ScanRecord::score(
            pair,
            &RigidTransform::identity(),
            false,
            start.elapsed().as_secs_f64() * 1e3,
            Some(err.to_string()),
        ),
    }
}

/// The success thresholds of the real-scan benchmark: (degrees, share of the diagonal).
pub const SCAN_SUCCESS: [(f64, f64); 2] = [(2.0, 0.01), (1.0, 0.005)];

/// The real-scan table's header: pairs, successes at [`SCAN_SUCCESS`], the results the method
/// trusted that miss the looser of them, median errors, time.
pub fn scan_table_header() -> String {
    format!(
        "| {:<12} | {:<14} | {:>5} | {:>10} | {:>10} | {:>14} | {:>9} | {:>10} | {:>9} |\n|{}|",
        "method",
        "scans",
        "pairs",
        "2° / 1 %",
        "1° / 0.5 %",
        "wrong, trusted",
        "median R°",
        "median t %",
        "ms/pair",
        ["-"; 9].map(|_| "---").join("|")
    )
}

/// One row of the real-scan table for `records`; `None` when there is none.
pub fn scan_table_row(method: &str, scans: &str, records: &[ScanRecord]) -> Option<String> {
    if records.is_empty() {
        return None;
    }
    let successes = SCAN_SUCCESS.map(|(degrees, share)| {
        let k = records
            .iter()
            .filter(|r| r.succeeds(degrees, share))
            .count();
        format!("{k} / {}", records.len())
    });
    let (degrees, share) = SCAN_SUCCESS[0];
    let wrong_trusted = records
        .iter()
        .filter(|r| r.registered && !r.succeeds(degrees, share))
        .count();
    let time_ms = records.iter().map(|r| r.time_ms).sum::<f64>() / records.len() as f64;
    Some(format!(
        "| {:<12} | {:<14} | {:>5} | {:>10} | {:>10} | {:>14} | {:>9.3} | {:>10.3} | {:>9.1} |",
        method,
        scans,
        records.len(),
        successes[0],
        successes[1],
        format!("{wrong_trusted} / {}", records.len()),
        median(records.iter().map(|r| r.rotation_error_deg)),
        100.0 * median(records.iter().map(|r| r.translation_error)),
        time_ms
    ))
}

/// The median of `values` (the mean of the middle two of an even count); NaN when empty.
fn median(values: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => (v[n / 2 - 1] + v[n / 2]) / 2.0,
    }
}

/// One scene pair's outcome ([`rgm_data::scenes`]), its source turned or not.
#[derive(Clone, Debug, Serialize)]
pub struct SceneRecord {
    /// The pair's number in its folder's `gt.log`.
    pub index: usize,
    /// The fragments' file names.
    pub source: String,
    pub target: String,
    /// The known turn of the source, as `--turns` spells it (`None`: as published).
    pub turn: Option<String>,
    /// The predicted `t_target_source` as 4×4 rows (the identity when the method failed).
    pub transform: [[f64; 4]; 4],
    /// Rotation error, degrees, and translation error, metres
    /// ([`rgm_data::scenes::LoadedScenePair::errors`]).
    pub rotation_error_deg: f64,
    pub translation_error_m: f64,
    /// Whether the method trusts its result (it reports no doubt).
    pub registered: bool,
    /// The method's own time, in milliseconds.
    pub time_ms: f64,
    /// Why the method failed (or the pair could not be read), if it did.
    pub failure: Option<String>,
}

impl SceneRecord {
    /// Whether the result meets the 3DMatch criterion.
    pub fn succeeds(&self) -> bool {
        self.rotation_error_deg < MAX_ROTATION_ERROR_DEG
            && self.translation_error_m < MAX_TRANSLATION_ERROR
    }
}

/// Reads `pair` (its source turned by `turn`), runs `method` on it and scores it; a method
/// error is a failure scored as the identity. A pair that cannot be read is a failed row with
/// no result (infinite errors, `null` in JSON), so that one bad fragment costs its own pairs,
/// not the run.
pub fn evaluate_scene_pair(
    method: &mut Method,
    pair: &ScenePair,
    turn: Option<&Turn>,
) -> (SceneRecord, Vec<rgm_data::Warning>) {
    let (source, target) = pair.names();
    let mut record = SceneRecord {
        index: pair.index,
        source,
        target,
        turn: turn.map(|t| t.to_string()),
        transform: RigidTransform::identity().to_rows(),
        rotation_error_deg: f64::INFINITY,
        translation_error_m: f64::INFINITY,
        registered: false,
        time_ms: 0.0,
        failure: None,
    };
    let loaded = match pair.load(turn) {
        Ok(loaded) => loaded,
        Err(err) => {
            record.failure = Some(format!("reading the pair: {err}"));
            return (record, Vec::new());
        }
    };
    let start = Instant::now();
    let found = match method.register(&loaded.source, &loaded.target) {
        Ok(reg) => {
            record.registered = reg.doubt.is_none();
            record.time_ms = reg.time_ms;
            reg.result.t_target_source
        }
        Err(err) => {
            record.time_ms = start.elapsed().as_secs_f64() * 1e3;
            record.failure = Some(err.to_string());
            RigidTransform::identity()
        }
    };
    (record.rotation_error_deg, record.translation_error_m) = loaded.errors(&found);
    record.transform = found.to_rows();
    (record, loaded.warnings)
}

/// The scene table's header: pairs, successes by the 3DMatch criterion, the results the
/// method trusted that are wrong, median errors, time.
pub fn scene_table_header() -> String {
    format!(
        "| {:<12} | {:<14} | {:>5} | {:>11} | {:>13} | {:>9} | {:>12} | {:>9} |\n|{}|",
        "method",
        "scenes",
        "pairs",
        "15° / 0.3 m",
        "wrong, trusted",
        "median R°",
        "median t (m)",
        "ms/pair",
        ["-"; 8].map(|_| "---").join("|")
    )
}

/// One row of the scene table for `records`; `None` when there is none.
pub fn scene_table_row(method: &str, scenes: &str, records: &[SceneRecord]) -> Option<String> {
    if records.is_empty() {
        return None;
    }
    let n = records.len();
    let right = records.iter().filter(|r| r.succeeds()).count();
    let wrong_trusted = records
        .iter()
        .filter(|r| r.registered && !r.succeeds())
        .count();
    let time_ms = records.iter().map(|r| r.time_ms).sum::<f64>() / n as f64;
    Some(format!(
        "| {:<12} | {:<14} | {:>5} | {:>11} | {:>13} | {:>9.2} | {:>12.3} | {:>9.1} |",
        method,
        scenes,
        n,
        format!("{right} / {n}"),
        format!("{wrong_trusted} / {n}"),
        median(records.iter().map(|r| r.rotation_error_deg)),
        median(records.iter().map(|r| r.translation_error_m)),
        time_ms
    ))
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

/// The header and rule of the metrics table, a Markdown table (spec §5 columns, paper order):
/// what `rgm eval` prints and `cargo xtask reproduce-tables` writes.
pub fn table_header() -> String {
    format!(
        "| {:<12} | {:<8} | {:>5} | {:>8} | {:>8} | {:>8} | {:>8} | {:>8} | {:>7} | {:>9} |\n|{}|",
        "method",
        "setting",
        "pairs",
        "MIE(R)",
        "MIE(t)",
        "MAE(R)",
        "MAE(t)",
        "CCD",
        "recall",
        "ms/pair",
        ["-"; 10].map(|_| "---").join("|")
    )
}

/// One row of the metrics table.
pub fn table_row(method: &str, setting: &str, s: &Summary) -> String {
    format!(
        "| {:<12} | {:<8} | {:>5} | {:>8.4} | {:>8.5} | {:>8.4} | {:>8.5} | {:>8.5} | {:>6.2}% | {:>9.1} |",
        method,
        setting,
        s.metrics.pairs,
        s.metrics.mie_r_deg,
        s.metrics.mie_t,
        s.metrics.mae_r_deg,
        s.metrics.mae_t,
        s.metrics.ccd,
        100.0 * s.metrics.recall,
        s.time_ms
    )
}

/// A [`PairRecord`] as `rgm eval --json` writes it: transforms as 4×4 rows, the metrics
/// flattened.
#[derive(Serialize)]
struct RecordJson {
    index: usize,
    transform: [[f64; 4]; 4],
    ground_truth: [[f64; 4]; 4],
    time_ms: f64,
    correspondences: usize,
    mie_r_deg: f64,
    mie_t: f64,
    mae_r_deg: f64,
    mae_t: f64,
    ccd: f64,
    chamfer: f64,
    recall: bool,
    failure: Option<String>,
}

impl Serialize for PairRecord {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let m = &self.metrics;
        RecordJson {
            index: self.index,
            transform: self.transform.to_rows(),
            ground_truth: self.ground_truth.to_rows(),
            time_ms: self.time_ms,
            correspondences: self.correspondences,
            mie_r_deg: m.mie_r_deg,
            mie_t: m.mie_t,
            mae_r_deg: m.mae_r_deg,
            mae_t: m.mae_t,
            ccd: m.ccd,
            chamfer: m.chamfer,
            recall: m.recall,
            failure: self.failure.clone(),
        }
        .serialize(serializer)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rgm_geom::{MetricsSummary, Vector3};

    pub(super) fn record() -> PairRecord {
        let transform = RigidTransform::new(
            rgm_geom::euler::rotation_xyz_intrinsic(0.3, -0.2, 0.1),
            Vector3::new(0.1, 0.2, -0.3),
        );
        PairRecord {
            index: 7,
            transform,
            ground_truth: transform.inverse(),
            time_ms: 12.5,
            correspondences: 300,
            metrics: PairMetrics {
                mae_r_deg: 1.25,
                mae_t: 0.5,
                mie_r_deg: 2.5,
                mie_t: 0.75,
                ccd: 0.125,
                chamfer: 0.0625,
                recall: false,
            },
            failure: Some("no correspondences".into()),
        }
    }

    #[test]
    fn a_record_is_written_with_the_fields_of_rgm_eval_json() {
        let value = serde_json::to_value(record()).unwrap();
        assert_eq!(value["index"], 7);
        assert_eq!(value["mie_r_deg"], 2.5);
        assert_eq!(value["transform"][0][3], 0.1);
        assert_eq!(
            value["ground_truth"][3],
            serde_json::json!([0.0, 0.0, 0.0, 1.0])
        );
        assert_eq!(value["correspondences"], 300);
        assert_eq!(value["failure"], "no correspondences");
    }

    #[test]
    fn a_scan_row_counts_successes_and_trusted_failures_and_takes_medians() {
        let record = |rotation_error_deg: f64, translation_error: f64, registered| ScanRecord {
            index: 0,
            source: "a.ply".into(),
            target: "b.ply".into(),
            transform: RigidTransform::identity().to_rows(),
            rotation_error_deg,
            translation_error,
            registered,
            time_ms: 100.0,
            failure: None,
        };
        // Successes at 2° / 1 %: the first three; at 1° / 0.5 %: the first two. Wrong and
        // trusted: the fourth (the fifth is wrong and doubted).
        let records = [
            record(0.2, 0.001, true),
            record(0.9, 0.004, true),
            record(1.5, 0.002, false),
            record(0.5, 0.02, true),
            record(30.0, 0.2, false),
        ];
        assert_eq!(
            scan_table_row("auto+refine", "bunny", &records).unwrap(),
            "| auto+refine  | bunny          |     5 |      3 / 5 |      2 / 5 |          1 / 5 |     0.900 |      0.400 |     100.0 |"
        );
        assert_eq!(scan_table_row("x", "y", &[]), None);
        assert_eq!(scan_table_header().lines().count(), 2);
    }

    #[test]
    fn a_scene_row_counts_successes_and_trusted_failures() {
        let record = |rotation_error_deg: f64, translation_error_m: f64, registered| SceneRecord {
            index: 0,
            source: "cloud_bin_1.ply".into(),
            target: "cloud_bin_0.ply".into(),
            turn: None,
            transform: RigidTransform::identity().to_rows(),
            rotation_error_deg,
            translation_error_m,
            registered,
            time_ms: 1000.0,
            failure: None,
        };
        // Within 15° and 0.3 m: the first two; wrong and trusted: the third (the fourth is
        // doubted).
        let records = [
            record(1.0, 0.05, true),
            record(14.0, 0.2, false),
            record(2.0, 0.94, true),
            record(170.0, 3.0, false),
        ];
        assert_eq!(
            scene_table_row("auto+refine", "redkitchen", &records).unwrap(),
            "| auto+refine  | redkitchen     |     4 |       2 / 4 |         1 / 4 |      8.00 |        0.570 |    1000.0 |"
        );
        assert_eq!(scene_table_row("x", "y", &[]), None);
        assert_eq!(scene_table_header().lines().count(), 2);
    }

    #[test]
    fn a_table_row_prints_the_summary_in_paper_order() {
        let summary = Summary {
            metrics: MetricsSummary {
                pairs: 3,
                mae_r_deg: 1.0,
                mae_t: 0.02,
                mie_r_deg: 2.0,
                mie_t: 0.04,
                ccd: 0.005,
                chamfer: 0.0,
                recall: 2.0 / 3.0,
            },
            failures: 0,
            time_ms: 45.06,
        };
        assert_eq!(
            table_row("fgr", "partial", &summary),
            "| fgr          | partial  |     3 |   2.0000 |  0.04000 |   1.0000 |  0.02000 |  0.00500 |  66.67% |      45.1 |"
        );
        assert_eq!(table_header().lines().count(), 2);
    }
}
