//! `rgm` — register two point clouds, or evaluate registration methods on ModelNet40.
//!
//! Layering rule: the command is a thin shell over rgm-model (methods, evaluation) and rgm-data
//! (files, pairs); it owns argument parsing, progress and printing, and no algorithm.

mod commands;
mod table;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand};
pub use rgm_cli::progress;
use rgm_data::{
    ModelNet40, PairGenerator, ScanFolder, ScanPair, ScanPairConfig, Setting, Shape, Split,
};
use rgm_model::network::TestStatistics;
use rgm_model::{Method, MethodName, MethodOptions, Registrar};
use rgm_nn::Precision;
use rgm_registration::methods::refine::RefineConfig;

/// Robust point-cloud registration (RGM, CVPR 2021) and classical baselines.
#[derive(Parser, Debug)]
#[command(name = "rgm", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Threads one command may use: `rgm register` runs the network's attention on them (and
    /// both candidates side by side with --accept inf), and `--workers` of `register --pairs`
    /// and `rgm eval` defaults to it
    /// (`rgm train` has its own --workers); more than 4 per core are cut to 4 per core [default:
    /// one per core; the `RAYON_NUM_THREADS` variable sets it too].
    #[arg(long, global = true, value_name = "N", value_parser = clap::value_parser!(u16).range(1..))]
    threads: Option<u16>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Find the rigid transform that maps SRC onto TGT and print it as a 4×4 matrix.
    ///
    /// By default (--method auto) runs FGR, refined with ICP, and where its result overlaps
    /// too little or, short of a whole overlap, fits as well turned about one of the source's
    /// axes (--accept) also RGM,
    /// with the partial-to-partial model built into rgm (or --weights), refined the same way,
    /// and returns the one whose result overlaps better; the output names the candidates and
    /// their scores. --method rgm, fgr or icp runs one method; --no-refine skips the
    /// refinement; docs/results.md compares them. Clouds of any size, scale and density:
    /// unless already in the unit-sphere frame, both are centred and scaled by one factor into
    /// it, clouds denser than ModelNet40's 1,024 points are thinned to 1,024 (a second way,
    /// its candidates named …/cells, when no result of the first is taken and the candidates
    /// disagree), RGM matches on 256 random points of each (--method rgm: every point), and the
    /// transform is reported for the clouds as given.
    /// The winner on a thinned pair is refined further on the clouds as given, point to plane
    /// at their own point spacing. Reads the formats SRC's help lists, gzip-compressed ones too
    /// (`scan.ply.gz`).
    Register(commands::register::Args),
    /// Run a method over the ModelNet40 test pairs and print the paper's metrics, or over real
    /// scan pairs (--scans) and print successes, median errors and time.
    Eval(commands::eval::Args),
    /// Write the ModelNet40 test pairs, or real scan pairs (--scans), as PLY files and
    /// ground-truth JSON for outside tools.
    Pairs(commands::pairs::Args),
    /// Score transforms produced by an outside tool on the pairs written by `rgm pairs`.
    ///
    /// The transforms file is JSON: {"method": NAME, "pairs": [{"index": I, "transform":
    /// [[4 numbers] × 4 rows], "time_ms": T}, …]}, one entry per pair index of the pairs folder;
    /// `tools/open3d/register_pairs.py` writes one for Open3D.
    Score(commands::score::Args),
    /// Train the RGM network on ModelNet40 pairs; resumes an interrupted run in --out.
    ///
    /// Writes checkpoints, best.safetensors and log.jsonl (one JSON line per checkpoint and per
    /// validation) into the run folder.
    Train(commands::train::Args),
    /// Draw SRC and TGT before and after a registration (PNG): a given transform or a method's.
    Render(commands::render::Args),
    /// Put every scan of an object (or a room) into one frame, with no initial poses.
    ///
    /// Every pair of scans is registered by `rgm register`'s method (--method etc. change it);
    /// results it doubts are left out, wrong ones found by cycles of three that do not close,
    /// and the poses solved as a pose graph from the maximum spanning tree of the pairs'
    /// fitness, then refined by multiway ICP (each scan against the union of the others, at
    /// the scans' own point spacing). Scans that hang together form a component, each merged
    /// on its own; a scan no trusted pair links is left unplaced and named. Writes
    /// DIR/poses.json ({"scans", "poses": 4×4 model ← scan or null, "registered", "component",
    /// "residual": median point-to-plane distance to the other scans, "edges": every pair,
    /// used or why not}), DIR/poses.conf (Stanford's `bmesh NAME tx ty tz qx qy qz qw` lines of
    /// the largest component, p_model = R(q)ᵀ·p + t) and DIR/model.ply (the largest
    /// component's scans in one frame, one point per --voxel cube, a `scan` property giving
    /// each point's scan by its place in the list). Fails when no pair of the scans could be
    /// registered (the files written first).
    Merge(commands::merge::Args),
}

