//! The argument groups the commands share (the method, workers, the data) and what they
//! build from them.

use std::path::{Path, PathBuf};

use anyhow::Context;

use rgm_data::{
    ModelNet40, PairGenerator, ScanFolder, ScanPair, ScanPairConfig, Setting, Shape, Split,
};
use rgm_model::network::TestStatistics;
use rgm_model::{Method, MethodName, MethodOptions};
use rgm_nn::Precision;
use rgm_registration::methods::refine::{self, RefineConfig};

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
    /// The registration method [default: auto in `rgm register` and `rgm render`; scene in
    /// `rgm merge` and `rgm eval --multiway`; rgm, the paper's method, in `rgm eval`]. RGM uses
    /// the model built into rgm unless --weights names another.
    #[arg(long, value_enum)]
    pub(crate) method: Option<MethodName>,
    /// RGM weights: a safetensors file with the authors' parameter names
    /// (`tools/reference/rgm_reference.py` documents them). Without it, RGM uses the model
    /// built into rgm (crates/rgm-model/weights/manifest.json describes it).
    #[arg(long, value_name = "FILE")]
    pub(crate) weights: Option<PathBuf>,
    /// The network sizes --weights were trained with: paper, small, fast or tiny.
    #[arg(long, value_name = "NAME", requires = "weights")]
    pub(crate) preset: Option<String>,
    /// Batch-norm statistics for --weights: cloud for weights trained by `rgm train`, running
    /// for the authors' PyTorch weights [default: running; the built-in model's own otherwise].
    #[arg(long, value_enum, value_name = "WHICH", requires = "weights")]
    pub(crate) test_statistics: Option<TestStatistics>,
    /// RGM matches on at most N randomly drawn points of each cloud (fixed seed) and applies
    /// the transform to the full clouds; 0 matches on every point. The network's memory grows
    /// with the square of N (about 0.7 GB at 1,024 points, 2.7 GB at 2,048 for the paper's
    /// sizes), and a request beyond the machine's free memory is refused [default: the
    /// built-in model's every point, as the paper tests it (chosen on validation pairs), or 256
    /// as the auto cascade's second stage; 1,024 with --weights, the paper's training size].
    #[arg(long, value_name = "N")]
    pub(crate) match_points: Option<usize>,
    /// RGM's passes of network → matching → Kabsch, each on the source moved by the passes
    /// before [default: 2, as in the paper's tables].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..))]
    pub(crate) passes: Option<u16>,
    // Help from `refine_help`: the distances are RefineConfig's defaults.
    #[arg(long, overrides_with = "no_refine", help = refine_help())]
    pub(crate) refine: bool,
    /// Report the method's own transform, unrefined (as the paper's tables do).
    #[arg(long, overrides_with = "refine")]
    pub(crate) no_refine: bool,
    /// RGM's matrix products: f32, or bf16 (inputs rounded to bfloat16, f32 accumulation:
    /// faster where the processor has AMX tile units or AVX-512 BF16; the rest of the network
    /// stays f32).
    #[arg(long, value_name = "f32|bf16", default_value_t = MethodOptions::default().precision)]
    pub(crate) precision: Precision,
    /// auto: take FGR's result without running the network when its overlap score (both
    /// clouds' share of points on the other, 0 to 2) reaches SCORE and the shape does not fit as
    /// well turned about one of its axes (or the clouds lie wholly on each other); `inf` runs
    /// both methods on every pair (slower).
    #[arg(long, value_name = "SCORE", default_value_t = MethodOptions::default().accept)]
    pub(crate) accept: f64,
}

