//! The results file of `cargo xtask reproduce-tables`: the paper's five tables from the rows'
//! records, the trained models, the figures, and how the run was made.

use std::path::Path;

use rgm_model::evaluate::{table_header, table_row};
use rgm_model::weights::ModelEntry;
use rgm_model::Summary;
use rgm_registration::methods::refine::RefineConfig;

use rgm_model::weights::Variant;

use super::{Results, Row};

/// What the results file says about the run that wrote it.
pub(super) struct Report {
    pub(super) command: String,
    /// The commit when the run started (the models were loaded then).
    pub(super) commit: String,
    pub(super) threads: usize,
    /// The 1-minute load average when the run started and when it ended.
    pub(super) load: [Option<f64>; 2],
    pub(super) figures: usize,
    /// The weights manifest's models.
    pub(super) models: Vec<ModelEntry>,
}

/// A table of the paper: its number, its caption, its test set and whether it is the ablation
/// (trained models only, every variant) rather than a comparison of methods.
struct Table {
    number: u8,
    caption: &'static str,
    key: &'static str,
    ablation: bool,
}

const TABLES: [Table; 5] = [
    Table {
        number: 1,
        caption: "clean point clouds",
        key: "clean",
        ablation: false,
    },
    Table {
        number: 2,
        caption: "Gaussian noise",
        key: "noise",
        ablation: false,
    },
    Table {
        number: 3,
        caption: "partial-to-partial",
        key: "partial",
        ablation: false,
    },
    Table {
        number: 4,
        caption: "unseen categories (partial-to-partial protocol)",
        key: "partial-unseen",
        ablation: false,
    },
    Table {
        number: 5,
        caption: "ablation — RGM, Var1 (distance affinity) and Var2 (full connection) on \
                  partial-to-partial",
        key: "partial",
        ablation: true,
    },
];

impl Report {
    pub(super) fn markdown(&self, results: &Results, out: &Path) -> String {
        let load = |l: Option<f64>| l.map_or("unknown".into(), |l| format!("{l:.2}"));
        let mut md = String::from("# Results\n\n");
        md += &format!(
            "Produced by `{}` at commit {} on {} ({} worker threads); pairs already in the \
             per-pair files were read back from earlier invocations, not recomputed. \
             Hand-measured comparisons — Open3D on the same pairs, timings on an idle machine, \
             the network against the PyTorch reference — are in [baselines.md](baselines.md).\n\n",
            self.command,
            self.commit,
            crate::bench::machine_description(),
            self.threads
        );
        md += &data_notes();
        md += "- **RGM's test-time procedure** is the reference code's (spec §4): a chain of 2 \
               passes moving the source toward the target and one moving the target toward the \
               source, the correspondences both chains end with (cycle consistency), one \
               weighted Kabsch of the original clouds. It reproduces the authors' own procedure \
               on weights their code trained, transforms and correspondences, on 21 partial \
               test pairs (`crates/rgm-model/tests/authors_fast.rs`).\n";
        md += &format!(
            "- **Time per pair** is the method's own wall time on one worker thread. This run \
             used {} worker threads on the machine above with a 1-minute load average of {} at \
             its start and {} at its end; with a load above the worker count other work shared \
             the cores, so times are comparable only within one table. Pairs \
             read back from an earlier run keep that run's times.\n",
            self.threads,
            load(self.load[0]),
            load(self.load[1])
        );
        md += "- **Per-pair records**: `results/<setting>/<method>.jsonl.gz` (for a trained \
               model `<name>-<training pairs seen>pairs.jsonl.gz`), gzip'd JSON lines (`zcat` \
               shows them): a header naming the row's inputs (the method's options, a model's \
               weights and their CRC-32), then per pair its index, the transform found (3 × 4, \
               full precision), the time, the correspondences and any failure; the ground truth \
               and the metrics are computed again from the pair, which `rgm-data` regenerates \
               from its index. A later run computes only the pairs missing there, and every \
               pair of a row whose inputs changed. The files are not kept in the working tree \
               (`.gitignore`); those committed earlier are in the history, and a run that \
               misses one starts from the copy the last commit to add or change it holds \
               (`git log -1 -- PATH`); delete a file and pass `--no-history` to recompute \
               it. A refined row's file ends `-refine` (`fgr-refine.jsonl.gz`); before issue 58 \
               it ended `-icp` (`fgr-icp.jsonl.gz`, the rows then named `+icp`): the history's \
               `-icp` files are read back under the new name, and a copy of one elsewhere is \
               read once renamed `*-refine.jsonl.gz`.\n\n";
        md += &self.models_markdown();
        for table in &TABLES {
            md += &format!("## Table {}: {}\n\n", table.number, table.caption);
            md += &table_markdown(table, &results[table.key]);
        }
        md += &self.figures_markdown(results, out);
        md
    }