/// `precision`, after saying on stderr when bf16 falls back to f32 on this processor.
pub fn checked_precision(precision: Precision) -> Precision {
    if precision == Precision::Bf16 && !rgm_nn::gemm::bf16_available() {
        eprintln!(
            "--precision bf16: this processor has neither AMX nor AVX-512 BF16; products run in \
             f32"
        );
    }
    precision
}

/// The method and, for RGM, its weights and test-time options.
#[derive(clap::Args, Debug, Clone)]
pub struct MethodArgs {
    /// The registration method [default: auto in `rgm register` and `rgm render`; rgm, the
    /// paper's method, in `rgm eval`]. RGM uses the model built into rgm unless --weights names
    /// another.
    #[arg(long, value_enum)]
    method: Option<MethodName>,
    /// RGM weights: a safetensors file with the authors' parameter names
    /// (`tools/reference/rgm_reference.py` documents them). Without it, RGM uses the model
    /// built into rgm (crates/rgm-model/weights/manifest.json describes it).
    #[arg(long, value_name = "FILE")]
    weights: Option<PathBuf>,
    /// The network sizes --weights were trained with: paper, small, fast or tiny.
    #[arg(long, value_name = "NAME", requires = "weights")]
    preset: Option<String>,
    /// Batch-norm statistics for --weights: cloud for weights trained by `rgm train`, running
    /// for the authors' PyTorch weights [default: running; the built-in model's own otherwise].
    #[arg(long, value_enum, value_name = "WHICH", requires = "weights")]
    test_statistics: Option<TestStatistics>,
    /// RGM matches on at most N randomly drawn points of each cloud (fixed seed) and applies
    /// the transform to the full clouds; 0 matches on every point. The network's memory grows
    /// with the square of N (about 0.7 GB at 1,024 points, 2.7 GB at 2,048 for the paper's
    /// sizes), and a request beyond the machine's free memory is refused [default: the
    /// built-in model's every point, as the paper tests it (chosen on validation pairs), or 256
    /// as the auto cascade's second stage; 1,024 with --weights, the paper's training size].
    #[arg(long, value_name = "N")]
    match_points: Option<usize>,
    /// RGM's passes of network → matching → Kabsch, each on the source moved by the passes
    /// before [default: 2, as in the paper's tables].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..))]
    passes: Option<u16>,
    // Help from `refine_help`: the distances are RefineConfig's defaults.
    #[arg(long, overrides_with = "no_refine", help = refine_help())]
    refine: bool,
    /// Report the method's own transform, unrefined (as the paper's tables do).
    #[arg(long, overrides_with = "refine")]
    no_refine: bool,
    /// RGM's matrix products: f32, or bf16 (inputs rounded to bfloat16, f32 accumulation:
    /// faster where the processor has AMX tile units or AVX-512 BF16; the rest of the network
    /// stays f32).
    #[arg(long, value_name = "f32|bf16", default_value_t = MethodOptions::default().precision)]
    precision: Precision,
    /// auto: take FGR's result without running the network when its overlap score (both
    /// clouds' share of points on the other, 0 to 2) reaches SCORE and the shape does not fit as
    /// well turned about one of its axes (or the clouds lie wholly on each other); `inf` runs
    /// both methods on every pair (slower).
    #[arg(long, value_name = "SCORE", default_value_t = MethodOptions::default().accept)]
    accept: f64,
}

