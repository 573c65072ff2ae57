//! Resumable evaluation: a method's records on a set of test pairs kept in a per-pair file, so
//! that an evaluation stopped at its deadline, or killed, carries on where it stopped: a later
//! one reads the file back and computes only the pairs missing there.
//!
//! The file is gzip'd JSON lines, small enough to commit: a [`Header`] naming the inputs the
//! records were made from, then one [`Line`] per pair holding only what the pair cannot give
//! back (the transform, the time, the correspondences, the failure). The ground truth and the
//! metrics are computed again from the regenerated test pair when the file is read. Each
//! finished chunk of pairs is appended as a gzip member of its own, so that a killed run loses
//! at most the chunk it was writing; when the evaluation stops, the file is written again as
//! one member, which compresses far better.

use std::collections::HashSet;
use std::fs;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use flate2::read::MultiGzDecoder;
use flate2::write::GzEncoder;
use flate2::Compression;
use rayon::prelude::*;
use rgm_data::{Pair, PairGenerator, Shape};
use rgm_geom::{Matrix4, RigidTransform};
use rgm_registration::refiner::Refiner;
use serde::{Deserialize, Serialize};

use super::{evaluate_pair, PairRecord};
use crate::progress::Progress;
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
    /// A line of the per-pair file is not a record, or its header not a header.
    #[error("{} line {line}: {error}", path.display())]
    Record {
        path: PathBuf,
        line: usize,
        error: String,
    },
    /// The per-pair file is of a format this code does not read.
    #[error("{}: per-pair file version {version}, this code reads {VERSION}", path.display())]
    Version { path: PathBuf, version: u32 },
    /// A test pair could not be made.
    #[error(transparent)]
    Data(#[from] rgm_data::DataError),
    /// A transform could not be scored.
    #[error(transparent)]
    Geom(#[from] rgm_geom::GeomError),
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
    /// index, kept in the per-pair file `path`. `inputs` names what the records depend on
    /// besides the code (the method's options, its weights): records of the file made from
    /// other inputs are computed again.
    pub fn evaluate(
        &self,
        path: &Path,
        inputs: &str,
        method: &Method,
        pairs: TestPairs,
        progress: &dyn Progress,
    ) -> Result<Vec<PairRecord>, EvaluateError> {
        let indices: Vec<usize> = (0..pairs.len()).collect();
        self.records(
            (path, inputs),
            pairs,
            &indices,
            progress,
            || method.clone(),
            |method, i| Ok(evaluate_pair(method, i, &pairs.pair(i)?)?),
        )
    }

    /// The records of `plain` refined as `rgm eval --refine` refines them
    /// ([`PairRecord::refined`]: the network is not run again), for the pairs `plain` has,
    /// kept in the per-pair file `path` of `inputs` (as in [`Resumable::evaluate`]).
    pub fn refine(
        &self,
        path: &Path,
        inputs: &str,
        plain: &[PairRecord],
        refiner: &impl Refiner,
        pairs: TestPairs,
        progress: &dyn Progress,
    ) -> Result<Vec<PairRecord>, EvaluateError> {
        let mut plain: Vec<&PairRecord> = plain.iter().collect();
        plain.sort_by_key(|r| r.index);
        let indices: Vec<usize> = plain.iter().map(|r| r.index).collect();
        self.records(
            (path, inputs),
            pairs,
            &indices,
            progress,
            || (),
            |(), i| {
                let start = plain[indices.binary_search(&i).expect("an index of plain")];
                Ok(start.refined(&pairs.pair(i)?, refiner)?)
            },
        )
    }

    /// The records of the pairs `indices` (sorted) kept in the per-pair file `path` of
    /// `inputs`, sorted by pair index: those already there read back and scored on their
    /// pairs, the others made by `compute` (with a state per worker from `init`) in parallel
    /// chunks appended as they finish. Fewer when the deadline came first.
    fn records<S>(
        &self,
        (path, inputs): (&Path, &str),
        pairs: TestPairs,
        indices: &[usize],
        progress: &dyn Progress,
        init: impl Fn() -> S + Sync + Send,
        compute: impl Fn(&mut S, usize) -> Result<PairRecord, EvaluateError> + Sync + Send,
    ) -> Result<Vec<PairRecord>, EvaluateError> {
        let file = read_file(path)?;
        let mut lines = match file.inputs {
            Some(found) if found == inputs => file.lines,
            _ => Vec::new(),
        };
        let mut records: Vec<PairRecord> = self.pool.install(|| {
            lines
                .par_iter()
                .filter(|line| indices.binary_search(&line.index).is_ok())
                .map(|line| Ok(line.record(&pairs.pair(line.index)?)?))
                .collect::<Result<_, EvaluateError>>()
        })?;
        let done: HashSet<usize> = lines.iter().map(|l| l.index).collect();
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
            progress.start(indices.len(), records.len());
            // Chunks several times the workers long keep them all busy between two appends.
            let chunk = 4 * self.pool.current_num_threads();
            let mut complete = true;
            let mut computed = false;
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
                let new: Vec<Line> = found.iter().map(Line::of).collect();
                // The first chunk writes the file anew: its header, the lines read back (a
                // cut member dropped, stale records gone), the chunk; later ones append.
                if computed {
                    append(path, &new).map_err(io)?;
                    lines.extend(new);
                } else {
                    lines.extend(new);
                    write_file(path, inputs, &lines).map_err(io)?;
                }
                records.extend(found);
                computed = true;
            }
            if computed {
                lines.sort_by_key(|l| l.index);
                write_file(path, inputs, &lines).map_err(io)?;
            }
            progress.finish(complete);
        }
        records.sort_by_key(|r| r.index);
        Ok(records)
    }
}

