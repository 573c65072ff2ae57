//! Many pairs registered on parallel workers, one JSON line each, resumably: the runner behind
//! `rgm register --pairs LIST` and Python's `Registrar.register_many`.
//!
//! The output file ([`Output`]) is rgm's only when its first line is rgm's header
//! (`{"rgm_many_pairs": 1, "settings": {…}}`), which records every setting that changes results
//! ([`settings`]); any other file is never written to. (A file of before issue 58, whose
//! header is `{"rgm_batch": 1, …}` and whose method is named `auto+icp` for `auto+refine`,
//! resumes too: its header is rewritten as today's, its lines kept as they are.) While a run uses it, it holds an
//! exclusive lock on it, so a second run on the same file is refused instead of mixing its
//! lines in. A later run with the same settings keeps the lines of finished pairs and registers
//! the other pairs; with other settings it is refused, naming the setting. Resuming drops a
//! cut-off last line (a killed run), the lines of pairs that failed (they are tried again) and
//! repeated pairs, by rewriting the file whole (temporary file and rename) before it appends,
//! so the file never holds a pair twice. Lines are appended one `write` each, as pairs finish.
//!
//! A pair is named by its files as the caller spells them, and each line also records what its
//! inputs were (`"inputs"`, [`inputs`]: each file's resolved path, size and modification time,
//! or each cloud's point count and CRC-32): a resume counts a pair as finished only when its
//! inputs are still those, so another day's `scan.npy`, or other arrays at the same place of a
//! Python list, run again rather than take an old line's transform. Their new line replaces
//! the old one (the CLI drops the old ones before it starts, [`Output::forget`]; a later
//! line of a pair supersedes an earlier one when a file is read).

mod output;

pub use output::Output;

use std::collections::{HashMap, HashSet};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

use rayon::prelude::*;
use rgm_data::pair_list::{self, ListedPair};
use rgm_geom::PointCloud;
use rgm_registration::registrar::Registrar as _;
use serde_json::{json, Map, Value};

use crate::progress::Progress;
use crate::{Method, MethodName, MethodOptions, Registration};

/// The version of the output's format, in its header.
pub const FORMAT: u64 = 1;

/// The header's key that marks a file as the output of rgm's many pairs.
const HEADER_KEY: &str = "rgm_many_pairs";

/// [`HEADER_KEY`] before issue 58 renamed a pair list's runner (it was `batch`): still read.
const OLD_HEADER_KEY: &str = "rgm_batch";

/// Why a run of many pairs could not run. A pair that fails is a line, not an error.
#[derive(Debug, thiserror::Error)]
pub enum PairsError {
    /// A file could not be read or written.
    #[error("{action} {}: {error}", path.display())]
    Io {
        action: &'static str,
        path: PathBuf,
        error: std::io::Error,
    },
    /// The pair list is not one (the message names the file, the line and the value).
    #[error("{0}")]
    List(String),
    /// The output file is not rgm's, or not of these settings (the message says which and
    /// how to go on).
    #[error("{0}")]
    Output(String),
    /// Another run holds the output file.
    #[error(
        "{}: another run is writing this file (it holds its lock); wait for it to end, or give \
         another output file",
        path.display()
    )]
    Busy { path: PathBuf },
}

impl PairsError {
    fn io<'a>(action: &'static str, path: &'a Path) -> impl FnOnce(std::io::Error) -> Self + 'a {
        move |error| Self::Io {
            action,
            path: path.to_path_buf(),
            error,
        }
    }
}

/// What became of a pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    Registered,
    /// A result with a doubt ([`Registration::doubt`]), `"registered": false`.
    NotRegistered,
    Failed,
}

/// How many pairs came out each way.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Tally {
    pub registered: usize,
    pub not_registered: usize,
    pub failed: usize,
}

impl Tally {
    pub fn add(&mut self, outcome: Outcome) {
        match outcome {
            Outcome::Registered => self.registered += 1,
            Outcome::NotRegistered => self.not_registered += 1,
            Outcome::Failed => self.failed += 1,
        }
    }

    pub fn total(&self) -> usize {
        self.registered + self.not_registered + self.failed
    }
}

impl std::ops::AddAssign for Tally {
    fn add_assign(&mut self, other: Self) {
        self.registered += other.registered;
        self.not_registered += other.not_registered;
        self.failed += other.failed;
    }
}

