//! `cargo xtask <chore>`: the runner of benchmarks and reproductions.
//!
//! Layering rule: xtask drives the other crates through cargo and their libraries (rgm-model's
//! methods and evaluation, rgm-data's pairs, rgm-viz's figures, rgm-cli's progress bars); it
//! chooses what to run and writes the reports, and holds no algorithm of its own.

mod bench;
mod pack;
mod snapshot;
mod tables;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// The project's chores.
#[derive(Parser, Debug)]
#[command(name = "cargo xtask", about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run every criterion bench and write docs/bench.md and docs/bench.json.
    Bench(bench::Args),
    /// Reproduce the paper's Tables 1–5 on ModelNet40: docs/results.md, per-pair JSON, figures.
    ReproduceTables(tables::Args),
    /// Pack ModelNet40's training shapes into one safetensors file of at most 32 MiB for a GPU
    /// machine (docs/training/gpu.md), or check a pack against the data (--check).
    PackModelnet(pack::Args),
    /// Make the training runs under runs/ small enough to commit (Adam moments in bf16).
    SnapshotRuns(snapshot::Args),
}

fn main() -> ExitCode {
    let outcome = match Cli::parse().command {
        Command::Bench(args) => bench::run(args),
        Command::ReproduceTables(args) => tables::run(args),
        Command::PackModelnet(args) => pack::run(args),
        Command::SnapshotRuns(args) => snapshot::run(args),
    };
    match outcome {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("xtask: error: {err:#}");
            ExitCode::FAILURE
        }
    }
}

/// The repository root (the folder above xtask/).
pub fn project_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask/ has a parent")
        .to_path_buf()
}
