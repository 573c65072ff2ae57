//! `cargo xtask reproduce-tables`: the paper's Tables 1–5 on ModelNet40 from this project's own
//! runs — ICP, FGR and every trained RGM model of the weights manifest on the clean, noise,
//! partial and unseen-category test pairs — written to `docs/results.md` with per-pair records
//! and figures.
//!
//! Resumable ([`rgm_model::evaluate::Resumable`]): every finished chunk of pairs is appended to
//! its row's per-pair file at once, and a later run computes only the pairs that are missing
//! there, or every pair of a row whose inputs ([`Candidate::inputs`]) changed. The per-pair
//! files are not kept in the working tree (`.gitignore`: the tree travels to other machines and
//! must stay small); those committed earlier are in the history, and a row whose file is
//! missing starts from the one the last commit that added or changed that path holds
//! ([`restore_from_history`]). This file chooses the rows and writes the report.

use std::collections::BTreeMap;
use std::fmt::Debug;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use rgm_cli::TaskBar;
use rgm_data::{ModelNet40, PairGenerator, Setting, Shape, Split};
use rgm_model::evaluate::{Resumable, TestPairs};
use rgm_model::policy::TUNED;
use rgm_model::weights::{weights_dir, Manifest, ModelEntry, Variant, WeightsFile};
use rgm_model::{Method, MethodName, MethodOptions, PairRecord, Registrar};
use rgm_registration::compose::Normalised;
use rgm_registration::methods::refine::{self, RefineConfig};
use rgm_registration::refiner::Refiner;
use rgm_registration::registrar::MethodId;
use rgm_viz::{correct_fraction, correspondence_figure, registration_figure};

use crate::project_root;
use report::Report;

mod report;

/// Options of `cargo xtask reproduce-tables`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The ModelNet40 `.npy` tree [default: ../shared/data/modelnet40_npy1024 beside the
    /// repository].
    #[arg(long, env = "RGM_DATA", value_name = "DIR")]
    data: Option<PathBuf>,
    /// Only the first N test pairs of every setting: a quick look, written under
    /// target/reproduce-tables/limit-N/ so that docs/ keeps the full tables.
    #[arg(long, value_name = "N")]
    limit: Option<usize>,
    /// Only these rows (`icp`, `fgr`, `fgr+refine`, `auto+refine` or a model of the manifest, which
    /// brings its `+refine` row): a new model's rows without recomputing the others' missing
    /// pairs. Written under target/reproduce-tables/ unless --out says otherwise. A name of
    /// before issue 58 (`fgr+icp`, `auto+icp`) is read as today's (`fgr+refine`, `auto+refine`).
    #[arg(long, value_delimiter = ',', value_name = "NAME,NAME", value_parser = row_name)]
    only: Vec<String>,
    /// Where results.md, results/ and figures/ go [default: docs/, or
    /// target/reproduce-tables/limit-N[-only-NAMES]/ with --limit or --only].
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Test pairs per setting drawn as figures (the first ones).
    #[arg(long, default_value_t = 2, value_name = "N")]
    figures: usize,
    /// Start no new chunk of pairs after this many minutes; the tables then state how many
    /// pairs each row covers, and the next run carries on from there.
    #[arg(long, value_name = "MINUTES")]
    minutes: Option<f64>,
    /// Worker threads, each with its own copy of the method [default: every core].
    #[arg(long, value_name = "N")]
    threads: Option<usize>,
    /// The commit this tree is, for a copy of it without its git history (another machine);
    /// by default `git rev-parse`, marked when the code has uncommitted changes.
    #[arg(long, value_name = "REV")]
    commit: Option<String>,
    /// Compute a row whose per-pair file is missing from scratch, instead of starting from the
    /// one the git history last committed at that path.
    #[arg(long)]
    no_history: bool,
}

/// A row's name as `--only` gives it, spelled as today ([`refine::current_name`]: `fgr+icp`, the
/// name before issue 58, is `fgr+refine`).
fn row_name(name: &str) -> Result<String, std::convert::Infallible> {
    Ok(refine::current_name(name).into_owned())
}

/// One protocol of test pairs (spec §1): a setting on the whole test split or on the unseen
/// categories.
#[derive(Clone, Copy, Debug)]
struct TestSet {
    setting: Setting,
    unseen: bool,
}