    /// The trained models the tables use, with how each was trained.
    fn models_markdown(&self) -> String {
        let mut md = String::from(
            "## Trained models\n\nFrom `crates/rgm-model/weights/manifest.json`; each RGM row \
             below is one of these, named as here.\n\n",
        );
        if self.models.is_empty() {
            return md + "None yet.\n\n";
        }
        md += "| name | setting | unseen | variant | preset | match points | epochs | pairs seen \
               | trained with | note |\n|---|---|---|---|---|---:|---:|---:|---|---|\n";
        for m in &self.models {
            md += &format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | `{}` | {} |\n",
                m.name,
                m.setting.name(),
                if m.unseen { "yes" } else { "no" },
                m.variant.name(),
                m.preset,
                m.match_points.map_or("all".into(), |n| n.to_string()),
                m.epochs,
                m.pairs_seen,
                m.trained_with,
                m.note
            );
        }
        md + "\n"
    }

    fn figures_markdown(&self, results: &Results, out: &Path) -> String {
        let mut md = String::from("## Figures\n\n");
        md += "Each cloud picture shows the source (orange) and the target (blue) from one \
               oblique view, before registration (left) and with the source moved by the \
               method's transform (right). Correspondence matrices follow the paper's Figure 5: \
               rows are the source points, columns the target points ordered so that the \
               ground truth is the diagonal, drawn in 36 × 36 blocks; a block is black when \
               most correspondences in it are correct, red when most are wrong, light grey when \
               it holds ground truth that was not found.\n\n";
        for (key, rows) in results {
            md += &format!("### {key}\n\n");
            for i in 0..self.figures {
                let truth = format!("figures/{key}/truth-pair{i}.png");
                if !out.join(&truth).exists() {
                    continue;
                }
                md += &format!(
                    "Pair {i}:\n\n| method | clouds: before, after | hard correspondences | \
                     MIE(R) ° | recall |\n|---|---|---|---:|---|\n"
                );
                for row in rows {
                    let Some(r) = row.records.iter().find(|r| r.index == i) else {
                        continue;
                    };
                    let (name, stem) = (&row.name, &row.stem);
                    let matrix = row.matched.get(&i).map_or(String::new(), |share| {
                        format!(
                            "![{name}: correspondences of pair {i}](figures/{key}/{stem}-matrix-pair{i}.png) ({:.1} % correct)",
                            100.0 * share
                        )
                    });
                    md += &format!(
                        "| {name} | ![{name} on pair {i}](figures/{key}/{stem}-pair{i}.png) | {matrix} | {:.2} | {} |\n",
                        r.metrics.mie_r_deg,
                        if r.metrics.recall { "yes" } else { "no" }
                    );
                }
                md += &format!("| ground truth | | ![ground truth of pair {i}]({truth}) | | |\n\n");
            }
        }
        md
    }
}

