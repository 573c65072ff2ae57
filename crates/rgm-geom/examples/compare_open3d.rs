//! Runs rgm-geom's FGR and ICP on the pairs written by `tools/open3d_fgr_icp.py` and prints the
//! same summary as that script, plus the agreement with Open3D's transforms.
//!
//!     cargo run --release -p rgm-geom --example compare_open3d -- /tmp/cmp/pairs

use std::path::Path;
use std::time::Instant;

use rgm_geom::{fgr, icp, Matrix4, PairMetrics, Point3, PointCloud, RigidTransform};

fn read_rows(path: &Path) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .map(|l| {
            l.split_whitespace()
                .map(|v| v.parse().expect("a number"))
                .collect()
        })
        .collect()
}

fn read_cloud(path: &Path) -> PointCloud {
    PointCloud::new(
        read_rows(path)
            .iter()
            .map(|r| Point3::new(r[0], r[1], r[2]))
            .collect(),
    )
}

fn read_transform(path: &Path) -> RigidTransform {
    let rows = read_rows(path);
    let m = Matrix4::from_fn(|r, c| rows[r][c]);
    RigidTransform::from_matrix4(&m, 1e-6).expect("a rigid transform")
}

/// CPU seconds this process has used (user + system), from /proc: robust to a busy machine.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let after_name = stat.rsplit(')').next().unwrap_or("");
    let fields: Vec<f64> = after_name
        .split_whitespace()
        .map(|v| v.parse().unwrap_or(0.0))
        .collect();
    // Fields 14 and 15 of the file (utime, stime) are 12 and 13 after the name; ticks of 1/100 s.
    (fields.get(11).copied().unwrap_or(0.0) + fields.get(12).copied().unwrap_or(0.0)) / 100.0
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let dir = std::env::args().nth(1).expect("usage: compare_open3d DIR");
    let dir = Path::new(&dir);
    let (mut fgr_m, mut icp_m, mut fgr_ms, mut icp_ms, mut same) =
        (vec![], vec![], vec![], vec![], 0);
    let (mut plain_m, mut plain_ms) = (vec![], vec![]);
    let mut cpu = [0.0; 3]; // CPU seconds in FGR, FGR with Open3D's defaults, ICP
                            // Open3D's actual default keeps μ fixed; ours decreases it (graduated non-convexity).
    let open3d_default = fgr::FgrConfig {
        decrease_mu: false,
        ..fgr::FgrConfig::default()
    };
    for i in 0.. {
        let file = |what: &str| dir.join(format!("{i:04}_{what}.txt"));
        if !file("src").exists() {
            break;
        }
        let (src, tgt, gt) = (
            read_cloud(&file("src")),
            read_cloud(&file("tgt")),
            read_transform(&file("gt")),
        );
        let (t, c0) = (Instant::now(), cpu_seconds());
        let f = fgr::register(&src, &tgt, &fgr::FgrConfig::default()).expect("fgr");
        fgr_ms.push(t.elapsed().as_secs_f64() * 1e3);
        let (t, c1) = (Instant::now(), cpu_seconds());
        let plain = fgr::register(&src, &tgt, &open3d_default).expect("fgr");
        plain_ms.push(t.elapsed().as_secs_f64() * 1e3);
        let (t, c2) = (Instant::now(), cpu_seconds());
        let c = icp::register(&src, &tgt, &icp::IcpConfig::default()).expect("icp");
        icp_ms.push(t.elapsed().as_secs_f64() * 1e3);
        let c3 = cpu_seconds();
        cpu = [cpu[0] + c1 - c0, cpu[1] + c2 - c1, cpu[2] + c3 - c2];
        let open3d = read_transform(&file("open3d_fgr"));
        let agree =
            PairMetrics::compute(&plain.t_target_source, &open3d, &src, &tgt).expect("metrics");
        same += usize::from(agree.mie_r_deg < 1.0);
        plain_m
            .push(PairMetrics::compute(&plain.t_target_source, &gt, &src, &tgt).expect("metrics"));
        fgr_m.push(PairMetrics::compute(&f.t_target_source, &gt, &src, &tgt).expect("metrics"));
        icp_m.push(PairMetrics::compute(&c.t_target_source, &gt, &src, &tgt).expect("metrics"));
    }
    let n = fgr_m.len();
    let show = |name: &str, m: &[PairMetrics], ms: Vec<f64>, cpu_s: f64| {
        let s = rgm_geom::MetricsSummary::from_pairs(m).expect("pairs");
        println!(
            "rgm {name}: MAE(R) {:.3} MAE(t) {:.4} recall {:.3} median time {:.1} ms, mean CPU {:.1} ms",
            s.mae_r_deg,
            s.mae_t,
            s.recall,
            median(ms),
            1e3 * cpu_s / m.len() as f64
        );
    };
    println!("pairs {n}");
    show("FGR", &fgr_m, fgr_ms, cpu[0]);
    show(
        "FGR (decrease_mu false, Open3D's default)",
        &plain_m,
        plain_ms,
        cpu[1],
    );
    show("ICP", &icp_m, icp_ms, cpu[2]);
    println!("FGR with Open3D's defaults within 1° of Open3D's FGR transform: {same} of {n}");
}