impl TestSet {
    /// In the order they are computed: partial-to-partial first (the paper's headline and the
    /// ablation's setting), so that a run cut short by `--minutes` has it.
    const ALL: [TestSet; 4] = [
        TestSet::seen(Setting::Partial),
        TestSet {
            setting: Setting::Partial,
            unseen: true,
        },
        TestSet::seen(Setting::Clean),
        TestSet::seen(Setting::Noise),
    ];

    const fn seen(setting: Setting) -> Self {
        Self {
            setting,
            unseen: false,
        }
    }

    /// The name used in tables and paths: `clean`, `noise`, `partial`, `partial-unseen`.
    fn key(&self) -> String {
        format!(
            "{}{}",
            self.setting.name(),
            if self.unseen { "-unseen" } else { "" }
        )
    }
}

/// A method to evaluate and the name of its rows and files.
struct Candidate {
    /// Row name: `icp`, `fgr`, or the model's manifest name.
    name: String,
    /// Stem of its per-pair file and figures: the name, and for a model also the training
    /// pairs its weights have seen, so that retrained weights are evaluated afresh.
    stem: String,
    /// The RGM variant of a trained model; `None` for ICP and FGR.
    variant: Option<Variant>,
    /// The training pairs of a trained model.
    pairs_seen: Option<u64>,
    /// What its records depend on besides the code, kept in its per-pair file: the method's
    /// options and, for a model, its weights (by their CRC-32, since a manifest entry may
    /// point into a run whose weights move on).
    inputs: String,
    method: Method,
}

impl Candidate {
    /// The name, stem and inputs of its refined row (`<name>+refine`).
    fn refined(&self, refiner: &(impl Refiner + Debug)) -> (String, String, String) {
        let suffix = refiner.name();
        (
            format!("{}+{suffix}", self.name),
            format!("{}-{suffix}", self.stem),
            format!("{}; refined with {refiner:?}", self.inputs),
        )
    }
}

/// One row of a table: a method's records on a test set of `total` pairs.
struct Row {
    name: String,
    /// As [`Candidate::stem`].
    stem: String,
    /// As [`Candidate::variant`].
    variant: Option<Variant>,
    /// As [`Candidate::pairs_seen`].
    pairs_seen: Option<u64>,
    records: Vec<PairRecord>,
    total: usize,
    /// For an RGM model: the share of correct hard correspondences on each drawn pair, by
    /// pair index.
    matched: BTreeMap<usize, f64>,
}

/// The rows of every test set, by its key.
type Results = BTreeMap<String, Vec<Row>>;

/// Where one invocation writes, and how it evaluates (its workers, its deadline).
struct Run {
    out: PathBuf,
    limit: Option<usize>,
    evaluation: Resumable,
    /// Whether a missing per-pair file is first read back from the history.
    history: bool,
}

