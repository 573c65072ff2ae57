//! `rgm register --pairs LIST`: every pair of a list registered on parallel workers, one JSON
//! line each, resumable.
//!
//! Resuming: each line names its pair by `source` and `target` as LIST spells them. A rerun on
//! the same `--output` keeps the lines of finished pairs and registers the other pairs. It drops
//! a cut-off last line (a killed run), the lines of pairs that failed (they are tried again) and
//! repeated pairs, by rewriting the file whole (temporary file and rename) before it appends,
//! so the file never holds a pair twice. Lines are appended one `write` each, as pairs finish.

use std::collections::{HashMap, HashSet};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use rgm_model::{Method, Registrar};

use crate::{MethodArgs, WorkerArgs};

/// The batch options of `rgm register`.
#[derive(clap::Args, Debug)]
#[command(next_help_heading = "Batches")]
pub struct BatchArgs {
    /// Register every pair of LIST instead of SOURCE TARGET, all cores busy (--workers), and
    /// write one JSON line per pair.
    ///
    /// Each line is the object --json prints for the pair, with the pair's "source" and
    /// "target" as LIST spells them; a pair that could not be registered (a file that cannot
    /// be read, a method that fails) gets {"source", "target", "method", "error"} instead, and
    /// the others go on. LIST is CSV whose header names the columns `source` and `target` (in
    /// any order; other columns are ignored, `#` lines are comments, a field in double quotes
    /// may hold commas), or JSON: a list of {"source": FILE, "target": FILE}, or an object
    /// whose "pairs" is one (the pairs.json of `rgm pairs`). Relative paths are relative to
    /// LIST's folder. A pair listed twice runs once. Lines come in the order pairs finish. The
    /// summary goes to stderr; the exit status is 1 when any pair failed or was not registered.
    #[arg(long, value_name = "LIST")]
    pairs: Option<PathBuf>,
    /// Write the lines of --pairs to FILE (JSON Lines) instead of stdout, resumably: a run on
    /// a FILE that holds lines already registers only the pairs it has no line for (a killed
    /// run's cut-off last line, and pairs that failed, are done again); a FILE of another
    /// method is refused.
    #[arg(long, value_name = "FILE", requires = "pairs")]
    output: Option<PathBuf>,
    #[command(flatten)]
    workers: WorkerArgs,
}

impl BatchArgs {
    /// The refusal of the batch options when SOURCE TARGET name one pair.
    pub fn refuse_without_pairs(&self) -> Result<()> {
        if self.workers.workers.is_some() {
            bail!("--workers applies to --pairs LIST; one pair runs on one thread");
        }
        Ok(())
    }
}

/// One pair of LIST.
#[derive(Debug)]
struct Listed {
    /// The files as LIST spells them: the pair's name in the output.
    source: String,
    target: String,
    /// The files, relative paths taken from LIST's folder.
    source_path: PathBuf,
    target_path: PathBuf,
}

impl Listed {
    fn key(&self) -> (&str, &str) {
        (&self.source, &self.target)
    }
}

/// What became of a pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Outcome {
    Registered,
    /// A result with a doubt ([`rgm_model::Registration::doubt`]), `"registered": false`.
    NotRegistered,
    Failed,
}