/// The format of the per-pair files this code writes and reads.
const VERSION: u32 = 1;

/// The first line of a per-pair file.
#[derive(Serialize, Deserialize)]
struct Header {
    /// [`VERSION`].
    version: u32,
    /// What its records were made from besides the code ([`Resumable::evaluate`]).
    inputs: String,
}

/// A pair's line in a per-pair file: what its [`PairRecord`] holds that the test pair cannot
/// give back.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Line {
    index: usize,
    /// The first three rows (R | t) of the predicted `t_target_source`, at f64's full
    /// precision so that the metrics are computed again bit for bit.
    transform: [[f64; 4]; 3],
    time_ms: f64,
    correspondences: usize,
    failure: Option<String>,
}

impl Line {
    fn of(record: &PairRecord) -> Self {
        let rows = record.transform.to_rows();
        Self {
            index: record.index,
            transform: [rows[0], rows[1], rows[2]],
            time_ms: record.time_ms,
            correspondences: record.correspondences,
            failure: record.failure.clone(),
        }
    }

    fn transform(&self) -> rgm_geom::Result<RigidTransform> {
        let rows = &self.transform;
        let m = Matrix4::from_fn(|i, j| match rows.get(i) {
            Some(row) => row[j],
            None => [0.0, 0.0, 0.0, 1.0][j],
        });
        RigidTransform::from_matrix4(&m, 1e-6)
    }

    /// The record of this line on its test pair `pair`.
    fn record(&self, pair: &Pair) -> rgm_geom::Result<PairRecord> {
        PairRecord::score(
            self.index,
            pair,
            self.transform()?,
            self.time_ms,
            self.correspondences,
            self.failure.clone(),
        )
    }
}

/// A per-pair file as read back.
struct PerPairFile {
    /// The header's inputs; `None` when there is no file or it was cut inside its header.
    inputs: Option<String>,
    lines: Vec<Line>,
}