/// The help of --refine, with the distances of [`RefineConfig::default`].
fn refine_help() -> String {
    let refine = RefineConfig::default();
    let then = |distances: &[f64]| {
        let d: Vec<String> = distances.iter().map(f64::to_string).collect();
        d.join(", then ")
    };
    format!(
        "Refine the transform of RGM or FGR (both with auto) with ICP on the full clouds: \
         trimmed point-to-plane with pairs closer than {}, and point-to-point at {} (RGM and \
         auto measure them in the unit-sphere frame, FGR alone in the clouds' own units, like \
         its own radii, which suit unit-sized shapes); with auto on clouds denser than 1,024 \
         points, then point-to-plane on the clouds as given at a few point spacings and at 3 \
         noise σ (rgm_registration::methods::refine::refine_at_resolution). On by default in `rgm register` and \
         `rgm render`; `rgm eval` follows the paper's protocol and refines only when asked",
        then(&refine.distances),
        then(&refine.point_distances)
    )
}

/// What a command runs when the options leave it open.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Defaults {
    /// `rgm register`'s: [`MethodOptions::default`], FGR and RGM as a cascade, refined.
    Register,
    /// The paper's protocol (`rgm eval`): RGM, unrefined.
    Paper,
}

impl MethodArgs {
    /// The method these options select, with its weights loaded ([`Self::options`] built).
    fn build(&self, defaults: Defaults) -> anyhow::Result<Method> {
        Ok(self.options(defaults)?.build()?)
    }

    /// The options of the method these select: refined when --refine is given, or by
    /// `defaults` unless --no-refine is (ICP is its own refinement). `rgm_model::MethodOptions`
    /// builds the method, as it does for the Python package.
    fn options(&self, defaults: Defaults) -> anyhow::Result<MethodOptions> {
        let refine_by_default = defaults == Defaults::Register;
        let method = match self.method {
            Some(method) => method,
            None if refine_by_default => MethodOptions::default().method,
            None => MethodName::Rgm,
        };
        if method == MethodName::Icp && self.refine {
            anyhow::bail!("--refine adds ICP after RGM or FGR; --method icp is ICP already");
        }
        let refine = self.refine || (refine_by_default && !self.no_refine);
        let options = MethodOptions {
            method,
            weights: self.weights.clone(),
            preset: self.preset.clone(),
            test_statistics: self.test_statistics,
            match_points: self.match_points,
            passes: self.passes.map(usize::from),
            precision: checked_precision(self.precision),
            refine,
            accept: self.accept,
        };
        Ok(options)
    }
}

/// Runs `method` on the clouds read from `source_path` and `target_path`, naming both files and
/// the method when it fails. FGR's steps show as a bar (in percent) on a terminal.
pub fn register_files(
    method: &mut Method,
    (source, target): (&rgm_geom::PointCloud, &rgm_geom::PointCloud),
    (source_path, target_path): (&std::path::Path, &std::path::Path),
) -> anyhow::Result<rgm_model::Registration> {
    let bar = progress(100, &method.name());
    let registration = method
        .register_with_progress(source, target, &mut |p| {
            bar.set_position((100.0 * p.done) as u64);
            bar.set_message(p.step);
        })
        .map_err(|err| method_failure(err, &method.name(), (source_path, target_path)));
    bar.finish_and_clear();
    registration
}

/// `err` of method `name` on the pair of files, named, with a hint where an option helps.
pub fn method_failure(
    err: rgm_model::MethodError,
    name: &str,
    (source_path, target_path): (&Path, &Path),
) -> anyhow::Error {
    let hint = match err {
        rgm_model::MethodError::TooMuchMemory { .. } => {
            " (--match-points N matches on fewer points)"
        }
        _ => "",
    };
    anyhow::Error::new(err).context(format!(
        "{name} failed on {} → {}{hint}",
        source_path.display(),
        target_path.display()
    ))
}

/// `--workers N`: how many pairs run at once.
#[derive(clap::Args, Debug, Clone)]
pub struct WorkerArgs {
    /// Pairs registered at once, one per worker thread, at most 4 per core [default:
    /// --threads]. Times are each method's own, per pair.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..))]
    workers: Option<u16>,
}

