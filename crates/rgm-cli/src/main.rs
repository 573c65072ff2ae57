//! `rgm` — register two point clouds, or evaluate registration methods on ModelNet40.
//!
//! Layering rule: the command is a thin shell over rgm-model (methods, evaluation) and rgm-data
//! (files, pairs); it owns argument parsing, progress and printing, and no algorithm. This file
//! only parses and dispatches: the argument groups the commands share are in `args`, reading
//! and writing their files in `files`, each command in `commands`; none imports this file.

mod args;
mod commands;
mod files;
mod table;

use std::process::ExitCode;

use clap::{Parser, Subcommand};
pub use rgm_cli::progress;

use crate::args::sane_threads;

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
    /// and returns the one whose result overlaps better; on a pair denser than ModelNet40, where
    /// neither result is taken, also the scene stage (second-order spatial compatibility on the
    /// pair's own FPFH matches; --method scene runs it alone on dense pairs). The output names
    /// the candidates and their scores. --method rgm, fgr or icp runs one method; --no-refine
    /// skips the refinement; docs/results.md compares them. Clouds of any size, scale and density:
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
    /// Pairs of scans are registered (by --method scene unless told otherwise) in rounds, each
    /// round's pairs chosen from the poses the pairs so far give: a pair those poses place
    /// apart is skipped, a scan not yet in a consistent cycle of three tries more partners
    /// (--all-pairs registers every pair). Results the method doubts are left out, wrong ones
    /// found by cycles of three that do not close,
    /// and the poses solved as a pose graph from the maximum spanning tree of the pairs'
    /// fitness, then refined by multiway ICP (each scan against the union of the others, at
    /// the scans' own point spacing). Scans that hang together form a component, each merged
    /// on its own; a scan no trusted pair links is left unplaced and named. Writes
    /// DIR/poses.json ({"scans", "poses": 4×4 model ← scan or null, "registered", "component",
    /// "residual": median point-to-plane distance to the other scans, "on_loop": whether one
    /// of its pairs lies on a loop of pairs (a scan without one is placed unchecked), "edges":
    /// every pair, used or why not}), DIR/poses.conf (Stanford's `bmesh NAME tx ty tz qx qy qz qw` lines of
    /// the largest component, p_model = R(q)ᵀ·p + t) and DIR/model.ply (the largest
    /// component's scans in one frame, one point per --voxel cube, a `scan` property giving
    /// each point's scan by its place in the list) and DIR/model.html (that model in the
    /// browser, a colour per scan, toggled to the scans as given). Fails when no pair of the
    /// scans could be registered (the files written first).
    Merge(commands::merge::Args),
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