pub fn run(args: &BatchArgs, method: &MethodArgs) -> Result<()> {
    let list = args
        .pairs
        .as_deref()
        .context("SOURCE and TARGET name one pair, --pairs LIST many")?;
    let method = method.build(crate::Defaults::Register)?;
    let listed = read_list(list)?;
    let mut done: HashMap<(String, String), Outcome> = HashMap::new();
    let sink: Box<dyn Write + Send> = match &args.output {
        Some(output) => {
            crate::check_writable(output)?;
            done = earlier_lines(output, &method.name())?;
            Box::new(
                std::fs::OpenOptions::new()
                    .create(true)
                    .append(true)
                    .open(output)
                    .with_context(|| format!("opening {}", output.display()))?,
            )
        }
        None => Box::new(std::io::stdout()),
    };
    let todo: Vec<&Listed> = listed
        .iter()
        .filter(|p| !done.contains_key(&(p.source.clone(), p.target.clone())))
        .collect();
    if let (Some(output), false) = (&args.output, done.is_empty()) {
        eprintln!(
            "rgm: {} of the {} pairs have their line in {} already; registering {}",
            listed.len() - todo.len(),
            listed.len(),
            output.display(),
            todo.len()
        );
    }
    let bar = crate::progress(todo.len(), &method.name());
    let failed = AtomicUsize::new(0);
    let sink = Mutex::new(sink);
    let pool = args.workers.pool()?;
    let outcomes: Vec<Outcome> = pool.install(|| {
        todo.par_iter()
            .map_init(
                || method.clone(),
                |method, pair| -> Result<Outcome> {
                    let (line, outcome) = register(method, pair, &bar);
                    let mut out = sink.lock().unwrap_or_else(|p| p.into_inner());
                    out.write_all(format!("{line}\n").as_bytes())
                        .and_then(|()| out.flush())
                        .with_context(|| match &args.output {
                            Some(output) => format!("writing {}", output.display()),
                            None => "writing to stdout".into(),
                        })?;
                    drop(out);
                    if outcome == Outcome::Failed {
                        let n = failed.fetch_add(1, Ordering::Relaxed) + 1;
                        bar.set_message(format!("{n} failed"));
                    }
                    bar.inc(1);
                    Ok(outcome)
                },
            )
            .collect::<Result<_>>()
    })?;
    bar.finish_and_clear();
    let listed_keys: HashSet<(&str, &str)> = listed.iter().map(Listed::key).collect();
    let earlier = done
        .iter()
        .filter(|(k, _)| listed_keys.contains(&(k.0.as_str(), k.1.as_str())))
        .map(|(_, &o)| o);
    let all: Vec<Outcome> = earlier.chain(outcomes).collect();
    let count = |o: Outcome| all.iter().filter(|&&x| x == o).count();
    let (failed, doubted) = (count(Outcome::Failed), count(Outcome::NotRegistered));
    let written = args
        .output
        .as_ref()
        .map_or("stdout".into(), |o| o.display().to_string());
    eprintln!(
        "rgm: {} pairs: {} registered, {doubted} not registered, {failed} failed (lines in {written})",
        all.len(),
        count(Outcome::Registered),
    );
    if failed + doubted > 0 {
        bail!(
            "of {} pairs, {failed} failed and {doubted} were not registered; their lines in \
             {written} say why",
            all.len()
        );
    }
    Ok(())
}

/// The pair's JSON line and its outcome; a failure is a line with its `"error"`.
fn register(method: &mut Method, pair: &Listed, bar: &indicatif::ProgressBar) -> (String, Outcome) {
    let read = |path: &Path| -> Result<rgm_geom::PointCloud> {
        let (cloud, warnings) = rgm_data::read_point_cloud_warned(path)?;
        for warning in warnings {
            bar.suspend(|| eprintln!("rgm: {warning}"));
        }
        Ok(cloud)
    };
    let registered = (|| -> Result<serde_json::Value> {
        let source = read(&pair.source_path)?;
        let target = read(&pair.target_path)?;
        let registration = method.register(&source, &target).map_err(|e| {
            crate::method_failure(e, &method.name(), (&pair.source_path, &pair.target_path))
        })?;
        Ok(super::register::json(
            method,
            &registration,
            (source.len(), target.len()),
        ))
    })();
    let (mut value, outcome) = match registered {
        Ok(value) if value["registered"] == true => (value, Outcome::Registered),
        Ok(value) => (value, Outcome::NotRegistered),
        Err(err) => (
            serde_json::json!({"method": method.name(), "error": crate::error_message(&err)}),
            Outcome::Failed,
        ),
    };
    value["source"] = pair.source.clone().into();
    value["target"] = pair.target.clone().into();
    (value.to_string(), outcome)
}