pub fn run(args: Args) -> Result<()> {
    let root = project_root();
    let data = args
        .data
        .clone()
        .unwrap_or_else(|| root.join("../shared/data/modelnet40_npy1024"));
    let part = [
        args.limit.map(|n| format!("limit-{n}")),
        (!args.only.is_empty()).then(|| format!("only-{}", args.only.join("-"))),
    ]
    .into_iter()
    .flatten()
    .collect::<Vec<_>>()
    .join("-");
    let out = match &args.out {
        Some(dir) => dir.clone(),
        None if part.is_empty() => root.join("docs"),
        None => root.join("target/reproduce-tables").join(part),
    };
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let run = Run {
        out,
        limit: args.limit,
        history: !args.no_history,
        evaluation: Resumable {
            pool: rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()?,
            deadline: args
                .minutes
                .map(|m| Instant::now() + Duration::from_secs_f64(60.0 * m)),
        },
    };
    let (load_before, commit_before) = (load_average(), commit(args.commit.as_deref()));
    let dataset = ModelNet40::open(&data)
        .with_context(|| format!("opening ModelNet40 at {}", data.display()))?;
    let manifest_path = weights_dir().join("manifest.json");
    let manifest = Manifest::load(&manifest_path)?;
    // Each worker runs one network: OpenBLAS must not start threads of its own under them.
    rgm_nn::threads::set_blas_threads(1);
    let mut results = Results::new();
    check_only(&manifest, &args.only)?;
    for set in TestSet::ALL {
        let shapes = test_shapes(&dataset, set, run.limit);
        let generator = PairGenerator::new(set.setting);
        let pairs = TestPairs {
            generator: &generator,
            shapes: &shapes,
        };
        let mut rows = Vec::new();
        for candidate in candidates(set, &manifest, &args.only)? {
            let records = run.evaluation.evaluate(
                &run.records_file(set, &candidate.stem)?,
                &candidate.inputs,
                &candidate.method,
                pairs,
                &TaskBar::new(format!("{} {}", set.key(), candidate.name)),
            )?;
            let matched = run.draw(set, &candidate, &records, pairs, args.figures)?;
            // A trained model refined as `rgm eval --refine` refines it, from its own
            // transforms: the refinement alone is computed.
            let refined = match candidate.variant {
                Some(_) => {
                    let config = RefineConfig::default();
                    let (name, stem, inputs) = candidate.refined(&config);
                    let records = run.evaluation.refine(
                        &run.records_file(set, &stem)?,
                        &inputs,
                        &records,
                        &config,
                        pairs,
                        &TaskBar::new(format!("{} {name}", set.key())),
                    )?;
                    run.draw_clouds(set, &stem, &records, pairs, args.figures)?;
                    Some(Row {
                        name,
                        stem,
                        variant: None,
                        pairs_seen: None,
                        records,
                        total: shapes.len(),
                        matched: BTreeMap::new(),
                    })
                }
                None => None,
            };
            rows.push(Row {
                name: candidate.name,
                stem: candidate.stem,
                variant: candidate.variant,
                pairs_seen: candidate.pairs_seen,
                records,
                total: shapes.len(),
                matched,
            });
            rows.extend(refined);
        }
        results.insert(set.key(), rows);
    }
    let report = Report {
        command: command_line(std::env::args()),
        commit: commit_before,
        threads,
        load: [load_before, load_average()],
        figures: args.figures,
        models: manifest.models,
    };
    let path = run.out.join("results.md");
    fs::write(&path, report.markdown(&results, &run.out))
        .with_context(|| format!("writing {}", path.display()))?;
    println!("wrote {}", path.display());
    Ok(())
}

/// The test shapes of `set`, cut to `limit`.
fn test_shapes(dataset: &ModelNet40, set: TestSet, limit: Option<usize>) -> Vec<&Shape> {
    let mut shapes = dataset.split(Split::Test, set.unseen);
    shapes.truncate(limit.unwrap_or(usize::MAX));
    shapes
}

/// ICP or FGR (refined when `refine`) as `rgm register --method` builds it.
/// Its row is named as the method names itself, its files with `-` for `+`.
fn classical(method: MethodName, refine: bool) -> Result<Candidate> {
    let options = MethodOptions {
        method,
        refine,
        ..MethodOptions::default()
    };
    let method = options.build()?;
    Ok(Candidate {
        name: method.name(),
        stem: method.name().replace('+', "-"),
        variant: None,
        pairs_seen: None,
        inputs: format!("{options:?}"),
        method,
    })
}

/// A model of the manifest as a row's inputs ([`Candidate::inputs`]): what it runs with and
/// its weights, read from disk.
fn model_inputs(entry: &ModelEntry) -> Result<String> {
    let path = from_history(entry)?.file.on_disk(&weights_dir())?;
    let bytes = fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
    let mut crc = flate2::Crc::new();
    crc.update(&bytes);
    Ok(format!(
        "{} ({}, preset {}, match points {:?}, {:?} statistics), weights {} of CRC-32 {:08x}",
        entry.name,
        entry.variant.name(),
        entry.preset,
        entry.match_points,
        entry.test_statistics,
        entry.file,
        crc.sum()
    ))
}

/// The name of `rgm register`'s default row (RGM and FGR, refined), known before its weights
/// are read.
fn default_row() -> String {
    MethodId {
        base: rgm_model::options::AUTO,
        refiner: Some(refine::NAME),
    }
    .to_string()
}