/// The per-pair file `path`, in the file's order. A run killed while it appended leaves the
/// last gzip member cut: the lines before the cut are kept, and the next chunk computed writes
/// the file anew.
fn read_file(path: &Path) -> Result<PerPairFile, EvaluateError> {
    let io = |error| EvaluateError::Io {
        path: path.to_path_buf(),
        error,
    };
    let bytes = match fs::read(path) {
        Ok(bytes) => bytes,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Ok(PerPairFile {
                inputs: None,
                lines: Vec::new(),
            })
        }
        Err(error) => return Err(io(error)),
    };
    let mut text = Vec::new();
    match MultiGzDecoder::new(&bytes[..]).read_to_end(&mut text) {
        Ok(_) => {}
        Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
            let whole_lines = text.iter().rposition(|&b| b == b'\n').map_or(0, |n| n + 1);
            text.truncate(whole_lines);
        }
        Err(error) => return Err(io(error)),
    }
    let text = String::from_utf8(text)
        .map_err(|e| io(std::io::Error::new(std::io::ErrorKind::InvalidData, e)))?;
    let error = |line: usize, error: String| EvaluateError::Record {
        path: path.to_path_buf(),
        line: line + 1,
        error,
    };
    let mut lines = text.lines().enumerate();
    let Some((_, header)) = lines.next() else {
        return Ok(PerPairFile {
            inputs: None,
            lines: Vec::new(),
        });
    };
    let header: Header = serde_json::from_str(header).map_err(|e| error(0, e.to_string()))?;
    if header.version != VERSION {
        return Err(EvaluateError::Version {
            path: path.to_path_buf(),
            version: header.version,
        });
    }
    let lines = lines
        .map(|(n, text)| {
            let line: Line = serde_json::from_str(text).map_err(|e| error(n, e.to_string()))?;
            line.transform().map_err(|e| error(n, e.to_string()))?;
            Ok(line)
        })
        .collect::<Result<_, EvaluateError>>()?;
    Ok(PerPairFile {
        inputs: Some(header.inputs),
        lines,
    })
}

/// `lines` as JSON lines.
fn json_lines<T: Serialize>(lines: &[T]) -> String {
    lines
        .iter()
        .map(|line| serde_json::to_string(line).expect("a line serialises") + "\n")
        .collect()
}

/// `text` as one gzip member (no time stamp: the same text, the same bytes).
fn gzip(text: &str) -> Vec<u8> {
    let mut gz = GzEncoder::new(Vec::new(), Compression::best());
    gz.write_all(text.as_bytes()).expect("writing to memory");
    gz.finish().expect("writing to memory")
}

/// The per-pair file `path` of `inputs` holding `lines`, in one gzip member, replaced whole
/// ([`rgm_data::durable`]), so that a run killed meanwhile leaves the old file.
fn write_file(path: &Path, inputs: &str, lines: &[Line]) -> std::io::Result<()> {
    let header = Header {
        version: VERSION,
        inputs: inputs.to_string(),
    };
    let bytes = gzip(&(json_lines(&[header]) + &json_lines(lines)));
    rgm_data::durable::replace(path, |out| out.write_all(&bytes))
}

