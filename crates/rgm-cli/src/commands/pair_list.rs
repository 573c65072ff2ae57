//! `rgm register --pairs LIST`: every pair of a list registered on parallel workers, one JSON
//! line each, resumable ([`rgm_model::many_pairs`] runs it; each line names its pair by `source` and
//! `target` as LIST spells them).

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Mutex;

use anyhow::{bail, Context, Result};
use rgm_model::many_pairs::{self, Output};
use rgm_model::progress::Progress as _;

use crate::args::{MethodArgs, WorkerArgs};

/// The pair-list options of `rgm register`.
#[derive(clap::Args, Debug)]
#[command(next_help_heading = "Pair lists")]
pub struct PairListArgs {
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
    /// Write the lines of --pairs to FILE (JSON Lines) instead of stdout, resumably, after a
    /// first line that records the settings that change results ({"rgm_many_pairs": 1,
    /// "settings": {…}}: the method, the weights' CRC-32, the network's options). A run on a
    /// FILE that holds lines already registers only the pairs it has no line for (a killed
    /// run's cut-off last line, and pairs that failed, are done again). Refused, and left as it
    /// is: a FILE without that first line (not rgm's), one of other settings, and one that
    /// another run is writing. A FILE of an rgm before issue 58 ({"rgm_batch": 1, …}, the
    /// methods named +icp for +refine) resumes too, its header rewritten as today's.
    #[arg(long, value_name = "FILE", requires = "pairs")]
    output: Option<PathBuf>,
    #[command(flatten)]
    workers: WorkerArgs,
}

impl PairListArgs {
    /// The refusal of the pair-list options when SOURCE TARGET name one pair.
    pub fn refuse_without_pairs(&self) -> Result<()> {
        if self.workers.workers.is_some() {
            bail!("--workers applies to --pairs LIST; one pair runs on one thread");
        }
        Ok(())
    }
}

pub fn run(args: &PairListArgs, method: &MethodArgs) -> Result<()> {
    let list = args
        .pairs
        .as_deref()
        .context("SOURCE and TARGET name one pair, --pairs LIST many")?;
    let options = method.options(crate::args::Defaults::Register)?;
    let method = options.build()?;
    let bar = rgm_cli::TaskBar::new(method.name());
    let listed = many_pairs::read_list(list, &bar)?;
    let mut output = match &args.output {
        Some(path) => Some(Output::open(
            path,
            &many_pairs::settings(&options, &method)?,
            &bar,
        )?),
        None => None,
    };
    let done = output
        .as_ref()
        .map(Output::done)
        .cloned()
        .unwrap_or_default();
    let (todo, earlier, stale) = many_pairs::remaining(&listed, &done);
    if let Some(output) = &mut output {
        if !stale.is_empty() {
            eprintln!(
                "rgm: {} pairs of {} have a line of other files (changed since, or another list's \
                 files of the same names); they run again and their lines are replaced",
                stale.len(),
                output.path().display()
            );
        }
        output.forget(&stale)?;
    }
    if let (Some(output), false) = (&output, done.is_empty()) {
        eprintln!(
            "rgm: {} of the {} pairs have their line in {} already; registering {}",
            listed.len() - todo.len(),
            listed.len(),
            output.path().display(),
            todo.len()
        );
    }
    bar.start(listed.len(), listed.len() - todo.len());
    let stdout = Mutex::new(std::io::stdout());
    let lines = match &output {
        Some(output) => output.lines(),
        None => (
            std::path::Path::new("stdout"),
            &stdout as &Mutex<dyn std::io::Write + Send>,
        ),
    };
    let jobs = todo.iter().enumerate().map(|(i, pair)| pair.job(i));
    let tally = args.workers.pool()?.install(|| {
        many_pairs::register_all(
            &method,
            jobs,
            Some(lines),
            &bar,
            &AtomicBool::new(false),
            |_, _| {},
        )
    })?;
    bar.finish(true);
    let mut all = earlier;
    all += tally;
    let written = lines.0.display();
    let (failed, doubted) = (all.failed, all.not_registered);
    eprintln!(
        "rgm: {} pairs: {} registered, {doubted} not registered, {failed} failed (lines in {written})",
        all.total(),
        all.registered,
    );
    if failed + doubted > 0 {
        bail!(
            "of {} pairs, {failed} failed and {doubted} were not registered; their lines in \
             {written} say why",
            all.total()
        );
    }
    Ok(())
}