/// The methods of the tables of `set`: ICP and FGR (identity initialisation, Open3D's
/// settings; spec §6), on partial pairs also FGR refined by `rgm_registration::methods::refine` (the classical
/// pipeline RGM competes with there; on clean and noisy pairs FGR alone registers nearly every
/// pair, docs/results.md),
/// `rgm register`'s default (`auto+refine`: RGM with the built-in model and FGR, both refined, the
/// better by its score), then every model of the manifest trained for `set`, as the paper runs
/// it (unrefined; [`run`] adds each model refined, `<name>+refine`, from its own transforms).
///
/// Only the rows named in `only` when it is not empty: the others' methods are not even built
/// (a model's weights are not read).
fn candidates(set: TestSet, manifest: &Manifest, only: &[String]) -> Result<Vec<Candidate>> {
    let wanted = |name: &str| only.is_empty() || only.iter().any(|o| o == name);
    let mut list = vec![
        classical(MethodName::Icp, false)?,
        classical(MethodName::Fgr, false)?,
    ];
    if set.setting == Setting::Partial {
        list.push(classical(MethodName::Fgr, true)?);
    }
    // `rgm register`'s default on every test set, named by the built-in model it runs.
    if let Some(builtin) = manifest.builtin_entry().filter(|_| wanted(&default_row())) {
        let options = MethodOptions::default();
        list.push(Candidate {
            name: default_row(),
            stem: format!(
                "auto-{}-{}pairs-{}",
                builtin.name,
                builtin.pairs_seen,
                refine::NAME
            ),
            variant: None,
            pairs_seen: None,
            inputs: format!("{options:?}, built-in model {}", model_inputs(builtin)?),
            method: options.build()?,
        });
    }
    for entry in models_for(manifest, set).filter(|e| wanted(&e.name)) {
        let method = from_history(entry)?
            .registrar(&weights_dir())
            .map(|registrar| Method::new(Normalised::new(registrar, TUNED.frame)))
            .with_context(|| format!("loading the model {}", entry.name))?;
        list.push(Candidate {
            name: entry.name.clone(),
            stem: format!("{}-{}pairs", entry.name, entry.pairs_seen),
            variant: Some(entry.variant),
            pairs_seen: Some(entry.pairs_seen),
            inputs: model_inputs(entry)?,
            method,
        });
    }
    list.retain(|c| wanted(&c.name));
    Ok(list)
}

/// An error naming the rows of `only` that no test set has.
fn check_only(manifest: &Manifest, only: &[String]) -> Result<()> {
    let classical = [
        (MethodName::Icp, None),
        (MethodName::Fgr, None),
        (MethodName::Fgr, Some(refine::NAME)),
    ]
    .map(|(name, refiner)| {
        MethodId {
            base: name.name(),
            refiner,
        }
        .to_string()
    });
    let rows: Vec<String> = classical.into_iter().chain([default_row()]).collect();
    let known: Vec<&str> = rows
        .iter()
        .map(String::as_str)
        .chain(manifest.models.iter().map(|m| m.name.as_str()))
        .collect();
    let unknown: Vec<&str> = only
        .iter()
        .map(String::as_str)
        .filter(|name| !known.contains(name))
        .collect();
    anyhow::ensure!(
        unknown.is_empty(),
        "--only {}: no such row (the rows are {} and the models of the manifest)",
        unknown.join(","),
        rows.join(", ")
    );
    Ok(())
}

/// `entry` with its weights on disk: a file of the git history ([`WeightsFile::Git`]) is
/// written once to `target/git-weights/` by `git show`.
fn from_history(entry: &ModelEntry) -> Result<ModelEntry> {
    let WeightsFile::Git { revision, path } = &entry.file else {
        return Ok(entry.clone());
    };
    let dir = project_root().join("target/git-weights");
    // Named by the revision too, so that a manifest pinning the name to another commit does
    // not read the earlier extraction.
    let extracted = dir.join(format!("{}-{revision}.safetensors", entry.name));
    if !extracted.exists() {
        let object = format!("{revision}:{path}");
        let out = Command::new("git")
            .args(["show", &object])
            .current_dir(project_root())
            .output()
            .context("running git show")?;
        anyhow::ensure!(
            out.status.success(),
            "the weights of {}: git show {object} failed: {}",
            entry.name,
            String::from_utf8_lossy(&out.stderr)
        );
        fs::create_dir_all(&dir)?;
        fs::write(&extracted, out.stdout)?;
    }
    Ok(ModelEntry {
        file: WeightsFile::Path(extracted),
        ..entry.clone()
    })
}