/// One table: the rows of its test set, a note where a row covers fewer pairs than the set, and
/// a line when no trained model exists for it. The ablation lists trained models only, and of
/// those only the ones at the training budget of a Var1 or Var2 model, so that it compares like
/// with like.
fn table_markdown(table: &Table, rows: &[Row]) -> String {
    let ablation_budgets: Vec<u64> = rows
        .iter()
        .filter(|r| matches!(r.variant, Some(Variant::Var1 | Variant::Var2)))
        .filter_map(|r| r.pairs_seen)
        .collect();
    let mut lines = String::new();
    let mut notes = String::new();
    let mut models = 0;
    for row in rows.iter().filter(|r| {
        !table.ablation
            || (r.variant.is_some() && r.pairs_seen.is_some_and(|p| ablation_budgets.contains(&p)))
    }) {
        models += row.variant.is_some() as usize;
        let Ok(summary) = Summary::from_records(&row.records) else {
            notes += &format!("\n{}: no pair finished yet.\n", row.name);
            continue;
        };
        let name = match (&row.variant, row.pairs_seen) {
            (Some(variant), Some(pairs)) if table.ablation => {
                format!("{} ({}, {pairs} pairs)", row.name, variant.name())
            }
            _ => row.name.clone(),
        };
        lines += &table_row(&name, table.key, &summary);
        lines.push('\n');
        if row.records.len() < row.total {
            notes += &format!(
                "\n{}: the first {} of {} pairs only (the run stopped at its time limit).\n",
                row.name,
                row.records.len(),
                row.total
            );
        }
    }
    if table.ablation && ablation_budgets.is_empty() {
        notes += "\nVar1, Var2: no trained weights (yet).\n";
    } else if models == 0 {
        notes += "\nRGM: no trained weights for this setting (yet).\n";
    }
    if lines.is_empty() {
        return notes.trim_start().to_string() + "\n";
    }
    table_header() + "\n" + &lines + &notes + "\n"
}

/// The notes on data, pairs and metrics that every results file carries.
fn data_notes() -> String {
    format!(
        "\
- **Data**: ModelNet40 with 1,024 points per shape (`../shared/data/modelnet40_npy1024`), \
official split: 2,468 test shapes, 1,266 of them in the unseen-category test split (categories \
20–39). The paper draws its 1,024 points from a 2,048-point release; source and target start \
from the same sample in both, so only the particular sample differs (`../shared/data/README.md`).
- **Pairs**: spec §1, made by `rgm-data`; test pair `i` is seeded from `i`, so every method and \
every run sees the same pairs (`docs/data.md`). Partial: each cloud cropped to 717 points and \
jittered.
- **Metrics**: spec §5, computed by `rgm-geom`. MIE: isotropic errors (degrees, length); MAE: \
anisotropic (Euler angles in degrees, per axis). CCD follows the authors' code (clipped \
Euclidean distances, means), not the paper's formula. Recall: MAE(R) < 1° and MAE(t) < 0.1.
- **Methods**: ICP point-to-point from the identity; FGR on FPFH features; both with Open3D's \
settings (see baselines.md for the agreement with Open3D). `+refine` rows: the method's transform \
refined as `rgm register` refines it (`rgm_registration::methods::refine`: {refinement}); the paper reports no refined rows. A \
trained model's `+refine` row refines the transforms of its own row (what `rgm eval --refine` \
gives, without running the network twice; its time adds the refinement's). \
`auto+refine`: `rgm register`'s default, RGM with the built-in model and FGR, both refined so, and \
per pair the result with the larger two-way overlap (`rgm_registration::compose`). The paper's learned \
peers (RPM-Net, IDAM, DeepGMR) are not reproduced here.
",
        refinement = refinement()
    )
}

