//! The output file of many pairs: rgm's header, the lock a run holds, the lines earlier runs
//! finished, and the rewrite that drops the others (the module doc of [`super`] says how).

use std::borrow::Cow;
use std::collections::{HashMap, HashSet};
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use rgm_data::durable::{self, LockError};
use rgm_data::pair_list::shortened;
use rgm_registration::methods::refine;
use serde_json::{json, Map, Value};

use super::{Done, Key, Outcome, PairsError, FORMAT, HEADER_KEY, OLD_HEADER_KEY};
use crate::progress::Progress;

/// A run's output file (JSON Lines), locked for the run, with what earlier runs finished.
pub struct Output {
    path: PathBuf,
    /// Open for appending, locked until dropped.
    file: Mutex<File>,
    done: HashMap<Key, Done>,
}

impl Output {
    /// Opens `path` for a run of `settings` (see the module's doc), rewriting it without the
    /// lines to be done again; a file that is not rgm's, or of other settings, or that another
    /// run holds, is an error and left as it is.
    pub fn open(
        path: &Path,
        settings: &Map<String, Value>,
        progress: &dyn Progress,
    ) -> Result<Self, PairsError> {
        let path = match std::fs::canonicalize(path) {
            Ok(resolved) => resolved,
            Err(_) => path.to_path_buf(),
        };
        if path.exists() && !path.is_file() {
            return Err(PairsError::Output(format!(
                "{}: not a regular file; the output is a file that later runs resume (leave it \
                 out to write the lines to stdout)",
                path.display()
            )));
        }
        let file = lock(&path)?;
        // Bytes, not text: a line cut inside a character by a kill or a full disk is dropped
        // like any cut-off line, wherever it was cut.
        let bytes = std::fs::read(&path).map_err(PairsError::io("reading", &path))?;
        let header = json!({HEADER_KEY: FORMAT, "settings": settings}).to_string() + "\n";
        if bytes.is_empty() {
            (&file)
                .write_all(header.as_bytes())
                .map_err(PairsError::io("writing", &path))?;
            return Ok(Self {
                path,
                file: Mutex::new(file),
                done: HashMap::new(),
            });
        }
        let (first, rest) = bytes.split_at(
            bytes
                .iter()
                .position(|&b| b == b'\n')
                .map_or(bytes.len(), |n| n + 1),
        );
        let current = check_header(&path, &String::from_utf8_lossy(first), settings)?;
        let (done, kept, rewrite) = earlier_lines(&path, rest, progress)?;
        // A header of before issue 58 is rewritten as today's.
        let file = match rewrite || !current {
            true => replace(&path, &(header + &kept))?,
            false => file,
        };
        Ok(Self {
            path,
            file: Mutex::new(file),
            done,
        })
    }

    /// The outcome of each pair an earlier run finished.
    pub fn done(&self) -> &HashMap<Key, Done> {
        &self.done
    }

