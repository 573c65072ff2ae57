//! Resumable evaluation: a method's records on a set of test pairs kept in a per-pair file (one
//! JSON object per line, the fields of [`PairRecord`]), appended chunk by chunk as the pairs
//! are computed, so that an evaluation stopped at its deadline, or killed, carries on where it
//! stopped: a later one reads the file back and computes only the pairs missing there.

use std::collections::HashSet;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use rgm_data::{Pair, PairGenerator, Shape};
use rgm_geom::refine::RefineConfig;

use super::{evaluate_pair, PairRecord};
use crate::Method;

/// Why a resumable evaluation stopped. A method's failure on a pair is a record, not an error.
#[derive(Debug, thiserror::Error)]
pub enum EvaluateError {
    /// The per-pair file could not be read or written.
    #[error("{}: {error}", path.display())]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    /// A line of the per-pair file is not a record.
    #[error("{} line {line}: {error}", path.display())]
    Record {
        path: PathBuf,
        line: usize,
        error: serde_json::Error,
    },
    /// A test pair could not be made.
    #[error(transparent)]
    Data(#[from] rgm_data::DataError),
    /// A transform could not be scored.
    #[error(transparent)]
    Geom(#[from] rgm_geom::GeomError),
}

/// What a resumable evaluation reports while it computes (the commands show a progress bar).
pub trait Progress: Sync {
    /// Computing starts: `done` of the `total` pairs were read back from the file. Not called
    /// when none is missing.
    fn start(&self, total: usize, done: usize);
    /// One more pair is finished (called from the workers).
    fn advance(&self);
    /// Computing ends; `complete` is false when the deadline came before the last pair.
    fn finish(&self, complete: bool);
}

/// No report.
impl Progress for () {
    fn start(&self, _: usize, _: usize) {}
    fn advance(&self) {}
    fn finish(&self, _: bool) {}
}

/// The test pairs of one protocol: pair `i` is made from `shapes` by `generator`, seeded from
/// `i` (spec §1).
#[derive(Clone, Copy)]
pub struct TestPairs<'a> {
    pub generator: &'a PairGenerator,
    pub shapes: &'a [&'a Shape],
}

impl TestPairs<'_> {
    /// Test pair `i`.
    pub fn pair(&self, i: usize) -> rgm_data::Result<Pair> {
        self.generator.test_pair(self.shapes, i)
    }

    /// How many pairs there are (one per shape).
    pub fn len(&self) -> usize {
        self.shapes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.shapes.is_empty()
    }
}

/// How a resumable evaluation runs: its workers, each with its own copy of the method, and
/// when it stops starting new work.
pub struct Resumable {
    pub pool: rayon::ThreadPool,
    /// No chunk of pairs starts after this instant; the records then cover fewer pairs than
    /// asked for, and a later evaluation carries on from there.
    pub deadline: Option<Instant>,
}

impl Resumable {
    /// Every pair of `pairs` evaluated with `method` ([`evaluate_pair`]), sorted by pair
    /// index, kept in the per-pair file `path`.
    pub fn evaluate(
        &self,
        path: &Path,
        method: &Method,
        pairs: TestPairs,
        progress: &dyn Progress,
    ) -> Result<Vec<PairRecord>, EvaluateError> {
        let indices: Vec<usize> = (0..pairs.len()).collect();
        self.records(
            path,
            &indices,
            progress,
            || method.clone(),
            |method, i| Ok(evaluate_pair(method, i, &pairs.pair(i)?)?),
        )
    }

    /// The records of `plain` refined as `rgm eval --refine` refines them
    /// ([`PairRecord::refined`]: the network is not run again), for the pairs `plain` has,
    /// kept in the per-pair file `path`.
    pub fn refine(
        &self,
        path: &Path,
        plain: &[PairRecord],
        config: &RefineConfig,
        pairs: TestPairs,
        progress: &dyn Progress,
    ) -> Result<Vec<PairRecord>, EvaluateError> {
        let mut plain: Vec<&PairRecord> = plain.iter().collect();
        plain.sort_by_key(|r| r.index);
        let indices: Vec<usize> = plain.iter().map(|r| r.index).collect();
        self.records(
            path,
            &indices,
            progress,
            || (),
            |(), i| {
                let start = plain[indices.binary_search(&i).expect("an index of plain")];
                Ok(start.refined(&pairs.pair(i)?, config)?)
            },
        )
    }