/// A pair an earlier run finished: how, and the inputs its line records (`Value::Null` for a
/// line written before lines recorded them: taken as the same inputs).
#[derive(Clone, Debug, PartialEq)]
pub struct Done {
    pub outcome: Outcome,
    pub inputs: Value,
}

impl Done {
    /// Whether the line stands for a pair of these `inputs`.
    pub fn is_of(&self, inputs: &Value) -> bool {
        self.inputs.is_null() || &self.inputs == inputs
    }
}

/// What identifies a pair's inputs, as its line records them: for files, each one's resolved
/// path, size and modification time (nanoseconds since the epoch; `null` for a file that
/// cannot be read, which then fails); for clouds in memory, each one's point count and the
/// CRC-32 of its coordinates.
pub fn inputs(clouds: &Clouds) -> Value {
    match clouds {
        Clouds::Files { source, target } => {
            json!({"source": file_identity(source), "target": file_identity(target)})
        }
        Clouds::Given { source, target } => {
            json!({"source": cloud_identity(source), "target": cloud_identity(target)})
        }
    }
}

fn file_identity(path: &Path) -> Value {
    let Ok(meta) = std::fs::metadata(path) else {
        return Value::Null;
    };
    let modified = meta
        .modified()
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map(|t| t.as_nanos().to_string());
    let resolved = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
    json!({"path": resolved.to_string_lossy(), "bytes": meta.len(), "modified_ns": modified})
}

fn cloud_identity(cloud: &PointCloud) -> Value {
    let mut crc = flate2::Crc::new();
    for p in &cloud.points {
        for c in [p.x, p.y, p.z] {
            crc.update(&c.to_le_bytes());
        }
    }
    json!({"points": cloud.len(), "crc32": crc.sum()})
}

/// A pair's name in the output: its source and target as the caller spells them.
pub type Key = (String, String);

/// One pair to register.
pub struct Job {
    /// Its place among the pairs given.
    pub index: usize,
    /// Its name in the output.
    pub key: Key,
    pub clouds: Clouds,
}

/// A pair's clouds: files read on the worker that registers them, or clouds in memory.
pub enum Clouds {
    Files {
        source: PathBuf,
        target: PathBuf,
    },
    Given {
        source: PointCloud,
        target: PointCloud,
    },
}

/// One pair of a list file.
#[derive(Debug)]
pub struct Listed {
    /// The files as the list spells them: the pair's name in the output.
    pub key: Key,
    /// The files, relative paths taken from the list's folder.
    pub source_path: PathBuf,
    pub target_path: PathBuf,
}

impl Listed {
    /// The pair as the `index`th job.
    pub fn job(&self, index: usize) -> Job {
        Job {
            index,
            key: self.key.clone(),
            clouds: Clouds::Files {
                source: self.source_path.clone(),
                target: self.target_path.clone(),
            },
        }
    }
}

/// The object `rgm register --json` prints for `registration` by `method` of clouds of
/// `points` (source, target); a run of many pairs writes it per pair, with the pair's names.
pub fn result_json(
    method: &Method,
    registration: &Registration,
    (source_points, target_points): (usize, usize),
) -> Value {
    let result = &registration.result;
    let candidates: Vec<Value> = registration
        .candidates
        .iter()
        .map(|c| {
            json!({
                "method": c.method,
                "score": c.score,
                "transform": c.t_target_source.to_rows(),
                "failure": c.failure,
                "time_ms": c.time_ms,
            })
        })
        .collect();
    let chosen = registration
        .chosen
        .map(|k| registration.candidates[k].method.as_str());
    json!({
        "method": method.name(),
        "transform": result.t_target_source.to_rows(),
        "time_ms": registration.time_ms,
        "iterations": result.iterations,
        "converged": result.converged,
        // The pairs behind the fitness: RGM's last hard matches unrefined, the refinement's
        // inliers refined.
        "correspondences": result.inlier_count,
        "refined": method.is_refined(),
        "fitness": result.fitness,
        "inlier_rmse": result.inlier_rmse,
        "source_points": source_points,
        "target_points": target_points,
        "candidates": candidates,
        "chosen": chosen,
        "registered": registration.doubt.is_none(),
        "reason": registration.doubt,
    })
}

