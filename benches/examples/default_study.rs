//! The measurements behind `rgm register`'s default, on validation pairs: how the
//! refinement ends, which score picks between RGM and FGR, and what the network's frame does.
//!
//! ```text
//! cargo run --release -p rgm-benches --example default_study -- --data DIR \
//!     [--setting partial] [--limit 300] [--stride 1] [--offset 0] [--split validation] \
//!     [--frame native|centred] [--study choices|cascade|robustness|network] \
//!     [--versions 'as they are,half size,twice the size,20000 points each'] \
//!     [--variants '2/384/both,1/384/both,1/256/both,2/384/one'] [--json FILE]
//! ```
//!
//! The pairs are `offset`, `offset + stride`, `offset + 2·stride`, … (at most `limit` of them).
//! The splits are ordered by category (the first 200 partial test pairs are airplanes, bathtubs
//! and beds), so a sample meant to speak for a split takes a stride, not its first pairs.
//!
//! `--study cascade` runs `rgm register`'s default with both candidates on each pair and, from
//! their overlap scores, outcomes and times, prints what a cascade would give: FGR first, the
//! network only when FGR's score (0 to 2; a partial pair registered right scores about 1) is
//! below a threshold or its turned share (`rgm_registration::check::turned_share`) above a limit (then
//! the better of the two, as the default picks). Run it on one thread (`RAYON_NUM_THREADS=1`)
//! so that each candidate's time is its own. `--dump FILE` writes each pair's scores, outcomes,
//! times and turned share to FILE, one line per pair.
//!
//! `--study robustness` instead runs `rgm register`'s default on each pair as it is, at half
//! and at twice its size, and with each cloud made of 20,000 points (every point repeated, with
//! N(0, 0.005²) noise), and prints each version's recall (transforms scaled back to the pair's
//! size) and time.
//!
//! `--study network` runs `rgm register`'s default with each variant of its network stage on
//! each pair, the variants one after the other on the same pair (so that a changing load
//! weighs on all of them alike): `PASSES/MATCH_POINTS/CHAINS[/ACCEPT]`, CHAINS `both` (cycle
//! consistency, the paper's) or `one` (the forward chain alone), ACCEPT the cascade's score
//! threshold (the default's when left out). Printed per variant: recall, the share off by more
//! than 45°, mean and median ms per pair, the pairs running the network, and the pairs whose
//! outcome differs from the first variant's. `--json FILE` writes each pair's outcome and time
//! per variant.
//!
//! For each pair: RGM (the built-in model, unrefined) and FGR give a start; each refinement
//! variant refines both starts; each score picks a candidate per pair. Printed: one row per
//! (refinement, score) with recall, the share off by more than 45° and the median MIE(R) of the
//! recalled pairs. `--frame centred` moves each pair into the frame of
//! `Normalisation::centred` before everything (the transform is reported back in the pair's frame).

use std::time::Instant;

use rgm_data::{ModelNet40, PairGenerator, Setting, Split};
use rgm_geom::frame::Normalisation;
use rgm_geom::metrics::PairMetrics;
use rgm_geom::{KnnIndex, PointCloud, RigidTransform};
use rgm_model::policy::TUNED;
use rgm_model::{MethodOptions, Registrar};
use rgm_registration::check::turned_share;
use rgm_registration::fit::score;
use rgm_registration::methods::fgr::{self, FgrConfig};
use rgm_registration::methods::refine::{self, RefineConfig};