    /// The records of the pairs `indices` (sorted) in the per-pair file `path`, sorted by pair
    /// index: those already there read back, the others made by `compute` (with a state per
    /// worker from `init`) in parallel chunks appended as they finish. Fewer when the deadline
    /// came first.
    fn records<S>(
        &self,
        path: &Path,
        indices: &[usize],
        progress: &dyn Progress,
        init: impl Fn() -> S + Sync + Send,
        compute: impl Fn(&mut S, usize) -> Result<PairRecord, EvaluateError> + Sync + Send,
    ) -> Result<Vec<PairRecord>, EvaluateError> {
        let mut records = read_records(path)?;
        records.retain(|r| indices.binary_search(&r.index).is_ok());
        let done: HashSet<usize> = records.iter().map(|r| r.index).collect();
        let missing: Vec<usize> = indices
            .iter()
            .copied()
            .filter(|i| !done.contains(i))
            .collect();
        if !missing.is_empty() {
            let io = |error| EvaluateError::Io {
                path: path.to_path_buf(),
                error,
            };
            if let Some(folder) = path.parent() {
                fs::create_dir_all(folder).map_err(io)?;
            }
            let mut file = fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(path)
                .map_err(io)?;
            progress.start(indices.len(), records.len());
            // Chunks several times the workers long keep them all busy between two appends.
            let chunk = 4 * self.pool.current_num_threads();
            let mut complete = true;
            for indices in missing.chunks(chunk) {
                if self.deadline.is_some_and(|d| Instant::now() >= d) {
                    complete = false;
                    break;
                }
                let found: Vec<PairRecord> = self.pool.install(|| {
                    indices
                        .par_iter()
                        .map_init(&init, |state, &i| {
                            let record = compute(state, i);
                            progress.advance();
                            record
                        })
                        .collect::<Result<_, _>>()
                })?;
                let mut lines = String::new();
                for record in &found {
                    lines += &serde_json::to_string(record).expect("a record serialises");
                    lines.push('\n');
                }
                file.write_all(lines.as_bytes()).map_err(io)?;
                records.extend(found);
            }
            progress.finish(complete);
        }
        records.sort_by_key(|r| r.index);
        Ok(records)
    }
}