impl WorkerArgs {
    /// The pool of `--workers` threads, each flushing denormals.
    fn pool(&self) -> anyhow::Result<rayon::ThreadPool> {
        Ok(rayon::ThreadPoolBuilder::new()
            .num_threads(
                self.workers
                    .map_or_else(rayon::current_num_threads, |n| sane_threads(n, "--workers")),
            )
            .start_handler(|_| {
                rgm_nn::threads::flush_denormals_to_zero();
            })
            .build()?)
    }
}

/// The names of `dirs` (each its own, also for `.`) as tables and output folders show them; an
/// error when two have one name (their pairs and results would take one name).
fn folder_names(dirs: &[PathBuf], flag: &str) -> anyhow::Result<Vec<String>> {
    let mut named: std::collections::HashMap<String, &Path> = Default::default();
    let mut names = Vec::with_capacity(dirs.len());
    for dir in dirs {
        let name = std::fs::canonicalize(dir)
            .ok()
            .and_then(|full| full.file_name().map(|n| n.to_string_lossy().into_owned()))
            .with_context(|| format!("{flag} {}: a folder with no name", dir.display()))?;
        if let Some(other) = named.insert(name.clone(), dir) {
            anyhow::bail!(
                "{flag} {} and {} are both named {name}; their pairs and results would take one \
                 name: give folders of different names (a link to one, renamed, will do)",
                other.display(),
                dir.display()
            );
        }
        names.push(name);
    }
    Ok(names)
}

/// Where the ModelNet40 data is: `--data DIR` or `$RGM_DATA`.
#[derive(clap::Args, Debug, Clone)]
pub struct DataArgs {
    /// The ModelNet40 `.npy` tree (e.g. ../shared/data/modelnet40_npy1024).
    #[arg(long, env = "RGM_DATA", value_name = "DIR")]
    data: Option<PathBuf>,
    /// Real range scans instead of ModelNet40: folders in the Stanford layout (`.ply` or
    /// `.ply.gz` scans and one `.conf` pose file, e.g. ../shared/data/stanford/bunny). The pairs
    /// are the scans that overlap by ≥ 45 % (the share of each scan's points within 3 median
    /// point spacings of the other under the ground truth, the smaller of the two), the source
    /// turned by up to 45° about a random axis and shifted by up to half the object's radius
    /// (seeded per pair); --setting, --unseen and --split do not apply. A folder is named by
    /// its own name (in tables, and as the subfolder of `rgm pairs`), so two folders of one name
    /// are refused; a folder without such a pair is noted on stderr, and a run without any pair
    /// fails. `rgm eval` counts the results within 2° / 1 % and 1° / 0.5 % of the object's
    /// diagonal, and those the method trusted (`registered`) that miss 2° / 1 %.
    #[arg(long, value_name = "DIR", num_args = 1..)]
    scans: Vec<PathBuf>,
    /// The paper's test protocol to use.
    #[arg(long, value_enum, default_value_t = Setting::Partial)]
    setting: Setting,
    /// Unseen categories: test on categories 20–39 only.
    #[arg(long)]
    unseen: bool,
    /// Use only the first N pairs (of those --every keeps).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    limit: Option<u64>,
    /// Use every Nth pair only (pairs 0, N, 2N, …; each is the same pair as in the whole run).
    /// The splits are ordered by category, so a sample that speaks for all of them takes a
    /// stride rather than the first pairs.
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    every: u64,
    /// The shapes the pairs are made of: the official test split, or the validation part of
    /// the training split (for choosing settings without looking at the test pairs).
    #[arg(long, value_enum, default_value_t = Split::Test)]
    split: Split,
}

impl DataArgs {
    /// The dataset and the pair generator these options select.
    fn open(&self) -> anyhow::Result<(ModelNet40, PairGenerator)> {
        let data = self.data.as_ref().context(
            "--data DIR (or the RGM_DATA variable) names the ModelNet40 tree; --scans DIR names \
             real scans",
        )?;
        let dataset = ModelNet40::open(data)?;
        Ok((dataset, PairGenerator::new(self.setting)))
    }

