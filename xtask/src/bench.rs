//! `cargo xtask bench`: run the criterion benches of every crate, keep their medians in
//! `docs/bench.json` with the machine they ran on, and render that file as `docs/bench.md`: median
//! times, GFLOP/s where a bench counts FLOPs, and each such rate as a share of the machine's GEMM
//! peak measured in the same run. `--render-only` re-renders `docs/bench.md` from the JSON alone.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::SystemTime;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::project_root;

/// The benches whose declared elements are FLOPs: the GEMM-bound ops of `benches/benches/nn.rs`
/// and the f32/bf16 products of `benches/benches/gemm.rs`. nn's other benches declare
/// rows·channels; the rest declare nothing.
const FLOP_BENCHES: [&str; 6] = [
    "sgemm/",
    "linear/",
    "attention/",
    "adjacency/gram/",
    "gemm/",
    "amx_peak/",
];

/// The bench whose best rate is the machine's GEMM peak (f32 products of square matrices).
const GEMM_PEAK_BENCH: &str = "sgemm/";

/// Options of `cargo xtask bench`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// A short run (1 s warm-up, 2 s measurement per bench) for a first look.
    #[arg(long)]
    quick: bool,
    /// Only the bench targets whose names are given (geom, nn, matching, ...); all by default.
    #[arg(long = "only", value_name = "BENCH")]
    only: Vec<String>,
    /// Run no bench: re-render docs/bench.md from the numbers in docs/bench.json.
    #[arg(long, conflicts_with_all = ["quick", "only"])]
    render_only: bool,
}

/// The contents of `docs/bench.json`: one run's medians and how they were taken.
#[derive(Serialize, Deserialize, Debug)]
struct Summary {
    /// CPU model, cores and memory of the machine that ran the benches.
    machine: String,
    /// Whether the run used `--quick`.
    quick: bool,
    /// The `--only` bench targets of the run; empty for all.
    only: Vec<String>,
    /// Sorted by id.
    benches: Vec<Row>,
}

/// One measured bench in the summary.
#[derive(Serialize, Deserialize, Debug)]
struct Row {
    id: String,
    median_ns: f64,
    /// Work per iteration as the bench declared it (FLOPs for [`FLOP_BENCHES`]).
    elements: Option<u64>,
    /// `elements / median` in units of 10⁹ per second.
    giga_per_s: Option<f64>,
}

#[derive(Deserialize)]
struct BenchmarkJson {
    full_id: String,
    /// `{"Elements": n}`, `{"Bytes": n}` or absent.
    throughput: Option<serde_json::Value>,
}

#[derive(Deserialize)]
struct Estimates {
    median: Estimate,
}

#[derive(Deserialize)]
struct Estimate {
    point_estimate: f64,
}

pub fn run(args: Args) -> Result<()> {
    let json_path = project_root().join("docs").join("bench.json");
    if !args.render_only {
        let summary = measure(&args)?;
        fs::write(&json_path, serde_json::to_string_pretty(&summary)?)?;
        println!("wrote docs/bench.json ({} benches)", summary.benches.len());
    }
    // The page is always rendered from the file, so a run and `--render-only` write the same.
    let json = fs::read_to_string(&json_path)
        .with_context(|| format!("reading {}", json_path.display()))?;
    let summary: Summary =
        serde_json::from_str(&json).with_context(|| format!("parsing {}", json_path.display()))?;
    fs::write(json_path.with_file_name("bench.md"), markdown(&summary))?;
    println!("wrote docs/bench.md from docs/bench.json");
    Ok(())
}

/// Runs the criterion benches and collects the medians they wrote.
fn measure(args: &Args) -> Result<Summary> {
    let root = project_root();
    let started = SystemTime::now();
    let mut cargo = Command::new(env!("CARGO"));
    cargo
        .current_dir(&root)
        .args(["bench", "-p", "rgm-benches"]);
    for name in &args.only {
        cargo.args(["--bench", name]);
    }
    cargo.arg("--");
    if args.quick {
        cargo.args(["--warm-up-time", "1", "--measurement-time", "2"]);
    }
    let status = cargo.status().context("running cargo bench")?;
    if !status.success() {
        bail!("cargo bench failed ({status})");
    }
    let criterion_dir = target_dir(&root).join("criterion");
    let mut benches = collect(&criterion_dir, started)?;
    benches.sort_by(|a, b| a.id.cmp(&b.id));
    if benches.is_empty() {
        bail!(
            "no criterion results newer than this run under {}",
            criterion_dir.display()
        );
    }
    Ok(Summary {
        machine: machine_description(),
        quick: args.quick,
        only: args.only.clone(),
        benches,
    })
}

fn target_dir(root: &Path) -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("target"))
}