/// The records of a per-pair file (one JSON object per line, blank lines skipped), in the
/// file's order; none when the file does not exist.
pub fn read_records(path: &Path) -> Result<Vec<PairRecord>, EvaluateError> {
    let text = match fs::read_to_string(path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(error) => {
            return Err(EvaluateError::Io {
                path: path.to_path_buf(),
                error,
            })
        }
    };
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(n, line)| {
            serde_json::from_str(line).map_err(|error| EvaluateError::Record {
                path: path.to_path_buf(),
                line: n + 1,
                error,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;

    use rgm_data::Setting;

    use super::*;
    use crate::{MethodName, MethodOptions};

    /// Counts what a [`Progress`] is told.
    #[derive(Default)]
    struct Counted {
        started: Mutex<Vec<(usize, usize)>>,
        advanced: AtomicUsize,
        finished: Mutex<Vec<bool>>,
    }

    impl Progress for Counted {
        fn start(&self, total: usize, done: usize) {
            self.started.lock().unwrap().push((total, done));
        }
        fn advance(&self) {
            self.advanced.fetch_add(1, Ordering::Relaxed);
        }
        fn finish(&self, complete: bool) {
            self.finished.lock().unwrap().push(complete);
        }
    }

    /// A shape of 256 points on a wavy sphere (no symmetry ICP could settle on).
    fn shape(k: usize) -> Shape {
        let points = (0..256)
            .map(|i| {
                let (t, p) = (i as f32 * 0.7 + k as f32, i as f32 * 0.31);
                let r = 1.0 + 0.3 * (3.0 * t).sin() * p.cos();
                [r * t.sin() * p.cos(), r * t.sin() * p.sin(), r * t.cos()]
            })
            .collect();
        Shape {
            name: format!("wavy_{k}"),
            label: 0,
            points,
        }
    }

    fn run(deadline: Option<Instant>) -> Resumable {
        Resumable {
            pool: rayon::ThreadPoolBuilder::new()
                .num_threads(2)
                .build()
                .unwrap(),
            deadline,
        }
    }

    /// ICP, the cheapest method: what these tests run.
    fn icp() -> Method {
        MethodOptions {
            method: MethodName::Icp,
            ..MethodOptions::default()
        }
        .build()
        .unwrap()
    }

    fn temp_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("rgm-resumable-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn a_resumed_evaluation_computes_only_the_missing_pairs_and_equals_a_whole_one() {
        let dir = temp_dir("resume");
        let path = dir.join("results/clean/icp.jsonl");
        let shapes: Vec<Shape> = (0..3).map(shape).collect();
        let shapes: Vec<&Shape> = shapes.iter().collect();
        let generator = PairGenerator::new(Setting::Clean);
        let pairs = TestPairs {
            generator: &generator,
            shapes: &shapes,
        };
        let method = icp();
        let whole = Counted::default();
        let all = run(None).evaluate(&path, &method, pairs, &whole).unwrap();
        assert_eq!(all.iter().map(|r| r.index).collect::<Vec<_>>(), [0, 1, 2]);
        assert_eq!(*whole.started.lock().unwrap(), [(3, 0)]);
        assert_eq!(whole.advanced.load(Ordering::Relaxed), 3);
        assert_eq!(*whole.finished.lock().unwrap(), [true]);

        // Keep the file's pair 1 only: a resumed evaluation computes pairs 0 and 2 again.
        let text = fs::read_to_string(&path).unwrap();
        let kept: String = text
            .lines()
            .filter(|l| l.starts_with("{\"index\":1,"))
            .map(|l| format!("{l}\n"))
            .collect();
        assert_eq!(kept.lines().count(), 1, "{text}");
        fs::write(&path, kept).unwrap();
        let resumed = Counted::default();
        let again = run(None).evaluate(&path, &method, pairs, &resumed).unwrap();
        assert_eq!(*resumed.started.lock().unwrap(), [(3, 1)]);
        assert_eq!(resumed.advanced.load(Ordering::Relaxed), 2);
        assert_eq!(read_records(&path).unwrap().len(), 3);
        for (a, b) in all.iter().zip(&again) {
            assert_eq!(a.index, b.index);
            assert_eq!(a.transform.to_rows(), b.transform.to_rows());
            assert_eq!(a.metrics, b.metrics);
        }

        // Nothing missing: nothing computed, nothing reported.
        let idle = Counted::default();
        let third = run(None).evaluate(&path, &method, pairs, &idle).unwrap();
        assert_eq!(third.len(), 3);
        assert!(idle.started.lock().unwrap().is_empty());

        // Refined from the records: the refinement's own file, every pair of the records.
        let refined_path = dir.join("results/clean/icp-icp.jsonl");
        let config = RefineConfig::default();
        let refined = run(None)
            .refine(&refined_path, &all[..2], &config, pairs, &())
            .unwrap();
        assert_eq!(refined.iter().map(|r| r.index).collect::<Vec<_>>(), [0, 1]);
        assert!(refined
            .iter()
            .zip(&all)
            .all(|(r, a)| r.time_ms >= a.time_ms));
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_passed_deadline_starts_no_chunk() {
        let dir = temp_dir("deadline");
        let path = dir.join("x.jsonl");
        let shapes = [shape(0)];
        let shapes: Vec<&Shape> = shapes.iter().collect();
        let generator = PairGenerator::new(Setting::Clean);
        let pairs = TestPairs {
            generator: &generator,
            shapes: &shapes,
        };
        let method = icp();
        let progress = Counted::default();
        let records = run(Some(Instant::now()))
            .evaluate(&path, &method, pairs, &progress)
            .unwrap();
        assert!(records.is_empty());
        assert_eq!(*progress.finished.lock().unwrap(), [false]);
        assert_eq!(progress.advanced.load(Ordering::Relaxed), 0);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn per_pair_files_are_read_back_line_by_line() {
        let dir = temp_dir("read");
        fs::create_dir_all(&dir).unwrap();
        let path = dir.join("icp.jsonl");
        assert!(read_records(&path).unwrap().is_empty());
        let mut records = [super::super::tests::record(), super::super::tests::record()];
        records[0].index = 3;
        records[1].index = 1;
        records[1].metrics.recall = true;
        let lines: String = records
            .iter()
            .map(|r| serde_json::to_string(r).unwrap() + "\n")
            .collect();
        fs::write(&path, lines + "\n").unwrap();
        let back = read_records(&path).unwrap();
        fs::write(&path, "\n{\"index\": 1}\n").unwrap();
        let err = read_records(&path).unwrap_err();
        fs::remove_dir_all(&dir).unwrap();
        assert_eq!(back.iter().map(|r| r.index).collect::<Vec<_>>(), [3, 1]);
        assert!(!back[0].metrics.recall && back[1].metrics.recall);
        // The file's own line number, blank lines counted.
        assert!(
            err.to_string().contains("icp.jsonl line 2: missing field"),
            "{err}"
        );
    }
}