/// Every setting of `options` that changes results, as the output's header records them: the
/// method's name (`method`, with `+refine` when refined), the weights' CRC-32 (the built-in
/// model's name and CRC-32 for `rgm` and `auto` without weights) and each option as given
/// (`null`: the method's default).
pub fn settings(
    options: &MethodOptions,
    method: &Method,
) -> Result<Map<String, Value>, PairsError> {
    let network = matches!(
        options.method,
        MethodName::Rgm | MethodName::Auto | MethodName::Scene
    );
    let weights = match (&options.weights, network) {
        (_, false) => Value::Null,
        (Some(path), true) => {
            let bytes = std::fs::read(path).map_err(PairsError::io("reading", path))?;
            format!("CRC-32 {:08x}", crc32(&bytes)).into()
        }
        (None, true) => {
            let manifest = crate::weights::Manifest::builtin();
            let name = manifest.builtin_entry().map_or("?", |e| e.name.as_str());
            format!(
                "built-in {name}, CRC-32 {:08x}",
                crc32(crate::weights::builtin_weights())
            )
            .into()
        }
    };
    let value = json!({
        "method": method.name(),
        "weights": weights,
        "preset": options.preset,
        "test_statistics": options.test_statistics.map(|s| format!("{s:?}").to_lowercase()),
        "match_points": options.match_points,
        "passes": options.passes,
        "accept": matches!(options.method, MethodName::Auto | MethodName::Scene).then(|| options.accept.to_string()),
        "refine": options.refine,
        "precision": options.precision.name(),
    });
    match value {
        Value::Object(map) => Ok(map),
        _ => unreachable!("a JSON object"),
    }
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = flate2::Crc::new();
    crc.update(bytes);
    crc.sum()
}