/// The manifest's models trained for `set`'s setting and categories.
fn models_for(manifest: &Manifest, set: TestSet) -> impl Iterator<Item = &ModelEntry> {
    manifest
        .models
        .iter()
        .filter(move |m| m.setting == set.setting && m.unseen == set.unseen)
}

impl Run {
    /// The per-pair file of one method on one test set, to resume from: when it is missing,
    /// the one the history last committed at its path is written there first (unless
    /// `--no-history`), or, for a refined row the history holds only under its stem of before
    /// issue 58 ([`older_stem`]: `fgr-icp`), that one.
    fn records_file(&self, set: TestSet, stem: &str) -> Result<PathBuf> {
        let path = records_path(&self.out, set, stem);
        if self.history && !path.exists() {
            let root = project_root();
            let restored = match restore_from_history(&root, &path)? {
                Some(revision) => Some(revision),
                None => match older_stem(stem) {
                    Some(old) => {
                        let held = records_path(&self.out, set, &old);
                        restore_renamed_from_history(&root, &held, &path)?
                            .map(|revision| format!("{revision} ({old}.jsonl.gz there)"))
                    }
                    None => None,
                },
            };
            if let Some(revision) = restored {
                println!("{}: read back from commit {revision}", path.display());
            }
        }
        Ok(path)
    }

    /// For the first `count` pairs: the clouds before and after `candidate`'s transform
    /// ([`Run::draw_clouds`]) and, for an RGM model, its hard correspondences (the pair is
    /// registered again for them). Returns the share of correct hard correspondences of each
    /// pair drawn for an RGM model.
    fn draw(
        &self,
        set: TestSet,
        candidate: &Candidate,
        records: &[PairRecord],
        pairs: TestPairs,
        count: usize,
    ) -> Result<BTreeMap<usize, f64>> {
        self.draw_clouds(set, &candidate.stem, records, pairs, count)?;
        let mut matched = BTreeMap::new();
        // The network's correspondences; a refined model's are its plain twin's.
        if candidate.method.id().base != rgm_model::procedure::NAME || candidate.method.is_refined()
        {
            return Ok(matched);
        }
        let dir = self.out.join("figures").join(set.key());
        for record in records.iter().take(count) {
            let i = record.index;
            let pair = pairs.pair(i)?;
            let mut method = candidate.method.clone();
            // A failure leaves no correspondences: an empty matrix, 0 % correct.
            let found = method
                .register(&pair.source, &pair.target)
                .map(|found| found.correspondences)
                .unwrap_or_default();
            let found = &found[..];
            correspondence_figure(&pair.correspondence, found, 36)?
                .write_png(dir.join(format!("{}-matrix-pair{i}.png", candidate.stem)))?;
            matched.insert(i, correct_fraction(&pair.correspondence, found));
        }
        Ok(matched)
    }

    /// For the first `count` pairs: the clouds before and after the transform of the method
    /// whose files are named `stem`, and the pair's ground-truth correspondence matrix.
    /// Existing pictures are kept.
    fn draw_clouds(
        &self,
        set: TestSet,
        stem: &str,
        records: &[PairRecord],
        pairs: TestPairs,
        count: usize,
    ) -> Result<()> {
        let dir = self.out.join("figures").join(set.key());
        fs::create_dir_all(&dir)?;
        for record in records.iter().take(count) {
            let i = record.index;
            let pair = pairs.pair(i)?;
            let clouds = dir.join(format!("{stem}-pair{i}.png"));
            if !clouds.exists() {
                registration_figure(&pair.source, &pair.target, &record.transform)?
                    .write_png(&clouds)?;
            }
            let truth = dir.join(format!("truth-pair{i}.png"));
            if !truth.exists() {
                correspondence_figure(&pair.correspondence, &pair.correspondence.pairs, 36)?
                    .write_png(&truth)?;
            }
        }
        Ok(())
    }
}

/// The per-pair file of one row on one test set in the results folder `out`: gzip'd JSON
/// lines ([`rgm_model::evaluate::Resumable`]).
fn records_path(out: &Path, set: TestSet, stem: &str) -> PathBuf {
    out.join("results")
        .join(set.key())
        .join(format!("{stem}.jsonl.gz"))
}