/// `lines` appended to the per-pair file `path`, a gzip member of their own.
fn append(path: &Path, lines: &[Line]) -> std::io::Result<()> {
    fs::OpenOptions::new()
        .append(true)
        .open(path)?
        .write_all(&gzip(&json_lines(lines)))
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;

    use rgm_data::Setting;

    use super::*;
    use crate::{MethodName, MethodOptions};
    use rgm_registration::methods::refine::RefineConfig;

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

    /// Clean test pairs of wavy shapes.
    struct Fixture {
        shapes: Vec<Shape>,
        generator: PairGenerator,
    }

    impl Fixture {
        fn new(count: usize) -> Self {
            Self {
                shapes: (0..count).map(shape).collect(),
                generator: PairGenerator::new(Setting::Clean),
            }
        }

        fn with<T>(&self, f: impl FnOnce(TestPairs) -> T) -> T {
            let shapes: Vec<&Shape> = self.shapes.iter().collect();
            f(TestPairs {
                generator: &self.generator,
                shapes: &shapes,
            })
        }
    }

    /// Every field of two records equal, bit for bit.
    fn assert_same(a: &[PairRecord], b: &[PairRecord]) {
        assert_eq!(a.len(), b.len());
        for (a, b) in a.iter().zip(b) {
            assert_eq!(a.index, b.index);
            assert_eq!(a.transform.to_rows(), b.transform.to_rows());
            assert_eq!(a.ground_truth.to_rows(), b.ground_truth.to_rows());
            assert_eq!(a.metrics, b.metrics);
            assert_eq!(a.time_ms.to_bits(), b.time_ms.to_bits());
            assert_eq!(a.correspondences, b.correspondences);
            assert_eq!(a.failure, b.failure);
        }
    }

    #[test]
    fn a_resumed_evaluation_computes_only_the_missing_pairs_and_equals_a_whole_one() {
        let dir = temp_dir("resume");
        let path = dir.join("results/clean/icp.jsonl.gz");
        let fixture = Fixture::new(3);
        let method = icp();
        fixture.with(|pairs| {
            let whole = Counted::default();
            let all = run(None)
                .evaluate(&path, "icp", &method, pairs, &whole)
                .unwrap();
            assert_eq!(all.iter().map(|r| r.index).collect::<Vec<_>>(), [0, 1, 2]);
            assert_eq!(*whole.started.lock().unwrap(), [(3, 0)]);
            assert_eq!(whole.advanced.load(Ordering::Relaxed), 3);
            assert_eq!(*whole.finished.lock().unwrap(), [true]);

            // Nothing missing: nothing computed, nothing reported, and the records scored
            // from the file's transforms are those of the evaluation, bit for bit.
            let idle = Counted::default();
            let again = run(None)
                .evaluate(&path, "icp", &method, pairs, &idle)
                .unwrap();
            assert!(idle.started.lock().unwrap().is_empty());
            assert_same(&again, &all);

            // Keep the file's pair 1 only: a resumed evaluation computes pairs 0 and 2 again.
            let kept = read_file(&path).unwrap().lines;
            write_file(&path, "icp", &kept[1..2]).unwrap();
            let resumed = Counted::default();
            let again = run(None)
                .evaluate(&path, "icp", &method, pairs, &resumed)
                .unwrap();
            assert_eq!(*resumed.started.lock().unwrap(), [(3, 1)]);
            assert_eq!(resumed.advanced.load(Ordering::Relaxed), 2);
            assert_eq!(read_file(&path).unwrap().lines.len(), 3);
            for (a, b) in all.iter().zip(&again) {
                assert_eq!(a.transform.to_rows(), b.transform.to_rows());
                assert_eq!(a.metrics, b.metrics);
            }

            // Other inputs (another option, other weights): every pair computed again.
            let changed = Counted::default();
            run(None)
                .evaluate(&path, "icp, other options", &method, pairs, &changed)
                .unwrap();
            assert_eq!(*changed.started.lock().unwrap(), [(3, 0)]);
            let file = read_file(&path).unwrap();
            assert_eq!(file.inputs.as_deref(), Some("icp, other options"));
            assert_eq!(file.lines.len(), 3);

            // Refined from the records: the refinement's own file, every pair of the records.
            let refined_path = dir.join("results/clean/icp-refine.jsonl.gz");
            let config = RefineConfig::default();
            let refined = run(None)
                .refine(
                    &refined_path,
                    "icp; refined",
                    &all[..2],
                    &config,
                    pairs,
                    &(),
                )
                .unwrap();
            assert_eq!(refined.iter().map(|r| r.index).collect::<Vec<_>>(), [0, 1]);
            assert!(refined
                .iter()
                .zip(&all)
                .all(|(r, a)| r.time_ms >= a.time_ms));
            let back = run(None)
                .refine(
                    &refined_path,
                    "icp; refined",
                    &all[..2],
                    &config,
                    pairs,
                    &(),
                )
                .unwrap();
            assert_same(&back, &refined);
        });
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_file_cut_anywhere_reads_back_as_its_whole_lines_and_resumes_to_the_whole() {
        let dir = temp_dir("cut");
        fs::create_dir_all(&dir).unwrap();
        let path = dir.join("icp.jsonl.gz");
        let fixture = Fixture::new(3);
        let method = icp();
        fixture.with(|pairs| {
            let all = run(None)
                .evaluate(&path, "icp", &method, pairs, &())
                .unwrap();
            // As a run writes it: the first chunk with the header, then a member per chunk.
            let lines: Vec<Line> = all.iter().map(Line::of).collect();
            write_file(&path, "icp", &lines[..1]).unwrap();
            append(&path, &lines[1..2]).unwrap();
            append(&path, &lines[2..]).unwrap();
            let bytes = fs::read(&path).unwrap();
            // The longest cut keeping n whole lines, for each n.
            let mut longest = [0; 4];
            for end in 0..=bytes.len() {
                fs::write(&path, &bytes[..end]).unwrap();
                let file = read_file(&path).unwrap();
                let n = file.lines.len();
                assert_eq!(file.lines, lines[..n], "cut at {end}");
                assert!(file.inputs.is_some() || n == 0);
                longest[n] = end;
            }
            assert!(longest.windows(2).all(|w| w[0] < w[1]), "{longest:?}");

            // Cut inside the second pair's member: pairs 1 and 2 computed again.
            fs::write(&path, &bytes[..longest[1]]).unwrap();
            assert_eq!(read_file(&path).unwrap().lines.len(), 1);
            let resumed = Counted::default();
            let again = run(None)
                .evaluate(&path, "icp", &method, pairs, &resumed)
                .unwrap();
            assert_eq!(*resumed.started.lock().unwrap(), [(3, 1)]);
            assert_same(&again[..1], &all[..1]);
            for (a, b) in all.iter().zip(&again) {
                assert_eq!(a.transform.to_rows(), b.transform.to_rows());
            }
            // Written anew as one member.
            let whole = fs::read(&path).unwrap();
            let file = read_file(&path).unwrap();
            assert_eq!(file.lines.len(), 3);
            let one = gzip(
                &(json_lines(&[Header {
                    version: VERSION,
                    inputs: "icp".into(),
                }]) + &json_lines(&file.lines)),
            );
            assert_eq!(whole, one);
        });
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_passed_deadline_starts_no_chunk_and_writes_nothing() {
        let dir = temp_dir("deadline");
        let path = dir.join("x.jsonl.gz");
        let fixture = Fixture::new(1);
        let method = icp();
        let progress = Counted::default();
        let records = fixture.with(|pairs| {
            run(Some(Instant::now()))
                .evaluate(&path, "icp", &method, pairs, &progress)
                .unwrap()
        });
        assert!(records.is_empty());
        assert_eq!(*progress.finished.lock().unwrap(), [false]);
        assert_eq!(progress.advanced.load(Ordering::Relaxed), 0);
        assert!(!path.exists());
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_line_that_is_not_a_record_is_named_and_other_versions_are_refused() {
        let dir = temp_dir("read");
        fs::create_dir_all(&dir).unwrap();
        let path = dir.join("icp.jsonl.gz");
        let record = super::super::tests::record();
        let header = r#"{"version":1,"inputs":"icp"}"#;
        fs::write(&path, gzip(&format!("{header}\n{{\"index\": 1}}\n"))).unwrap();
        let missing = read_file(&path).err().unwrap();
        let mut line = Line::of(&record);
        line.transform[0][0] = 2.0;
        fs::write(&path, gzip(&(format!("{header}\n") + &json_lines(&[line])))).unwrap();
        let not_rigid = read_file(&path).err().unwrap();
        fs::write(&path, gzip("{\"version\":2,\"inputs\":\"icp\"}\n")).unwrap();
        let version = read_file(&path).err().unwrap();
        fs::remove_dir_all(&dir).unwrap();
        assert!(
            missing
                .to_string()
                .contains("icp.jsonl.gz line 2: missing field"),
            "{missing}"
        );
        assert!(
            not_rigid.to_string().contains("icp.jsonl.gz line 2: "),
            "{not_rigid}"
        );
        assert!(
            version
                .to_string()
                .ends_with("per-pair file version 2, this code reads 1"),
            "{version}"
        );
    }
}