/// Every `new/benchmark.json` + `new/estimates.json` pair under `dir` written after `since`.
fn collect(dir: &Path, since: SystemTime) -> Result<Vec<Row>> {
    let mut rows = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(folder) = stack.pop() {
        let Ok(entries) = fs::read_dir(&folder) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
                continue;
            }
            if path.file_name().is_some_and(|n| n == "estimates.json")
                && path.parent().is_some_and(|p| p.ends_with("new"))
            {
                let fresh = fs::metadata(&path)
                    .and_then(|m| m.modified())
                    .is_ok_and(|t| t >= since);
                if fresh {
                    rows.push(read_row(path.parent().expect("checked above"))?);
                }
            }
        }
    }
    Ok(rows)
}

fn read_row(new_dir: &Path) -> Result<Row> {
    let read = |name: &str| {
        fs::read_to_string(new_dir.join(name))
            .with_context(|| format!("reading {}", new_dir.join(name).display()))
    };
    let bench: BenchmarkJson = serde_json::from_str(&read("benchmark.json")?)?;
    let estimates: Estimates = serde_json::from_str(&read("estimates.json")?)?;
    let median_ns = estimates.median.point_estimate;
    let elements = bench
        .throughput
        .as_ref()
        .and_then(|t| t.get("Elements"))
        .and_then(|n| n.as_u64());
    Ok(Row {
        id: bench.full_id,
        median_ns,
        elements,
        giga_per_s: elements.map(|n| n as f64 / median_ns),
    })
}

/// CPU model, core count and memory, read from /proc.
pub fn machine_description() -> String {
    let cpuinfo = fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let model = cpuinfo
        .lines()
        .find_map(|l| l.strip_prefix("model name"))
        .map(|s| s.trim_start_matches([' ', '\t', ':']).to_string())
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1);
    let meminfo = fs::read_to_string("/proc/meminfo").unwrap_or_default();
    let mem_gib = meminfo
        .lines()
        .find_map(|l| l.strip_prefix("MemTotal:"))
        .and_then(|s| s.trim().trim_end_matches(" kB").parse::<f64>().ok())
        .map(|kb| kb / (1024.0 * 1024.0))
        .unwrap_or(0.0);
    format!("{model}, {cores} cores, {mem_gib:.0} GiB")
}

/// The command line that measured `summary`.
fn command(summary: &Summary) -> String {
    let mut command = String::from("cargo xtask bench");
    if summary.quick {
        command += " --quick";
    }
    for name in &summary.only {
        command += &format!(" --only {name}");
    }
    command
}

/// The machine's GEMM peak in GFLOP/s: the best rate of the [`GEMM_PEAK_BENCH`] rows, with the
/// id of that row; None when the run had no such bench.
fn gemm_peak(rows: &[Row]) -> Option<(f64, &str)> {
    rows.iter()
        .filter(|r| r.id.starts_with(GEMM_PEAK_BENCH))
        .filter_map(|r| Some((r.giga_per_s?, r.id.as_str())))
        .max_by(|a, b| a.0.total_cmp(&b.0))
}

fn markdown(summary: &Summary) -> String {
    let peak = gemm_peak(&summary.benches);
    let mut out = String::from("# Benchmarks\n\n");
    out += &format!(
        "Machine: {}. Measured by `{}`: medians of criterion samples.\n",
        summary.machine,
        command(summary)
    );
    out += &match peak {
        Some((gflops, id)) => format!(
            "GEMM peak of this machine, measured in the same run: **{gflops:.1} GFLOP/s** \
             (`{id}`, f32).\n\n"
        ),
        None => format!("No GEMM peak: this run had no `{GEMM_PEAK_BENCH}` bench.\n\n"),
    };
    out += "Throughput: GFLOP/s for the benches that count FLOPs (the GEMM-bound ops), with its \
            share of that peak; G elements/s (rows·channels) for the other benches that declare \
            work; none for the rest.\n\n";
    out += "Re-render this page from `docs/bench.json` with `cargo xtask bench --render-only`.\n\n";
    out += "| bench | median | throughput | of GEMM peak |\n|---|---:|---:|---:|\n";
    for row in &summary.benches {
        let counts_flops = FLOP_BENCHES.iter().any(|p| row.id.starts_with(p));
        let (rate, share) = match (row.giga_per_s, counts_flops) {
            (Some(g), true) => (
                format!("{g:.2} GFLOP/s"),
                peak.map(|(p, _)| format!("{:.0} %", 100.0 * g / p))
                    .unwrap_or_default(),
            ),
            (Some(g), false) => (format!("{g:.2} G elem/s"), String::new()),
            (None, _) => (String::new(), String::new()),
        };
        out += &format!(
            "| {} | {} | {rate} | {share} |\n",
            row.id,
            format_ns(row.median_ns)
        );
    }
    out
}