/// The pairs of LIST, CSV or JSON (by its first character), a repeated pair once.
fn read_list(path: &Path) -> Result<Vec<Listed>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let folder = path.parent().unwrap_or(Path::new(""));
    let named = if text.trim_start().starts_with(['[', '{']) {
        json_list(path, text)?
    } else {
        csv_list(path, text)?
    };
    let mut first: HashMap<(String, String), String> = HashMap::new();
    let mut pairs = Vec::with_capacity(named.len());
    for (source, target, place) in named {
        let key = (source.clone(), target.clone());
        if let Some(earlier) = first.get(&key) {
            eprintln!(
                "rgm: {place} repeats the pair of {earlier} ({source}, {target}); it runs once"
            );
            continue;
        }
        first.insert(key, place);
        pairs.push(Listed {
            source_path: folder.join(&source),
            target_path: folder.join(&target),
            source,
            target,
        });
    }
    if pairs.is_empty() {
        bail!("{}: no pair listed", path.display());
    }
    Ok(pairs)
}

/// (source, target, place) of each row of a CSV list.
fn csv_list(path: &Path, text: &str) -> Result<Vec<(String, String, String)>> {
    let mut rows = text
        .lines()
        .enumerate()
        .map(|(i, line)| (i + 1, line))
        .filter(|(_, line)| !line.trim().is_empty() && !line.trim_start().starts_with('#'));
    let at = |n: usize| format!("{}:{n}", path.display());
    let Some((n, header)) = rows.next() else {
        bail!("{}: no header line `source,target`", path.display());
    };
    let names =
        csv_fields(header).map_err(|why| anyhow::anyhow!("{}: {why}: `{header}`", at(n)))?;
    let column = |name: &str| names.iter().position(|h| h.eq_ignore_ascii_case(name));
    let (Some(s), Some(t)) = (column("source"), column("target")) else {
        bail!(
            "{}: the header must name the columns `source` and `target`: `{header}`",
            at(n)
        );
    };
    let mut pairs = Vec::new();
    for (n, line) in rows {
        let fields =
            csv_fields(line).map_err(|why| anyhow::anyhow!("{}: {why}: `{line}`", at(n)))?;
        let get = |k: usize, name: &str| match fields.get(k) {
            Some(f) if !f.is_empty() => Ok(f.clone()),
            _ => Err(anyhow::anyhow!(
                "{}: no {name} file (column {}): `{line}`",
                at(n),
                k + 1
            )),
        };
        pairs.push((get(s, "source")?, get(t, "target")?, at(n)));
    }
    Ok(pairs)
}

/// The comma-separated fields of a CSV line, trimmed; a field in double quotes may hold commas,
/// and `""` inside it is one quote.
fn csv_fields(line: &str) -> Result<Vec<String>, &'static str> {
    let mut fields = Vec::new();
    let mut chars = line.chars().peekable();
    loop {
        while chars.peek().is_some_and(|c| c.is_whitespace()) {
            chars.next();
        }
        let mut field = String::new();
        if chars.peek() == Some(&'"') {
            chars.next();
            loop {
                match chars.next() {
                    Some('"') if chars.peek() == Some(&'"') => {
                        chars.next();
                        field.push('"');
                    }
                    Some('"') => break,
                    Some(c) => field.push(c),
                    None => return Err("a quoted field has no closing quote"),
                }
            }
            while chars.peek().is_some_and(|c| c.is_whitespace()) {
                chars.next();
            }
            if !matches!(chars.peek(), None | Some(',')) {
                return Err("text after a quoted field");
            }
        } else {
            while let Some(&c) = chars.peek() {
                if c == ',' {
                    break;
                }
                field.push(c);
                chars.next();
            }
            field = field.trim_end().to_string();
        }
        fields.push(field);
        if chars.next().is_none() {
            return Ok(fields);
        }
    }
}