    /// Rewrites the file without the lines of `stale` (pairs whose inputs changed since: they
    /// run again), so that it never holds two lines of one pair.
    pub fn forget(&mut self, stale: &HashSet<Key>) -> Result<(), PairsError> {
        if stale.is_empty() {
            return Ok(());
        }
        let bytes = std::fs::read(&self.path).map_err(PairsError::io("reading", &self.path))?;
        let text = String::from_utf8_lossy(&bytes);
        let mut kept = String::with_capacity(text.len());
        for (i, line) in text.lines().enumerate() {
            let value: Value = serde_json::from_str(line).unwrap_or(Value::Null);
            let key = (value["source"].as_str(), value["target"].as_str());
            let named = match key {
                (Some(s), Some(t)) => stale.contains(&(s.to_string(), t.to_string())),
                _ => false,
            };
            if i == 0 || !named {
                kept.push_str(line);
                kept.push('\n');
            }
        }
        let file = replace(&self.path, &kept)?;
        *self.file.lock().unwrap_or_else(|p| p.into_inner()) = file;
        for key in stale {
            self.done.remove(key);
        }
        Ok(())
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Where [`super::register_all`] appends the lines.
    pub fn lines(&self) -> (&Path, &Mutex<dyn Write + Send + '_>) {
        (&self.path, &self.file)
    }
}

/// `path` opened for appending, created when missing, and locked ([`durable::lock`]); an error
/// when another run holds it.
fn lock(path: &Path) -> Result<File, PairsError> {
    let options = std::fs::OpenOptions::new()
        .read(true)
        .append(true)
        .create(true)
        .clone();
    durable::lock(path, &options).map_err(|error| match error {
        LockError::Busy => PairsError::Busy {
            path: path.to_path_buf(),
        },
        LockError::Io(error) => PairsError::Io {
            action: "locking",
            path: path.to_path_buf(),
            error,
        },
    })
}

/// `path` written anew with `text` ([`durable::replace_with`]), the new file locked before it
/// is renamed over `path` (so the run keeps its lock); the file, open for appending.
fn replace(path: &Path, text: &str) -> Result<File, PairsError> {
    let options = std::fs::OpenOptions::new().read(true).append(true).clone();
    durable::replace_with(path, &options, |file| {
        file.try_lock().map_err(std::io::Error::other)?;
        file.write_all(text.as_bytes())
    })
    .map_err(|error| PairsError::Io {
        action: "rewriting",
        path: path.to_path_buf(),
        error,
    })
}

/// Refuses a file whose first line is not rgm's header, or one of other settings; `false` when
/// the header is one of before issue 58 (`{"rgm_batch": 1, …}`, the method named `auto+icp`),
/// read as today's.
fn check_header(
    path: &Path,
    first: &str,
    settings: &Map<String, Value>,
) -> Result<bool, PairsError> {
    let header: Option<Map<String, Value>> = serde_json::from_str(first).ok();
    let key = header.as_ref().and_then(|h| {
        [HEADER_KEY, OLD_HEADER_KEY]
            .into_iter()
            .find(|&key| h.contains_key(key))
    });
    let (Some(header), Some(key)) = (header.as_ref(), key) else {
        return Err(PairsError::Output(format!(
            "{}:1: not an output of rgm's pair lists (`rgm register --pairs`, \
             `register_many`: its first line is not rgm's header {{\"{HEADER_KEY}\": …}}), so \
             it is left as it is; give another output file (a file written by an rgm before the \
             header existed is not resumed either): `{}`",
            path.display(),
            shortened(first.trim_end())
        )));
    };
    if header[key] != FORMAT {
        return Err(PairsError::Output(format!(
            "{}:1: pair-list output format {}, this rgm writes {FORMAT}; give another output \
             file",
            path.display(),
            header[key]
        )));
    }
    let empty = Map::new();
    let mut written = header
        .get("settings")
        .and_then(Value::as_object)
        .unwrap_or(&empty)
        .clone();
    let mut current = key == HEADER_KEY;
    if let Some(Value::String(method)) = written.get_mut("method") {
        if let Cow::Owned(now) = refine::current_name(method) {
            *method = now;
            current = false;
        }
    }
    let mut names: Vec<&String> = settings.keys().chain(written.keys()).collect();
    names.sort();
    names.dedup();
    for name in names {
        let (was, now) = (
            written.get(name).unwrap_or(&Value::Null),
            settings.get(name).unwrap_or(&Value::Null),
        );
        if was != now {
            return Err(PairsError::Output(format!(
                "{}: its results were made with {name} {was}, this run asks for {name} {now} \
                 (null: the method's default); the file is left as it is: resume with its \
                 settings, or give another output file for these",
                path.display()
            )));
        }
    }
    Ok(current)
}

/// What became of each pair an earlier run finished, from the lines after the header
/// (`bytes`), the lines to keep, and whether the file must be rewritten without others: a
/// cut-off last line, a failed pair's line, a pair's earlier line where a later one supersedes
/// it (the last line of a pair says what became of it). A line that is not one of ours is an
/// error.
fn earlier_lines(
    path: &Path,
    bytes: &[u8],
    progress: &dyn Progress,
) -> Result<(HashMap<Key, Done>, String, bool), PairsError> {
    let mut done = HashMap::new();
    let (complete, cut) = match bytes.iter().rposition(|&b| b == b'\n') {
        Some(end) => bytes.split_at(end + 1),
        None => (&[][..], bytes),
    };
    let complete = std::str::from_utf8(complete).map_err(|e| {
        let line = 2 + complete[..e.valid_up_to()]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        PairsError::Output(format!(
            "{}:{line}: not text (a byte that is not UTF-8), so not a line of rgm's pair lists \
             (give another output file)",
            path.display()
        ))
    })?;
    let mut rewrite = !cut.is_empty();
    if rewrite {
        progress.note(&format!(
            "{}: the last line was cut off (a killed run?); its pair runs again",
            path.display()
        ));
    }
    // Each pair's last line, by its place among the lines.
    let mut last: HashMap<Key, (usize, &str)> = HashMap::new();
    for (i, line) in complete.lines().enumerate() {
        let at = || format!("{}:{}", path.display(), i + 2);
        if line.trim().is_empty() {
            rewrite = true;
            continue;
        }
        let value: Value = serde_json::from_str(line).map_err(|_| {
            PairsError::Output(format!(
                "{}: not a line of rgm's pair lists (give another output file): `{}`",
                at(),
                shortened(line)
            ))
        })?;
        let (Some(source), Some(target)) = (value["source"].as_str(), value["target"].as_str())
        else {
            return Err(PairsError::Output(format!(
                "{}: a line without \"source\" and \"target\" is not one of rgm's pair lists (give \
                 another output file): `{}`",
                at(),
                shortened(line)
            )));
        };
        let key = (source.to_string(), target.to_string());
        if value.get("error").is_some() {
            rewrite = true;
            done.remove(&key);
            last.remove(&key);
            continue;
        }
        let outcome = if value["registered"] == true {
            Outcome::Registered
        } else {
            Outcome::NotRegistered
        };
        let inputs = value.get("inputs").cloned().unwrap_or(Value::Null);
        rewrite |= done.insert(key.clone(), Done { outcome, inputs }).is_some();
        last.insert(key, (i, line));
    }
    let mut lines: Vec<(usize, &str)> = last.into_values().collect();
    lines.sort_unstable_by_key(|&(i, _)| i);
    let mut kept = String::with_capacity(complete.len());
    for (_, line) in lines {
        kept.push_str(line);
        kept.push('\n');
    }
    Ok((done, kept, rewrite))
}