fn format_ns(ns: f64) -> String {
    match ns {
        n if n >= 1e9 => format!("{:.3} s", n / 1e9),
        n if n >= 1e6 => format!("{:.3} ms", n / 1e6),
        n if n >= 1e3 => format!("{:.3} µs", n / 1e3),
        n => format!("{n:.0} ns"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_are_printed_in_the_right_unit() {
        assert_eq!(format_ns(1.5e9), "1.500 s");
        assert_eq!(format_ns(2.25e6), "2.250 ms");
        assert_eq!(format_ns(999.0), "999 ns");
    }

    /// Five rows: two GEMM peaks (the best is 160 GFLOP/s), a FLOP-counting op at half of it,
    /// an op counting rows·channels, and one declaring no work.
    const FIXTURE: &str = r#"{
        "machine": "Test CPU, 2 cores, 8 GiB", "quick": true, "only": ["nn"],
        "benches": [
            {"id": "kabsch/717", "median_ns": 8073.0, "elements": null, "giga_per_s": null},
            {"id": "linear/forward/4x4->4", "median_ns": 1000.0, "elements": 80000, "giga_per_s": 80.0},
            {"id": "norms/layer_norm_forward/4", "median_ns": 2000.0, "elements": 1000, "giga_per_s": 0.5},
            {"id": "sgemm/1024", "median_ns": 1.0e6, "elements": 160000000, "giga_per_s": 160.0},
            {"id": "sgemm/2048", "median_ns": 1.0e6, "elements": 150000000, "giga_per_s": 150.0}
        ]
    }"#;

    #[test]
    fn renders_gflops_and_share_of_the_gemm_peak() {
        let summary: Summary = serde_json::from_str(FIXTURE).unwrap();
        let md = markdown(&summary);
        for line in [
            "Machine: Test CPU, 2 cores, 8 GiB. Measured by `cargo xtask bench --quick --only nn`:",
            "measured in the same run: **160.0 GFLOP/s** (`sgemm/1024`, f32).\n",
            "| kabsch/717 | 8.073 µs |  |  |\n",
            "| linear/forward/4x4->4 | 1.000 µs | 80.00 GFLOP/s | 50 % |\n",
            "| norms/layer_norm_forward/4 | 2.000 µs | 0.50 G elem/s |  |\n",
            "| sgemm/1024 | 1.000 ms | 160.00 GFLOP/s | 100 % |\n",
            "| sgemm/2048 | 1.000 ms | 150.00 GFLOP/s | 94 % |\n",
        ] {
            assert!(md.contains(line), "missing {line:?} in\n{md}");
        }
    }

    #[test]
    fn without_a_gemm_bench_there_is_no_share() {
        let mut summary: Summary = serde_json::from_str(FIXTURE).unwrap();
        summary.benches.retain(|r| !r.id.starts_with("sgemm/"));
        let md = markdown(&summary);
        assert!(md.contains("No GEMM peak: this run had no `sgemm/` bench."));
        assert!(md.contains("| linear/forward/4x4->4 | 1.000 µs | 80.00 GFLOP/s |  |\n"));
    }

    /// `docs/bench.md` is what `cargo xtask bench --render-only` makes of `docs/bench.json`.
    #[test]
    fn committed_bench_md_is_rendered_from_bench_json() {
        let docs = project_root().join("docs");
        let json = fs::read_to_string(docs.join("bench.json")).unwrap();
        let summary: Summary = serde_json::from_str(&json).unwrap();
        let md = fs::read_to_string(docs.join("bench.md")).unwrap();
        assert!(
            md == markdown(&summary),
            "docs/bench.md is stale: run `cargo xtask bench --render-only`"
        );
    }

    #[test]
    fn reads_a_criterion_result() {
        let dir = std::env::temp_dir().join(format!("xtask-bench-{}", std::process::id()));
        let new_dir = dir.join("group/fn/new");
        fs::create_dir_all(&new_dir).unwrap();
        fs::write(
            new_dir.join("benchmark.json"),
            r#"{"full_id":"group/fn","throughput":{"Elements":2000}}"#,
        )
        .unwrap();
        fs::write(
            new_dir.join("estimates.json"),
            r#"{"median":{"point_estimate":1000.0}}"#,
        )
        .unwrap();
        let rows = collect(&dir, SystemTime::UNIX_EPOCH).unwrap();
        fs::remove_dir_all(&dir).unwrap();
        assert_eq!(rows.len(), 1);
        assert_eq!(rows[0].id, "group/fn");
        assert_eq!(rows[0].giga_per_s, Some(2.0));
    }
}