    /// The pairs of each --scans folder that `--every` and `--limit` select, with the folder's
    /// name (its own, also for `.`); the folders' reading warnings go to stderr, and a folder
    /// without a pair is noted there. An error when two folders have one name (their pairs
    /// would be written over each other) or no folder has a pair.
    fn scan_pairs(&self) -> anyhow::Result<Vec<(String, Vec<ScanPair>)>> {
        let mut folders: Vec<(String, Vec<ScanPair>)> = Vec::new();
        let config = ScanPairConfig::default();
        for (dir, name) in self.scans.iter().zip(folder_names(&self.scans, "--scans")?) {
            let folder = ScanFolder::open(dir)?;
            for warning in &folder.warnings {
                eprintln!("rgm: {warning}");
            }
            let pairs = self.select(folder.pairs(&config));
            if pairs.is_empty() {
                eprintln!(
                    "rgm: {}: no two of its {} scans overlap by {} % or more, so it has no \
                     pair",
                    dir.display(),
                    folder.scans.len(),
                    100.0 * config.min_overlap
                );
            }
            folders.push((name, pairs));
        }
        if folders.iter().all(|(_, pairs)| pairs.is_empty()) {
            anyhow::bail!(
                "no pair of scans: no two scans of a --scans folder overlap by {} % or more",
                100.0 * config.min_overlap
            );
        }
        Ok(folders)
    }

    /// The shapes of the selected split (and categories), and the indices of the pairs that
    /// `--every` and `--limit` select among them.
    fn shapes<'a>(&self, dataset: &'a ModelNet40) -> (Vec<&'a Shape>, Vec<usize>) {
        let shapes = dataset.split(self.split, self.unseen);
        let indices = self.select((0..shapes.len()).collect());
        (shapes, indices)
    }

    /// The items `--every` and `--limit` keep: every Nth, then the first of those.
    fn select<T>(&self, items: Vec<T>) -> Vec<T> {
        items
            .into_iter()
            .step_by(self.every as usize)
            .take(self.limit.map_or(usize::MAX, |n| n as usize))
            .collect()
    }

    /// The name of the selected pairs in tables: `partial`, `partial-unseen`, and
    /// `(validation)` after it for the validation split.
    fn pairs_name(&self) -> String {
        format!(
            "{}{}{}",
            self.setting.name(),
            if self.unseen { "-unseen" } else { "" },
            if self.split == Split::Validation {
                " (validation)"
            } else {
                ""
            }
        )
    }
}

/// The point clouds of a pair, read side by side; the readings' warnings (stray PLY header
/// lines) shown on stderr and a failure returned in the order source, target.
pub fn read_pair(
    source: &Path,
    target: &Path,
) -> anyhow::Result<(rgm_geom::PointCloud, rgm_geom::PointCloud)> {
    let (source, target) = rayon::join(
        || rgm_data::read_point_cloud_warned(source),
        || rgm_data::read_point_cloud_warned(target),
    );
    Ok((warned(source)?, warned(target)?))
}

/// The cloud read, its warnings printed.
fn warned(
    read: rgm_data::Result<(rgm_geom::PointCloud, Vec<rgm_data::io::Warning>)>,
) -> anyhow::Result<rgm_geom::PointCloud> {
    let (cloud, warnings) = read?;
    for warning in warnings {
        eprintln!("rgm: {warning}");
    }
    Ok(cloud)
}

/// The long help of a command's input cloud: `first`, then every format rgm reads, from the
/// one list of them.
fn source_help(first: &str) -> String {
    format!(
        "{first} The format by extension, gzip-compressed too (`scan.ply.gz`):\n{}",
        rgm_data::io::formats_help()
    )
}