/// Registers each of `jobs` with a copy of `method` per worker of the current rayon pool,
/// taking jobs as workers come free (an iterator is never collected). Each pair's line
/// (its [`result_json`] with `"source"` and `"target"`, or `{"source", "target", "method",
/// "error"}` when it failed) goes to `lines` as one `write`; `each` gets its registration or
/// error. Stops taking jobs once `stop` is set. A failed write to `lines` stops the run.
pub fn register_all<I, F>(
    method: &Method,
    jobs: I,
    lines: Option<(&Path, &Mutex<dyn Write + Send + '_>)>,
    progress: &dyn Progress,
    stop: &AtomicBool,
    each: F,
) -> Result<Tally, PairsError>
where
    I: Iterator<Item = Job> + Send,
    F: Fn(usize, Result<Registration, String>) + Sync,
{
    let tally = Mutex::new(Tally::default());
    jobs.take_while(|_| !stop.load(Ordering::Relaxed))
        .par_bridge()
        .map_init(
            || method.clone(),
            |method, job| -> Result<(), PairsError> {
                let (registered, points) = register_job(method, &job.clouds, progress);
                let outcome = match &registered {
                    Ok(r) if r.doubt.is_none() => Outcome::Registered,
                    Ok(_) => Outcome::NotRegistered,
                    Err(_) => Outcome::Failed,
                };
                if let Some((path, out)) = lines {
                    let mut line = match &registered {
                        Ok(registration) => result_json(method, registration, points),
                        Err(why) => json!({"method": method.name(), "error": why}),
                    };
                    line["source"] = job.key.0.clone().into();
                    line["target"] = job.key.1.clone().into();
                    line["inputs"] = inputs(&job.clouds);
                    let mut out = out.lock().unwrap_or_else(|p| p.into_inner());
                    out.write_all(format!("{line}\n").as_bytes())
                        .and_then(|()| out.flush())
                        .map_err(PairsError::io("writing", path))?;
                }
                tally.lock().unwrap_or_else(|p| p.into_inner()).add(outcome);
                each(job.index, registered);
                progress.advance();
                Ok(())
            },
        )
        .collect::<Result<(), PairsError>>()?;
    Ok(tally.into_inner().unwrap_or_else(|p| p.into_inner()))
}

/// A job's registration (or why it failed) and its clouds' sizes.
fn register_job(
    method: &mut Method,
    clouds: &Clouds,
    progress: &dyn Progress,
) -> (Result<Registration, String>, (usize, usize)) {
    let read = |path: &Path| -> Result<PointCloud, String> {
        let (cloud, warnings) =
            rgm_data::read_point_cloud_warned(path).map_err(|e| e.to_string())?;
        for warning in warnings {
            progress.note(&warning.to_string());
        }
        Ok(cloud)
    };
    match clouds {
        Clouds::Given { source, target } => {
            let registered = method
                .register(source, target)
                .map_err(|e| format!("{} failed: {e}", method.name()));
            (registered, (source.len(), target.len()))
        }
        Clouds::Files { source, target } => {
            match read(source).and_then(|s| Ok((s, read(target)?))) {
                Ok((s, t)) => {
                    let registered = method.register(&s, &t).map_err(|e| {
                        format!(
                            "{} failed on {} → {}: {e}",
                            method.name(),
                            source.display(),
                            target.display()
                        )
                    });
                    (registered, (s.len(), t.len()))
                }
                Err(why) => (Err(why), (0, 0)),
            }
        }
    }
}

/// The pairs of the list file `path` ([`rgm_data::pair_list`]), a repeated pair once (noted).
pub fn read_list(path: &Path, progress: &dyn Progress) -> Result<Vec<Listed>, PairsError> {
    let text = std::fs::read_to_string(path).map_err(PairsError::io("reading", path))?;
    let folder = path.parent().unwrap_or(Path::new(""));
    let named = pair_list::parse(path, &text).map_err(|e| PairsError::List(e.0))?;
    let mut first: HashMap<Key, String> = HashMap::new();
    let mut pairs = Vec::with_capacity(named.len());
    for ListedPair {
        source,
        target,
        place,
    } in named
    {
        let key = (source, target);
        if let Some(earlier) = first.get(&key) {
            progress.note(&format!(
                "{place} repeats the pair of {earlier} ({}, {}); it runs once",
                key.0, key.1
            ));
            continue;
        }
        first.insert(key.clone(), place);
        pairs.push(Listed {
            source_path: folder.join(&key.0),
            target_path: folder.join(&key.1),
            key,
        });
    }
    if pairs.is_empty() {
        return Err(PairsError::List(format!(
            "{}: no pair listed",
            path.display()
        )));
    }
    Ok(pairs)
}

/// The pairs of `listed` an earlier run has not finished (`done`) with the files they have
/// now, the finished ones' tally, and the pairs whose line is of other files (`stale`: their
/// files changed, or another list names other files alike; they run again).
pub fn remaining<'a>(
    listed: &'a [Listed],
    done: &HashMap<Key, Done>,
) -> (Vec<&'a Listed>, Tally, HashSet<Key>) {
    let mut earlier = Tally::default();
    let mut todo = Vec::new();
    let mut stale = HashSet::new();
    for pair in listed {
        match done.get(&pair.key) {
            Some(line) if line.is_of(&inputs(&pair.job(0).clouds)) => earlier.add(line.outcome),
            Some(_) => {
                stale.insert(pair.key.clone());
                todo.push(pair);
            }
            None => todo.push(pair),
        }
    }
    (todo, earlier, stale)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A folder for a test's output file `out.jsonl`, the default method's settings and the
    /// header they give.
    fn scratch_output(name: &str) -> (PathBuf, PathBuf, Map<String, Value>, String) {
        let dir =
            std::env::temp_dir().join(format!("rgm-many-pairs-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let settings = settings(
            &MethodOptions::default(),
            &MethodOptions::default().build().unwrap(),
        )
        .unwrap();
        let header = json!({HEADER_KEY: FORMAT, "settings": settings}).to_string();
        (dir.clone(), dir.join("out.jsonl"), settings, header)
    }

    #[test]
    fn a_rewritten_output_stays_locked_and_keeps_its_finished_lines() {
        let (dir, path, settings, header) = scratch_output("lock");
        let done = r#"{"source":"a","target":"b","registered":true}"#;
        let failed = r#"{"source":"c","target":"d","error":"no"}"#;
        // A failed pair's line and a cut-off last line: the file is rewritten without them.
        std::fs::write(&path, format!("{header}\n{done}\n{failed}\n{{\"sou")).unwrap();
        let output = Output::open(&path, &settings, &()).unwrap();
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            format!("{header}\n{done}\n")
        );
        let key = ("a".to_string(), "b".to_string());
        assert_eq!(
            output.done().get(&key).map(|d| d.outcome),
            Some(Outcome::Registered)
        );
        assert_eq!(output.done().len(), 1);
        // The file now at the path is the one this run holds.
        let other = std::fs::File::open(&path).unwrap();
        assert!(matches!(
            other.try_lock(),
            Err(std::fs::TryLockError::WouldBlock)
        ));
        assert!(matches!(
            Output::open(&path, &settings, &()),
            Err(PairsError::Busy { .. })
        ));
        drop(output);
        other.try_lock().unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_last_line_cut_inside_a_character_is_dropped_and_the_run_resumes() {
        let (dir, path, settings, header) = scratch_output("utf8");
        let done = r#"{"source":"é.ply","target":"b","registered":true}"#;
        // "ü" is two bytes; the line ends after the first.
        let mut bytes = format!("{header}\n{done}\n{{\"source\":\"").into_bytes();
        bytes.push("ü".as_bytes()[0]);
        std::fs::write(&path, &bytes).unwrap();
        let output = Output::open(&path, &settings, &()).unwrap();
        assert_eq!(output.done().len(), 1);
        drop(output);
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            format!("{header}\n{done}\n")
        );
        // A byte that is not UTF-8 inside a finished line is not one of rgm's lines.
        let mut bytes = format!("{header}\n{done}\n").into_bytes();
        bytes.extend_from_slice(b"{\"source\":\"\xff\"}\n");
        std::fs::write(&path, &bytes).unwrap();
        let error = Output::open(&path, &settings, &())
            .err()
            .unwrap()
            .to_string();
        assert!(error.contains("out.jsonl:3: not text"), "{error}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_file_of_before_issue_58_resumes_and_gets_today_s_header() {
        let (dir, path, settings, header) = scratch_output("issue58");
        // The header of then: `rgm_batch`, the default named `auto+icp`.
        assert_eq!(settings["method"], "auto+refine");
        let mut then = settings.clone();
        then["method"] = "auto+icp".into();
        let old = json!({OLD_HEADER_KEY: FORMAT, "settings": then}).to_string();
        let done = r#"{"source":"a","target":"b","method":"auto+icp","registered":true}"#;
        std::fs::write(&path, format!("{old}\n{done}\n")).unwrap();
        let output = Output::open(&path, &settings, &()).unwrap();
        let key = ("a".to_string(), "b".to_string());
        assert_eq!(
            output.done().get(&key).map(|d| d.outcome),
            Some(Outcome::Registered)
        );
        drop(output);
        // The header rewritten as today's, the line kept as it was.
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            format!("{header}\n{done}\n")
        );
        // Other settings of then are refused as before, naming the setting.
        then["match_points"] = 64.into();
        let old = json!({OLD_HEADER_KEY: FORMAT, "settings": then}).to_string();
        std::fs::write(&path, format!("{old}\n{done}\n")).unwrap();
        let error = Output::open(&path, &settings, &())
            .err()
            .unwrap()
            .to_string();
        assert!(error.contains("made with match_points 64"), "{error}");
        assert!(std::fs::read_to_string(&path).unwrap().starts_with(&old));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_later_line_of_a_pair_supersedes_an_earlier_one() {
        let (dir, path, settings, header) = scratch_output("last");
        let old = r#"{"source":"a","target":"b","registered":true,"inputs":1}"#;
        let other = r#"{"source":"c","target":"d","registered":true}"#;
        let new = r#"{"source":"a","target":"b","registered":false,"inputs":2}"#;
        std::fs::write(&path, format!("{header}\n{old}\n{other}\n{new}\n")).unwrap();
        let output = Output::open(&path, &settings, &()).unwrap();
        let key = ("a".to_string(), "b".to_string());
        let done = &output.done()[&key];
        assert_eq!(
            (done.outcome, &done.inputs),
            (Outcome::NotRegistered, &json!(2))
        );
        // A line without inputs (an older file's) stands for any; one with them, for those.
        assert!(output.done()[&("c".to_string(), "d".to_string())].is_of(&json!(5)));
        assert!(done.is_of(&json!(2)) && !done.is_of(&json!(1)));
        drop(output);
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            format!("{header}\n{other}\n{new}\n")
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