/// The help of --refine, with the distances of [`RefineConfig::default`].
fn refine_help() -> String {
    let refine = RefineConfig::default();
    let then = |distances: &[f64]| {
        let d: Vec<String> = distances.iter().map(f64::to_string).collect();
        d.join(", then ")
    };
    format!(
        "Refine the transform of RGM or FGR (both with auto), the method then named with \
         +{} (auto+{}; --method icp is plain ICP, a method of its own): ICP on the full clouds, \
         trimmed point-to-plane with pairs closer than {}, and point-to-point at {} (RGM and \
         auto measure them in the unit-sphere frame, FGR alone in the clouds' own units, like \
         its own radii, which suit unit-sized shapes); with auto on clouds denser than 1,024 \
         points, then point-to-plane on the clouds as given at a few point spacings and at 3 \
         noise σ (rgm_registration::methods::refine::refine_at_resolution). On by default in `rgm register` and \
         `rgm render`; `rgm eval` follows the paper's protocol and refines only when asked",
        refine::NAME,
        refine::NAME,
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
    /// `rgm merge`'s (and `rgm eval --multiway`'s): `scene`, refined.
    Merge,
}

impl MethodArgs {
    /// The method these options select, with its weights loaded ([`Self::options`] built).
    pub(crate) fn build(&self, defaults: Defaults) -> anyhow::Result<Method> {
        Ok(self.options(defaults)?.build()?)
    }

    /// The options of the method these select: refined when --refine is given, or by
    /// `defaults` unless --no-refine is (ICP is its own refinement). `rgm_model::MethodOptions`
    /// builds the method, as it does for the Python package.
    pub(crate) fn options(&self, defaults: Defaults) -> anyhow::Result<MethodOptions> {
        let refine_by_default = defaults != Defaults::Paper;
        let method = match (self.method, defaults) {
            (Some(method), _) => method,
            (None, Defaults::Register) => MethodOptions::default().method,
            (None, Defaults::Merge) => MethodName::Scene,
            (None, Defaults::Paper) => MethodName::Rgm,
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

/// `--workers N`: how many pairs run at once.
#[derive(clap::Args, Debug, Clone)]
pub struct WorkerArgs {
    /// Pairs registered at once, one per worker thread, at most 4 per core [default:
    /// --threads]. Times are each method's own, per pair.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..))]
    pub(crate) workers: Option<u16>,
}

impl WorkerArgs {
    /// The pool of `--workers` threads, each flushing denormals.
    pub(crate) fn pool(&self) -> anyhow::Result<rayon::ThreadPool> {
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
pub fn folder_names(dirs: &[PathBuf], flag: &str) -> anyhow::Result<Vec<String>> {
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
    pub(crate) data: Option<PathBuf>,
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
    pub(crate) scans: Vec<PathBuf>,
    /// The paper's test protocol to use.
    #[arg(long, value_enum, default_value_t = Setting::Partial)]
    pub(crate) setting: Setting,
    /// Unseen categories: test on categories 20–39 only.
    #[arg(long)]
    pub(crate) unseen: bool,
    /// Use only the first N pairs (of those --every keeps).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub(crate) limit: Option<u64>,
    /// Use every Nth pair only (pairs 0, N, 2N, …; each is the same pair as in the whole run).
    /// The splits are ordered by category, so a sample that speaks for all of them takes a
    /// stride rather than the first pairs.
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    pub(crate) every: u64,
    /// The shapes the pairs are made of: the official test split, or the validation part of
    /// the training split (for choosing settings without looking at the test pairs).
    #[arg(long, value_enum, default_value_t = Split::Test)]
    pub(crate) split: Split,
}

impl DataArgs {
    /// The dataset and the pair generator these options select.
    pub(crate) fn open(&self) -> anyhow::Result<(ModelNet40, PairGenerator)> {
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
    pub(crate) fn scan_pairs(&self) -> anyhow::Result<Vec<(String, Vec<ScanPair>)>> {
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
    pub(crate) fn shapes<'a>(&self, dataset: &'a ModelNet40) -> (Vec<&'a Shape>, Vec<usize>) {
        let shapes = dataset.split(self.split, self.unseen);
        let indices = self.select((0..shapes.len()).collect());
        (shapes, indices)
    }

    /// The items `--every` and `--limit` keep: every Nth, then the first of those.
    pub(crate) fn select<T>(&self, items: Vec<T>) -> Vec<T> {
        items
            .into_iter()
            .step_by(self.every as usize)
            .take(self.limit.map_or(usize::MAX, |n| n as usize))
            .collect()
    }

    /// The name of the selected pairs in tables: `partial`, `partial-unseen`, and
    /// `(validation)` after it for the validation split.
    pub(crate) fn pairs_name(&self) -> String {
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

/// Threads past this many per core only cost their start (each a stack) and their switching.
const THREADS_PER_CORE: usize = 4;

/// `asked` threads, or [`THREADS_PER_CORE`] per core when it asks for more (said on stderr):
/// tens of thousands of threads take minutes to start.
pub fn sane_threads(asked: u16, option: &str) -> usize {
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