fn arg(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

/// The refinements compared: `rgm_registration::methods::refine`'s point-to-plane stages alone, then with
/// point-to-point stages at these distances (`RefineConfig::point_distances`).
const REFINEMENTS: [(&str, &[f64]); 4] = [
    ("plane", &[]),
    ("plane + point 0.05", &[0.05]),
    ("plane + point 0.03", &[0.03]),
    ("plane + point 0.05, 0.03", &[0.05, 0.03]),
];

fn refined(
    s: &PointCloud,
    t: &PointCloud,
    start: &RigidTransform,
    points: &[f64],
) -> RigidTransform {
    let config = RefineConfig {
        point_distances: points.to_vec(),
        ..RefineConfig::default()
    };
    refine::refine(s, t, start, &config)
        .map(|r| r.t_target_source)
        .unwrap_or(*start)
}

/// A score of a transform without ground truth: higher is better.
type Score = (
    &'static str,
    fn(&PointCloud, &KnnIndex, &PointCloud, &KnnIndex, &RigidTransform) -> f64,
);

fn fitness(s: &PointCloud, ti: &KnnIndex, t: &RigidTransform, d: f64) -> f64 {
    score(&s.points, ti, t, d, None).fitness
}

/// Mean of min(d, clip) from the moved source to the target and back (the CCD of spec §5 at
/// `clip`), negated.
fn neg_ccd(
    s: &PointCloud,
    si: &KnnIndex,
    tc: &PointCloud,
    ti: &KnnIndex,
    t: &RigidTransform,
    clip: f64,
) -> f64 {
    let inv = t.inverse();
    let there: f64 = s
        .points
        .iter()
        .map(|p| ti.nearest(&t.apply(p)).1.min(clip))
        .sum::<f64>()
        / s.len() as f64;
    let back: f64 = tc
        .points
        .iter()
        .map(|q| si.nearest(&inv.apply(q)).1.min(clip))
        .sum::<f64>()
        / tc.len() as f64;
    -(there + back)
}

const SCORES: [Score; 6] = [
    ("fitness 0.05", |s, _, _, ti, t| fitness(s, ti, t, 0.05)),
    ("fitness 0.02", |s, _, _, ti, t| fitness(s, ti, t, 0.02)),
    ("fitness 0.02 both ways", |s, si, tc, ti, t| {
        fitness(s, ti, t, 0.02) + fitness(tc, si, &t.inverse(), 0.02)
    }),
    ("CCD 0.1", |s, si, tc, ti, t| neg_ccd(s, si, tc, ti, t, 0.1)),
    ("CCD 0.05", |s, si, tc, ti, t| {
        neg_ccd(s, si, tc, ti, t, 0.05)
    }),
    ("CCD 0.03", |s, si, tc, ti, t| {
        neg_ccd(s, si, tc, ti, t, 0.03)
    }),
];

struct Outcome {
    recall: bool,
    mie_r: f64,
}

fn outcome(t: &RigidTransform, gt: &RigidTransform, s: &PointCloud, tc: &PointCloud) -> Outcome {
    let m = PairMetrics::compute(t, gt, s, tc).expect("non-empty clouds");
    Outcome {
        recall: m.recall,
        mie_r: m.mie_r_deg,
    }
}

/// Recall, the share off by more than 45°, and the median MIE(R) of the recalled pairs.
fn summary(outcomes: &[Outcome]) -> (f64, f64, f64) {
    let n = outcomes.len() as f64;
    let recall = outcomes.iter().filter(|o| o.recall).count() as f64 / n;
    let wild = outcomes.iter().filter(|o| o.mie_r > 45.0).count() as f64 / n;
    let mut good: Vec<f64> = outcomes
        .iter()
        .filter(|o| o.recall)
        .map(|o| o.mie_r)
        .collect();
    good.sort_by(f64::total_cmp);
    let median = good.get(good.len() / 2).copied().unwrap_or(f64::NAN);
    (recall, wild, median)
}

fn row(name: &str, outcomes: &[Outcome]) {
    let (recall, wild, median) = summary(outcomes);
    println!(
        "| {name:<58} | {:>6.2} % | {:>5.2} % | {:>6.3}° |",
        100.0 * recall,
        100.0 * wild,
        median
    );
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    rgm_nn::threads::flush_denormals_to_zero();
    let args: Vec<String> = std::env::args().collect();
    let data = arg(&args, "--data").unwrap_or_else(|| "../shared/data/modelnet40_npy1024".into());
    let setting: Setting = arg(&args, "--setting")
        .unwrap_or_else(|| "partial".into())
        .parse()?;
    let limit: usize = arg(&args, "--limit").map_or(Ok(300), |v| v.parse())?;
    let stride: usize = arg(&args, "--stride").map_or(Ok(1), |v| v.parse())?;
    let offset: usize = arg(&args, "--offset").map_or(Ok(0), |v| v.parse())?;
    if stride == 0 {
        return Err("--stride must be positive".into());
    }
    let split = match arg(&args, "--split").as_deref() {
        Some("test") => Split::Test,
        _ => Split::Validation,
    };
    let centred = arg(&args, "--frame").as_deref() == Some("centred");
    let dataset = ModelNet40::open(&data)?;
    let shapes = dataset.split(split, false);
    let generator = PairGenerator::new(setting);
    // The pair indices of the sample (each pair is made from its index: the same pairs as the
    // tables' for the test split).
    let indices: Vec<usize> = (offset..shapes.len()).step_by(stride).take(limit).collect();
    if arg(&args, "--study").as_deref() == Some("cascade") {
        return cascade(&generator, &shapes, &indices, arg(&args, "--dump"));
    }
    if arg(&args, "--study").as_deref() == Some("network") {
        let variants = arg(&args, "--variants")
            .unwrap_or_else(|| "2/384/both,1/384/both,1/256/both,2/384/one".into());
        return network(
            &generator,
            &shapes,
            &indices,
            &variants,
            arg(&args, "--json"),
        );
    }
    if arg(&args, "--study").as_deref() == Some("robustness") {
        let versions = arg(&args, "--versions")
            .unwrap_or_else(|| "as they are,half size,twice the size,20000 points each".into());
        let versions: Vec<&str> = versions.split(',').collect();
        return robustness(&generator, &shapes, &indices, &versions);
    }
    let mut rgm = MethodOptions {
        refine: false,
        ..MethodOptions::default()
    }
    .build()?;
    let fgr_config = FgrConfig::default();

    let n = indices.len();
    // [start][refinement][candidate]: candidate 0 RGM, 1 FGR.
    let mut transforms: Vec<Vec<[RigidTransform; 2]>> = Vec::new();
    let mut pairs = Vec::new();
    let (mut rgm_ms, mut fgr_ms, mut refine_ms) = (0.0, 0.0, vec![0.0; REFINEMENTS.len()]);
    for (done, &i) in indices.iter().enumerate() {
        let pair = generator.test_pair(&shapes, i)?;
        let frame = if centred {
            Normalisation::centred(&pair.source, &pair.target)
        } else {
            Normalisation::identity()
        };
        let (s, t) = (frame.source(&pair.source), frame.target(&pair.target));
        let clock = Instant::now();
        let start_rgm = rgm
            .register(&s, &t)
            .map(|r| r.result.t_target_source)
            .unwrap_or_else(|_| RigidTransform::identity());
        rgm_ms += clock.elapsed().as_secs_f64() * 1e3;
        let clock = Instant::now();
        let start_fgr = fgr::register(&s, &t, &fgr_config)
            .map(|r| r.t_target_source)
            .unwrap_or_else(|_| RigidTransform::identity());
        fgr_ms += clock.elapsed().as_secs_f64() * 1e3;
        let mut per = vec![[start_rgm, start_fgr]];
        for (k, (_, points)) in REFINEMENTS.iter().enumerate() {
            let clock = Instant::now();
            per.push([
                refined(&s, &t, &start_rgm, points),
                refined(&s, &t, &start_fgr, points),
            ]);
            refine_ms[k] += clock.elapsed().as_secs_f64() * 1e3 / 2.0;
        }
        transforms.push(per);
        pairs.push((pair, frame, s, t));
        if (done + 1) % 50 == 0 {
            eprintln!("{} / {n} pairs", done + 1);
        }
    }
    let mean = |ms: f64| ms / n as f64;
    println!(
        "{n} {} {:?} pairs, frame {}; ms per pair: RGM {:.1}, FGR {:.1}, refinements {:?}\n",
        setting.name(),
        split,
        if centred { "centred" } else { "native" },
        mean(rgm_ms),
        mean(fgr_ms),
        refine_ms
            .iter()
            .map(|&ms| (mean(ms) * 10.0).round() / 10.0)
            .collect::<Vec<_>>()
    );
    println!("| candidates and choice | recall | > 45° | median MIE(R), recalled |");
    println!("|---|---:|---:|---:|");
    let evaluate = |choose: &dyn Fn(usize) -> RigidTransform| -> Vec<Outcome> {
        (0..n)
            .map(|i| {
                let (pair, frame, _, _) = &pairs[i];
                outcome(
                    &frame.undo(&choose(i)),
                    &pair.t_target_source,
                    &pair.source,
                    &pair.target,
                )
            })
            .collect()
    };
    let names = std::iter::once("start").chain(REFINEMENTS.iter().map(|r| r.0));
    for (k, name) in names.enumerate() {
        row(&format!("RGM, {name}"), &evaluate(&|i| transforms[i][k][0]));
        row(&format!("FGR, {name}"), &evaluate(&|i| transforms[i][k][1]));
        let oracle: Vec<Outcome> = (0..n)
            .map(|i| {
                let (pair, frame, _, _) = &pairs[i];
                let [a, b] = transforms[i][k].map(|t| {
                    outcome(
                        &frame.undo(&t),
                        &pair.t_target_source,
                        &pair.source,
                        &pair.target,
                    )
                });
                if a.recall || (!b.recall && a.mie_r < b.mie_r) {
                    a
                } else {
                    b
                }
            })
            .collect();
        row(&format!("either, {name}: oracle"), &oracle);
        for (score_name, f) in SCORES {
            for keep_start in [false, true] {
                if keep_start && k == 0 {
                    continue;
                }
                let chosen = evaluate(&|i| {
                    let (_, _, s, t) = &pairs[i];
                    let (si, ti) = (KnnIndex::new(&s.points), KnnIndex::new(&t.points));
                    let mut options: Vec<RigidTransform> = transforms[i][k].to_vec();
                    if keep_start {
                        options.extend(transforms[i][0]);
                    }
                    *options
                        .iter()
                        .max_by(|a, b| f(s, &si, t, &ti, a).total_cmp(&f(s, &si, t, &ti, b)))
                        .expect("two candidates")
                });
                let how = if keep_start { " or its start" } else { "" };
                row(&format!("either{how}, {name}: by {score_name}"), &chosen);
            }
        }
    }
    Ok(())
}

/// The pair's clouds scaled by `k` about the origin.
fn scaled(cloud: &PointCloud, k: f64) -> PointCloud {
    PointCloud::new(cloud.points.iter().map(|p| p * k).collect())
}

/// `n` points: the cloud's points over and over, each copy moved by N(0, σ²) noise (seeded).
fn densified(cloud: &PointCloud, n: usize, seed: u64) -> PointCloud {
    use rand::SeedableRng;
    use rand_distr::Distribution;
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let noise = rand_distr::Normal::new(0.0, 0.005).expect("a valid σ");
    PointCloud::new(
        (0..n)
            .map(|i| {
                let p = cloud.points[i % cloud.len()];
                p + rgm_geom::Vector3::new(
                    noise.sample(&mut rng),
                    noise.sample(&mut rng),
                    noise.sample(&mut rng),
                )
            })
            .collect(),
    )
}

/// One candidate of the default on one pair: its outcome, overlap score and time.
struct Tried {
    outcome: Outcome,
    score: f64,
    ms: f64,
}

/// The distances of the dump's looser overlap scores (unit-sphere units).
const LOOSE_DISTANCES: [f64; 3] = [0.03, 0.04, 0.05];

fn cascade(
    generator: &PairGenerator,
    shapes: &[&rgm_data::Shape],
    indices: &[usize],
    dump: Option<String>,
) -> Result<(), Box<dyn std::error::Error>> {
    use std::io::Write;
    // One line per pair for other thresholds: index, then per candidate (FGR, RGM) score,
    // recall, MIE(R) and ms, then FGR's turned share, then FGR's overlap score at each of
    // `LOOSE_DISTANCES` (a whole overlap that noise hides at the default's distance).
    let mut dump = dump.map(std::fs::File::create).transpose()?;
    // Both candidates on every pair, FGR's first, so that any cascade can be read off.
    let mut method = MethodOptions {
        accept: f64::INFINITY,
        ..MethodOptions::default()
    }
    .build()?;
    // Per pair: FGR's and RGM's outcomes, and FGR's turned share.
    let mut pairs: Vec<([Tried; 2], f64)> = Vec::new();
    for (done, &i) in indices.iter().enumerate() {
        let pair = generator.test_pair(shapes, i)?;
        let found = method.register(&pair.source, &pair.target)?;
        let tried = |k: usize| {
            let c = &found.candidates[k];
            Tried {
                outcome: outcome(
                    &c.t_target_source,
                    &pair.t_target_source,
                    &pair.source,
                    &pair.target,
                ),
                score: c.score.unwrap_or(f64::NEG_INFINITY),
                ms: c.time_ms,
            }
        };
        // FGR's transform in the frame where the default scores it.
        let frame = Normalisation::of_pair(&pair.source, &pair.target, &TUNED.frame);
        let s = frame.source(&pair.source.select(&TUNED.frame.near(&pair.source)));
        let t = frame.target(&pair.target.select(&TUNED.frame.near(&pair.target)));
        let (si, ti) = (KnnIndex::new(&s.points), KnnIndex::new(&t.points));
        let fgr = frame.redo(&found.candidates[0].t_target_source);
        let distance = rgm_model::policy::TUNED.scoring.overlap_distance;
        let turned = turned_share((&s, &si), (&t, &ti), &fgr, distance);
        let loose: Vec<String> = LOOSE_DISTANCES
            .iter()
            .map(|&d| {
                let there = score(&s.points, &ti, &fgr, d, None).fitness;
                let back = score(&t.points, &si, &fgr.inverse(), d, None).fitness;
                (there + back).to_string()
            })
            .collect();
        let both = [tried(0), tried(1)];
        if let Some(file) = &mut dump {
            let fields: Vec<String> = both
                .iter()
                .map(|c| {
                    format!(
                        "{} {} {} {}",
                        c.score, c.outcome.recall, c.outcome.mie_r, c.ms
                    )
                })
                .collect();
            writeln!(
                file,
                "{i} {} {turned} {}",
                fields.join(" "),
                loose.join(" ")
            )?;
        }
        pairs.push((both, turned));
        if (done + 1) % 50 == 0 {
            eprintln!("{} of {} pairs", done + 1, indices.len());
        }
    }
    let n = pairs.len() as f64;
    println!(
        "| threshold | turned share at most | recall | > 45° | ms / pair (candidates) | pairs running the network |"
    );
    println!("|---:|---:|---:|---:|---:|---:|");
    for threshold in [0.0, 0.3, 0.5, 0.6, 0.7, 0.8, 1.0, 1.2, f64::INFINITY] {
        for turned_at_most in [f64::INFINITY, 1.0, 0.8, 0.6, 0.5, 0.4, 0.3] {
            if threshold == f64::INFINITY && turned_at_most != f64::INFINITY {
                continue;
            }
            let mut outcomes = Vec::new();
            let (mut ms, mut second) = (0.0, 0);
            for ([fgr, rgm], turned) in &pairs {
                ms += fgr.ms;
                let pick = if fgr.score >= threshold && *turned <= turned_at_most {
                    fgr
                } else {
                    second += 1;
                    ms += rgm.ms;
                    // The default's choice: the higher score, ties to FGR (the earlier).
                    if rgm.score > fgr.score {
                        rgm
                    } else {
                        fgr
                    }
                };
                outcomes.push(Outcome {
                    recall: pick.outcome.recall,
                    mie_r: pick.outcome.mie_r,
                });
            }
            let (recall, wild, _) = summary(&outcomes);
            println!(
                "| {threshold} | {turned_at_most} | {:.2} % | {:.2} % | {:.0} | {:.1} % |",
                100.0 * recall,
                100.0 * wild,
                ms / n,
                100.0 * second as f64 / n
            );
        }
    }
    Ok(())
}

fn robustness(
    generator: &PairGenerator,
    shapes: &[&rgm_data::Shape],
    indices: &[usize],
    versions: &[&str],
) -> Result<(), Box<dyn std::error::Error>> {
    let n = indices.len();
    let mut method = MethodOptions::default().build()?;
    println!(
        "| `{}` on {n} {} pairs | recall | > 45° | median MIE(R), recalled | ms / pair | its candidates' recall |",
        method.name(),
        generator.setting.name()
    );
    println!("|---|---:|---:|---:|---:|---|");
    for (name, scale, points) in [
        ("as they are", 1.0, None),
        ("half size", 0.5, None),
        ("twice the size", 2.0, None),
        ("20000 points each", 1.0, Some(20_000)),
    ] {
        if !versions.contains(&name) {
            continue;
        }
        let (mut outcomes, mut ms) = (Vec::new(), 0.0);
        // Each candidate's outcomes, by its name (`rgm+refine`, `fgr+refine`, `…/cells`).
        let mut per_candidate: std::collections::BTreeMap<String, Vec<Outcome>> =
            Default::default();
        for &i in indices {
            let pair = generator.test_pair(shapes, i)?;
            let (s, t) = match points {
                Some(p) => (
                    densified(&pair.source, p, 2 * i as u64),
                    densified(&pair.target, p, 2 * i as u64 + 1),
                ),
                None => (scaled(&pair.source, scale), scaled(&pair.target, scale)),
            };
            let back = |t: &RigidTransform| {
                let native = RigidTransform::new(t.rotation, t.translation / scale);
                outcome(&native, &pair.t_target_source, &pair.source, &pair.target)
            };
            match method.register(&s, &t) {
                Ok(r) => {
                    ms += r.time_ms;
                    outcomes.push(back(&r.result.t_target_source));
                    for c in &r.candidates {
                        per_candidate
                            .entry(c.method.clone())
                            .or_default()
                            .push(back(&c.t_target_source));
                    }
                }
                Err(_) => outcomes.push(back(&RigidTransform::identity())),
            }
        }
        let (recall, wild, median) = summary(&outcomes);
        // A candidate's recall over the pairs where it ran (a dense pair has more of them).
        let candidates: Vec<String> = per_candidate
            .iter()
            .map(|(method, outcomes)| {
                let (recall, _, _) = summary(outcomes);
                format!("{method} {:.2} % of {}", 100.0 * recall, outcomes.len())
            })
            .collect();
        println!(
            "| {name} | {:.2} % | {:.2} % | {median:.3}° | {:.0} | {} |",
            100.0 * recall,
            100.0 * wild,
            ms / n as f64,
            candidates.join("; ")
        );
    }
    Ok(())
}

/// One variant of the cascade's network stage (`--study network`).
struct Variant {
    name: String,
    method: rgm_model::Method,
}

impl Variant {
    /// `PASSES/MATCH_POINTS/CHAINS[/ACCEPT]`.
    fn parse(spec: &str) -> Result<Self, Box<dyn std::error::Error>> {
        let fields: Vec<&str> = spec.split('/').collect();
        let (passes, points, chains) = match fields[..] {
            [p, m, c] | [p, m, c, _] => (p.parse::<usize>()?, m.parse::<usize>()?, c),
            _ => {
                return Err(
                    format!("variant {spec:?}: expected PASSES/POINTS/CHAINS[/ACCEPT]").into(),
                )
            }
        };
        let accept = match fields.get(3) {
            Some(a) => a.parse::<f64>()?,
            None => rgm_model::policy::TUNED.accept.score,
        };
        let mut rgm = rgm_model::weights::builtin_registrar()?;
        rgm.config.passes = passes;
        rgm.config.match_points = Some(points);
        rgm.config.cycle_consistency = match chains {
            "both" => true,
            "one" => false,
            _ => return Err(format!("variant {spec:?}: chains are both or one").into()),
        };
        let acceptance = rgm_registration::check::Acceptance {
            score: accept,
            ..rgm_model::policy::TUNED.accept
        };
        Ok(Self {
            name: spec.to_string(),
            method: rgm_model::options::auto(
                rgm,
                Some(RefineConfig::default()),
                acceptance,
                rgm_model::options::DenseStage::ObjectThenScene,
            ),
        })
    }
}

fn network(
    generator: &PairGenerator,
    shapes: &[&rgm_data::Shape],
    indices: &[usize],
    variants: &str,
    json: Option<String>,
) -> Result<(), Box<dyn std::error::Error>> {
    let mut variants: Vec<Variant> = variants
        .split(',')
        .map(Variant::parse)
        .collect::<Result<_, _>>()?;
    // [variant][pair]: outcome, ms, whether the network ran.
    let mut results: Vec<Vec<(Outcome, f64, bool)>> = variants.iter().map(|_| Vec::new()).collect();
    for (done, &i) in indices.iter().enumerate() {
        let pair = generator.test_pair(shapes, i)?;
        for (v, variant) in variants.iter_mut().enumerate() {
            let clock = Instant::now();
            let found = variant.method.register(&pair.source, &pair.target);
            let ms = clock.elapsed().as_secs_f64() * 1e3;
            let (t, network) = match &found {
                Ok(r) => (
                    r.result.t_target_source,
                    r.candidates.iter().any(|c| c.method.starts_with("rgm")),
                ),
                Err(_) => (RigidTransform::identity(), false),
            };
            let o = outcome(&t, &pair.t_target_source, &pair.source, &pair.target);
            results[v].push((o, ms, network));
        }
        if (done + 1) % 50 == 0 {
            eprintln!("{} of {} pairs", done + 1, indices.len());
        }
    }
    let n = indices.len() as f64;
    println!("| variant (passes/points/chains[/accept]) | recall | > 45° | ms / pair (mean) | median | pairs running the network | outcomes changed |");
    println!("|---|---:|---:|---:|---:|---:|---:|");
    for (variant, rows) in variants.iter().zip(&results) {
        let outcomes: Vec<Outcome> = rows
            .iter()
            .map(|(o, _, _)| Outcome {
                recall: o.recall,
                mie_r: o.mie_r,
            })
            .collect();
        let (recall, wild, _) = summary(&outcomes);
        let mut ms: Vec<f64> = rows.iter().map(|r| r.1).collect();
        let mean = ms.iter().sum::<f64>() / n;
        ms.sort_by(f64::total_cmp);
        let network = rows.iter().filter(|r| r.2).count() as f64 / n;
        let changed = rows
            .iter()
            .zip(&results[0])
            .filter(|(a, b)| a.0.recall != b.0.recall || (a.0.mie_r > 45.0) != (b.0.mie_r > 45.0))
            .count();
        println!(
            "| {} | {:.2} % | {:.2} % | {mean:.1} | {:.1} | {:.1} % | {changed} |",
            variant.name,
            100.0 * recall,
            100.0 * wild,
            ms[ms.len() / 2],
            100.0 * network
        );
    }
    if let Some(path) = json {
        let pairs: Vec<String> = indices
            .iter()
            .enumerate()
            .map(|(k, i)| {
                let per: Vec<String> = results
                    .iter()
                    .map(|r| {
                        let (o, ms, net) = &r[k];
                        format!(
                            "{{\"recall\":{},\"mie_r_deg\":{},\"ms\":{ms},\"network\":{net}}}",
                            o.recall, o.mie_r
                        )
                    })
                    .collect();
                format!("{{\"index\":{i},\"variants\":[{}]}}", per.join(","))
            })
            .collect();
        let names: Vec<String> = variants.iter().map(|v| format!("{:?}", v.name)).collect();
        std::fs::write(
            path,
            format!(
                "{{\"variants\":[{}],\"pairs\":[\n{}\n]}}\n",
                names.join(","),
                pairs.join(",\n")
            ),
        )?;
    }
    Ok(())
}
