//! `cargo xtask bench`: run the criterion benches of every crate, then summarise them in
//! `docs/bench.md` and `docs/bench.json` with the machine they ran on.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::SystemTime;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::project_root;

/// Options of `cargo xtask bench`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// A short run (1 s warm-up, 2 s measurement per bench) for a first look.
    #[arg(long)]
    quick: bool,
    /// Only the bench targets whose names are given (geom, nn, matching, ...); all by default.
    #[arg(long = "only", value_name = "BENCH")]
    only: Vec<String>,
}

/// One measured bench in the summary.
#[derive(Serialize, Debug)]
struct Row {
    id: String,
    median_ns: f64,
    /// Work per iteration as the bench declared it (FLOPs for the nn and matching benches).
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
    let mut rows = collect(&criterion_dir, started)?;
    rows.sort_by(|a, b| a.id.cmp(&b.id));
    if rows.is_empty() {
        bail!(
            "no criterion results newer than this run under {}",
            criterion_dir.display()
        );
    }
    let machine = machine_description();
    let docs = root.join("docs");
    fs::write(
        docs.join("bench.json"),
        serde_json::to_string_pretty(
            &serde_json::json!({ "machine": machine, "quick": args.quick, "only": args.only, "benches": rows }),
        )?,
    )?;
    let mut command = String::from("cargo xtask bench");
    if args.quick {
        command += " --quick";
    }
    for name in &args.only {
        command += &format!(" --only {name}");
    }
    fs::write(docs.join("bench.md"), markdown(&rows, &machine, &command))?;
    println!(
        "wrote docs/bench.md and docs/bench.json ({} benches)",
        rows.len()
    );
    Ok(())
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
fn machine_description() -> String {
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

fn markdown(rows: &[Row], machine: &str, command: &str) -> String {
    let mut out = String::from("# Benchmarks\n\n");
    out += &format!("Machine: {machine}. Produced by `{command}`; medians of criterion samples.\n");
    out += "Throughput is the bench's declared work per iteration (FLOPs for the nn and matching benches) per second.\n\n";
    out += "| bench | median | throughput (G/s) |\n|---|---:|---:|\n";
    for row in rows {
        let time = format_ns(row.median_ns);
        let rate = row
            .giga_per_s
            .map(|g| format!("{g:.2}"))
            .unwrap_or_default();
        out += &format!("| {} | {} | {} |\n", row.id, time, rate);
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