/// (source, target, place) of each entry of a JSON list.
fn json_list(path: &Path, text: &str) -> Result<Vec<(String, String, String)>> {
    let value: serde_json::Value = serde_json::from_str(text)
        .with_context(|| format!("{}: not valid JSON", path.display()))?;
    let entries = value
        .as_array()
        .or_else(|| value.get("pairs").and_then(serde_json::Value::as_array))
        .with_context(|| {
            format!(
                "{}: a JSON list of pairs is a list of {{\"source\": FILE, \"target\": FILE}}, \
                 or an object whose \"pairs\" is one",
                path.display()
            )
        })?;
    entries
        .iter()
        .enumerate()
        .map(|(i, entry)| {
            let place = format!("{} entry {}", path.display(), i + 1);
            let get = |name: &str| match entry.get(name) {
                Some(serde_json::Value::String(file)) if !file.is_empty() => Ok(file.clone()),
                _ => Err(anyhow::anyhow!(
                    "{place}: no \"{name}\" file name: `{}`",
                    shortened(&entry.to_string())
                )),
            };
            Ok((get("source")?, get("target")?, place))
        })
        .collect()
}

/// The outcome of each pair an earlier run finished in `output` (a JSON Lines file of
/// `--pairs`), after rewriting it without what is to be done again (see the module's doc).
/// A line that is not one of ours, or of another method, is an error: the file is not ours to
/// change.
fn earlier_lines(output: &Path, method: &str) -> Result<HashMap<(String, String), Outcome>> {
    let mut done = HashMap::new();
    if !output.is_file() {
        return Ok(done);
    }
    let text =
        std::fs::read_to_string(output).with_context(|| format!("reading {}", output.display()))?;
    let (complete, cut) = match text.rfind('\n') {
        Some(end) => text.split_at(end + 1),
        None => ("", text.as_str()),
    };
    let mut rewrite = !cut.is_empty();
    if rewrite {
        eprintln!(
            "rgm: {}: the last line was cut off (a killed run?); its pair runs again",
            output.display()
        );
    }
    let mut kept = String::with_capacity(complete.len());
    for (i, line) in complete.lines().enumerate() {
        let at = || format!("{}:{}", output.display(), i + 1);
        if line.trim().is_empty() {
            rewrite = true;
            continue;
        }
        let value: serde_json::Value = serde_json::from_str(line).map_err(|_| {
            anyhow::anyhow!(
                "{}: not a line of `rgm register --pairs` (give another --output): `{}`",
                at(),
                shortened(line)
            )
        })?;
        let (Some(source), Some(target)) = (value["source"].as_str(), value["target"].as_str())
        else {
            bail!(
                "{}: a line without \"source\" and \"target\" is not one of `rgm register \
                 --pairs` (give another --output): `{}`",
                at(),
                shortened(line)
            );
        };
        if value["method"] != method {
            bail!(
                "{}: a result of method {}, not of this run's {method} (give another --output)",
                at(),
                value["method"]
            );
        }
        let key = (source.to_string(), target.to_string());
        if value.get("error").is_some() || done.contains_key(&key) {
            rewrite = true;
            continue;
        }
        let outcome = if value["registered"] == true {
            Outcome::Registered
        } else {
            Outcome::NotRegistered
        };
        done.insert(key, outcome);
        kept.push_str(line);
        kept.push('\n');
    }
    if rewrite {
        crate::write_text(output, &kept)?;
    }
    Ok(done)
}

/// `text` cut to its first 120 characters, for messages.
fn shortened(text: &str) -> String {
    match text.char_indices().nth(120) {
        Some((end, _)) => format!("{}…", &text[..end]),
        None => text.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_fields_split_on_commas_outside_quotes() {
        assert_eq!(csv_fields(" a.ply , b.ply").unwrap(), ["a.ply", "b.ply"]);
        assert_eq!(
            csv_fields(r#""x, y.ply", "say ""hi"".ply",,z"#).unwrap(),
            ["x, y.ply", r#"say "hi".ply"#, "", "z"]
        );
        assert_eq!(
            csv_fields(r#""open"#),
            Err("a quoted field has no closing quote")
        );
        assert_eq!(csv_fields(r#""a"b,c"#), Err("text after a quoted field"));
    }
}