/// Fails now, before the work, when `path` cannot be written (its folder is missing, it is a
/// folder, permission is denied), so a long command does not lose its result at the end;
/// nothing changes at `path` ([`rgm_data::io::output::check_writable`]).
pub fn check_writable(path: &Path) -> anyhow::Result<()> {
    rgm_data::io::output::check_writable(path)
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Writes `text` to `path` as every output is written ([`rgm_data::io::output::write_file`]:
/// a failed write leaves the path as it was).
pub fn write_text(path: &Path, text: &str) -> anyhow::Result<()> {
    rgm_data::io::output::write_file(path, |out| out.write_all(text.as_bytes()))
        .with_context(|| format!("writing {}", path.display()))
}

/// Gives SIGPIPE its default action back (Rust ignores it, so `println!` to a closed pipe
/// panics): `rgm register a.ply b.ply | head -1` ends rgm quietly once `head` has its line,
/// with the status of any Unix tool stopped that way (141 in the shell), never a panic.
fn end_quietly_on_closed_pipes() {
    #[cfg(unix)]
    // SAFETY: sets one signal's disposition, before any other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

fn main() -> ExitCode {
    end_quietly_on_closed_pipes();
    let cli = Cli::parse();
    set_up_compute_threads(cli.threads.map_or(0, |n| sane_threads(n, "--threads")));
    let outcome = match cli.command {
        // On one of rayon's workers: its parallel steps then run on this thread and the pool's
        // others, instead of this thread handing each one over and sleeping until it ends.
        Command::Register(args) => rayon::scope(|_| commands::register::run(args)),
        Command::Eval(args) => commands::eval::run(args),
        Command::Pairs(args) => commands::pairs::run(args),
        Command::Score(args) => commands::score::run(args),
        Command::Train(args) => commands::train::run(args),
        Command::Render(args) => commands::render::run(args),
        Command::Merge(args) => commands::merge::run(args),
    };
    match outcome {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("rgm: error: {}", error_message(&err));
            ExitCode::FAILURE
        }
    }
}

/// Threads past this many per core only cost their start (each a stack) and their switching.
const THREADS_PER_CORE: usize = 4;

/// `asked` threads, or [`THREADS_PER_CORE`] per core when it asks for more (said on stderr):
/// tens of thousands of threads take minutes to start.
fn sane_threads(asked: u16, option: &str) -> usize {
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    let most = THREADS_PER_CORE * cores;
    if usize::from(asked) <= most {
        return asked.into();
    }
    eprintln!(
        "rgm: {option} {asked} is more than {THREADS_PER_CORE} per core on this machine's \
         {cores}; using {most}"
    );
    most
}

/// Denormals flushed to zero on every compute thread (the network's Sinkhorn underflows), and
/// one OpenBLAS thread unless `OPENBLAS_NUM_THREADS` asks for more: more threads gain a little
/// on an idle machine, but while other work holds the cores OpenBLAS's spinning threads make a
/// registration many times slower (docs/speed.md, "The `rgm` command: threads"). `rgm eval`
/// runs pairs on parallel workers instead. `threads` workers in rayon's pool (0: one per core).
fn set_up_compute_threads(threads: usize) {
    rgm_nn::threads::flush_denormals_everywhere(threads);
    if std::env::var_os("OPENBLAS_NUM_THREADS").is_none() {
        rgm_nn::threads::set_blas_threads(1);
    }
}

/// The error and its causes joined by `: `, leaving out a cause whose text the message already
/// ends with (many of our errors print their source themselves, e.g. "FILE: No such file").
fn error_message(err: &anyhow::Error) -> String {
    let mut message = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if message.is_empty() {
            message = text;
        } else if !message.ends_with(&text) {
            message = format!("{message}: {text}");
        }
    }
    message
}

#[cfg(test)]
mod help_tests {
    use clap::CommandFactory;

    /// `rgm register --help` and `rgm render --help` name every format and extension of the list.
    #[test]
    fn the_help_names_every_format() {
        for command in ["register", "render"] {
            let mut cli = super::Cli::command();
            let help = cli
                .find_subcommand_mut(command)
                .unwrap()
                .render_long_help()
                .to_string();
            for format in rgm_data::io::FORMATS {
                assert!(help.contains(format.name()), "{command}: {help}");
                for ext in format.extensions() {
                    assert!(help.contains(&format!(".{ext}")), "{command} lacks .{ext}");
                }
            }
        }
    }
}