/// The refinement of the `+refine` rows in words, from the settings it runs with
/// ([`RefineConfig::default`]).
fn refinement() -> String {
    let config = RefineConfig::default();
    let list = |values: &[f64], last: &str| match values {
        [] => String::new(),
        [one] => one.to_string(),
        [most @ .., end] => {
            let most: Vec<String> = most.iter().map(f64::to_string).collect();
            format!("{}{last}{end}", most.join(", "))
        }
    };
    format!(
        "trimmed point-to-plane ICP on the full clouds, pairs closer than {}, {} iterations \
         each, the closest {:.0} % of them fitted, then point-to-point ICP at {}",
        list(&config.distances, ", then "),
        config.iterations,
        100.0 * config.trim,
        list(&config.point_distances, " and ")
    )
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;
    use rgm_geom::metrics::PairMetrics;
    use rgm_geom::RigidTransform;
    use rgm_model::PairRecord;

    fn record(index: usize, recall: bool) -> PairRecord {
        PairRecord {
            index,
            transform: RigidTransform::identity(),
            ground_truth: RigidTransform::identity(),
            time_ms: 10.0,
            correspondences: 0,
            metrics: PairMetrics {
                mae_r_deg: 0.0,
                mae_t: 0.0,
                mie_r_deg: 0.0,
                mie_t: 0.0,
                ccd: 0.0,
                chamfer: 0.0,
                recall,
            },
            failure: None,
        }
    }

    fn row(name: &str, variant: Option<Variant>, records: Vec<PairRecord>, total: usize) -> Row {
        Row {
            name: name.into(),
            stem: name.into(),
            variant,
            pairs_seen: variant.map(|_| 100),
            records,
            total,
            matched: BTreeMap::new(),
        }
    }

    #[test]
    fn a_table_without_models_says_so_and_names_unfinished_rows() {
        let rows = [
            row("icp", None, vec![record(0, true), record(1, false)], 4),
            row("fgr", None, (0..4).map(|i| record(i, true)).collect(), 4),
        ];
        let md = table_markdown(&TABLES[2], &rows);
        assert_eq!(md.lines().filter(|l| l.starts_with("| ")).count(), 3);
        assert!(md.contains("| icp "), "{md}");
        assert!(md.contains("50.00%"), "{md}");
        assert!(md.contains("icp: the first 2 of 4 pairs only"), "{md}");
        assert!(!md.contains("fgr: the first"), "{md}");
        assert!(
            md.contains("no trained weights for this setting (yet)"),
            "{md}"
        );
        // The ablation lists trained models only: here none, so no table at all.
        let ablation = table_markdown(&TABLES[4], &rows);
        assert!(!ablation.contains('|'), "{ablation}");
        assert!(
            ablation.contains("Var1, Var2: no trained weights"),
            "{ablation}"
        );
    }

    #[test]
    fn the_ablation_lists_the_variants_at_equal_budget_by_name() {
        let longer = Row {
            pairs_seen: Some(900),
            ..row("partial-fast", Some(Variant::Rgm), vec![record(0, true)], 1)
        };
        let rows = [
            row("icp", None, vec![record(0, true)], 1),
            longer,
            row(
                "partial-fast-e1",
                Some(Variant::Rgm),
                vec![record(0, true)],
                1,
            ),
            row(
                "partial-var1",
                Some(Variant::Var1),
                vec![record(0, false)],
                1,
            ),
        ];
        let md = table_markdown(&TABLES[4], &rows);
        assert!(md.contains("| partial-fast-e1 (rgm, 100 pairs) "), "{md}");
        assert!(md.contains("| partial-var1 (var1, 100 pairs) "), "{md}");
        assert!(!md.contains("| partial-fast ("), "{md}");
        assert!(!md.contains("| icp"), "{md}");
        assert!(!md.contains("no trained weights"), "{md}");
        // Table 3 lists every model, by its name alone.
        let partial = table_markdown(&TABLES[2], &rows);
        assert!(partial.contains("| partial-fast "), "{partial}");
        assert!(partial.contains("| partial-var1 "), "{partial}");
    }

    #[test]
    fn the_notes_describe_the_refinement_it_runs_with() {
        assert!(data_notes().contains(
            "(`rgm_registration::methods::refine`: trimmed point-to-plane ICP on the full clouds, pairs closer \
             than 0.2, 0.1, then 0.05, 10 iterations each, the closest 80 % of them fitted, then \
             point-to-point ICP at 0.05 and 0.03); the paper reports no refined rows."
        ));
    }
}