/// The stem a refined row's per-pair file had before issue 58 renamed the refinement
/// (`fgr-refine` was `fgr-icp`, `partial-fast-755305pairs-refine` was
/// `partial-fast-755305pairs-icp`); `None` for a row that is not refined.
fn older_stem(stem: &str) -> Option<String> {
    let base = stem.strip_suffix(&format!("-{}", refine::NAME))?;
    Some(format!("{base}-{}", refine::OLD_NAME))
}

/// Writes the file `path` of the repository at `root` as the last commit that added or changed
/// it holds it (a per-pair file removed from the tree since), and returns that commit; `None`,
/// writing nothing, when no commit holds the path, `path` is outside the repository, or git
/// cannot tell (a copy of the tree without its history; a shallow clone that lacks the commit).
fn restore_from_history(root: &Path, path: &Path) -> Result<Option<String>> {
    restore_renamed_from_history(root, path, path)
}

/// [`restore_from_history`] of the file the history held at `held`, written to `path` (the
/// same file under its older name).
fn restore_renamed_from_history(root: &Path, held: &Path, path: &Path) -> Result<Option<String>> {
    let (Some(folder), Some(held_folder), Some(name)) =
        (path.parent(), held.parent(), held.file_name())
    else {
        return Ok(None);
    };
    // The folder the file goes to is made anyway (the evaluation writes there); canonical
    // paths, so that a relative --out and the root compare.
    fs::create_dir_all(folder).with_context(|| format!("creating {}", folder.display()))?;
    let (Ok(root), Ok(folder)) = (fs::canonicalize(root), fs::canonicalize(held_folder)) else {
        return Ok(None);
    };
    let Ok(relative) = folder.strip_prefix(&root) else {
        return Ok(None);
    };
    let Some(relative) = relative.join(name).to_str().map(|p| p.replace('\\', "/")) else {
        return Ok(None);
    };
    let git = |args: &[&str]| {
        Command::new("git")
            .args(args)
            .current_dir(&root)
            .output()
            .ok()
            .filter(|out| out.status.success())
            .map(|out| out.stdout)
    };
    let last = [
        "log",
        "-1",
        "--format=%h",
        "--diff-filter=AMRC",
        "--",
        &relative,
    ];
    let Some(revision) = git(&last).map(|out| String::from_utf8_lossy(&out).trim().to_string())
    else {
        return Ok(None);
    };
    if revision.is_empty() {
        return Ok(None);
    }
    let Some(bytes) = git(&["show", &format!("{revision}:{relative}")]) else {
        return Ok(None);
    };
    rgm_data::durable::replace(path, |out| out.write_all(&bytes))
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(Some(revision))
}

/// The 1-minute load average from /proc/loadavg (how busy the machine was).
fn load_average() -> Option<f64> {
    fs::read_to_string("/proc/loadavg")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// The command as typed (`args`: the process's arguments, the program first), for the report:
/// `cargo xtask` and the arguments, quoted for a shell where they need it.
fn command_line(args: impl Iterator<Item = String>) -> String {
    let quoted = args.skip(1).map(|arg| {
        let plain = !arg.is_empty()
            && arg
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "-_./,=:+@%".contains(c));
        if plain {
            arg
        } else {
            format!("'{}'", arg.replace('\'', r"'\''"))
        }
    });
    std::iter::once("cargo xtask".to_string())
        .chain(quoted)
        .collect::<Vec<_>>()
        .join(" ")
}

/// The commit the tables were made at (`given`, or git's), marked when the working tree
/// differs from it.
fn commit(given: Option<&str>) -> String {
    if let Some(rev) = given {
        return format!("`{rev}` (a copy of its tree, without git)");
    }
    let git = |args: &[&str]| {
        Command::new("git")
            .args(args)
            .current_dir(project_root())
            .output()
            .ok()
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
            .unwrap_or_default()
    };
    let hash = git(&["rev-parse", "--short", "HEAD"]);
    let dirty = !git(&[
        "status",
        "--porcelain",
        "--",
        "crates",
        "xtask",
        "Cargo.lock",
    ])
    .is_empty();
    format!(
        "`{hash}`{}",
        if dirty {
            " (with uncommitted changes to the code)"
        } else {
            ""
        }
    )
}

#[cfg(test)]
mod tests;
