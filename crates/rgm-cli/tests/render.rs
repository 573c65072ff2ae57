//! `rgm render`: the picture of a registration, from a transform file or a method.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use rgm_data::{read_point_cloud, write_point_cloud};
use rgm_geom::euler::rotation_xyz_intrinsic;
use rgm_geom::{RigidTransform, Vector3};
use rgm_tests::Scratch;

use rgm_viz::{registration_figure, PANEL_SIZE as PANEL, WHITE};

fn rgm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rgm"))
        .args(args)
        .output()
        .expect("the rgm binary runs")
}

/// A test shape as source and the same shape moved by a known pose as target.
fn clouds(dir: &Path) -> (String, String, RigidTransform) {
    let data = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/modelnet40_npy1024/airplane/test/airplane_0627.npy");
    let source = read_point_cloud(data).unwrap();
    let pose = RigidTransform::new(
        rotation_xyz_intrinsic(0.4, 0.1, 0.5),
        Vector3::new(0.2, -0.1, 0.3),
    );
    let (src, tgt) = (dir.join("src.ply"), dir.join("tgt.ply"));
    write_point_cloud(&src, &source).unwrap();
    write_point_cloud(&tgt, &source.transformed(&pose)).unwrap();
    let path = |p: PathBuf| p.to_str().unwrap().to_string();
    (path(src), path(tgt), pose)
}

/// Writes `t` as `rgm register` prints it.
fn write_transform(path: &Path, t: &RigidTransform) {
    let mut text = String::from("# transform target ← source\n");
    for row in t.to_rows() {
        text += &format!("{} {} {} {}\n", row[0], row[1], row[2], row[3]);
    }
    std::fs::write(path, text).unwrap();
}

/// The picture's size and its pixels (row-major RGB).
fn decode(path: &Path) -> (usize, usize, Vec<[u8; 3]>) {
    let decoder = png::Decoder::new(std::fs::File::open(path).unwrap());
    let mut reader = decoder.read_info().unwrap();
    let mut data = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut data).unwrap();
    let pixels = data.chunks(3).map(|p| [p[0], p[1], p[2]]).collect();
    (info.width as usize, info.height as usize, pixels)
}

/// Pixels drawn on (not background) in the right-hand (after) panel, separator excluded.
fn drawn_after(pixels: &[[u8; 3]], width: usize) -> usize {
    pixels
        .iter()
        .enumerate()
        .filter(|(k, p)| k % width > PANEL && **p != WHITE)
        .count()
}

fn render(src: &str, tgt: &str, transform: &Path, out: &Path) -> (usize, usize, Vec<[u8; 3]>) {
    let output = rgm(&[
        "render",
        src,
        tgt,
        "--transform",
        transform.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    decode(out)
}

#[test]
fn the_true_transform_puts_the_source_on_the_target() {
    let dir = Scratch::new("render-true");
    let (src, tgt, pose) = clouds(&dir);
    let (right, wrong) = (dir.join("right.txt"), dir.join("identity.txt"));
    write_transform(&right, &pose);
    write_transform(&wrong, &RigidTransform::identity());
    let (width, height, aligned) = render(&src, &tgt, &right, &dir.join("right.png"));
    assert_eq!((width, height), (2 * PANEL, PANEL));
    // The command draws exactly the library's figure of the clouds it read.
    let (source, target) = (
        read_point_cloud(&src).unwrap(),
        read_point_cloud(&tgt).unwrap(),
    );
    let expected = registration_figure(&source, &target, &pose).unwrap();
    for (k, p) in aligned.iter().enumerate() {
        assert_eq!(Some(*p), expected.pixel(k % width, k / width), "pixel {k}");
    }
    // After the true transform the source covers the target's own footprint; after the
    // identity the two clouds lie apart and cover much more.
    let (_, _, apart) = render(&src, &tgt, &wrong, &dir.join("identity.png"));
    let (on, off) = (drawn_after(&aligned, width), drawn_after(&apart, width));
    assert!(on > 2000, "{on}");
    assert!(5 * on < 4 * off, "{on} pixels aligned vs {off} apart");
}

#[test]
fn renders_what_register_json_found() {
    let dir = Scratch::new("render-json");
    let (src, tgt, pose) = clouds(&dir);
    let out = rgm(&["register", &src, &tgt, "--method", "fgr", "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json = dir.join("found.json");
    std::fs::write(&json, &out.stdout).unwrap();
    let (width, _, found) = render(&src, &tgt, &json, &dir.join("found.png"));
    let right = dir.join("right.txt");
    write_transform(&right, &pose);
    let (_, _, truth) = render(&src, &tgt, &right, &dir.join("right.png"));
    // FGR's transform on a clean pair is the true one up to ~1e-4: the same footprint.
    let (a, b) = (drawn_after(&found, width), drawn_after(&truth, width));
    assert!(a.abs_diff(b) * 50 < b, "{a} vs {b} pixels");
}

#[test]
fn a_transform_file_with_missing_numbers_is_refused_clearly() {
    let dir = Scratch::new("render-bad");
    let (src, tgt, _) = clouds(&dir);
    let bad = dir.join("bad.txt");
    std::fs::write(&bad, "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0\n").unwrap();
    let out = rgm(&[
        "render",
        &src,
        &tgt,
        "--transform",
        bad.to_str().unwrap(),
        "--out",
        dir.join("x.png").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("15 numbers"), "{err}");
}

/// `rgm render` of the known pair with `method`, asking for the correspondence matrix against
/// the true pose: the scratch folder (clouds.png, matrix.png) and the command's output.
fn render_matrix(name: &str, method: &str) -> (Scratch, Output) {
    let dir = Scratch::new(&format!("render-{name}"));
    let (src, tgt, pose) = clouds(&dir);
    let truth = dir.join("truth.txt");
    write_transform(&truth, &pose);
    let path = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let out = rgm(&[
        "render",
        &src,
        &tgt,
        "--method",
        method,
        "--out",
        &path("clouds.png"),
        "--matrix",
        &path("matrix.png"),
        "--truth",
        truth.to_str().unwrap(),
    ]);
    (dir, out)
}

#[test]
fn the_matrix_of_a_classical_method_is_its_inliers() {
    let (dir, out) = render_matrix("matrix", "fgr");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // FGR registers the clean pair: its inliers are the true correspondences.
    let said = String::from_utf8_lossy(&out.stdout);
    let correct: f64 = said
        .split(", ")
        .find_map(|part| part.strip_suffix(" % correct\n"))
        .and_then(|share| share.trim().parse().ok())
        .unwrap_or_else(|| panic!("{said}"));
    assert!(correct > 90.0, "{said}");
    assert!(dir.join("matrix.png").exists());
}

#[test]
fn the_matrix_of_the_built_in_model_is_drawn_in_blocks() {
    let (dir, out) = render_matrix("rgm-matrix", "rgm");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("% correct"));
    // 1,024 × 1,024 in blocks of 29 rows and columns: 36 blocks of 10 pixels a side.
    let (width, height, pixels) = decode(&dir.join("matrix.png"));
    assert_eq!((width, height), (360, 360));
    // The clean pair's ground truth is a full permutation: every diagonal block holds some
    // of it, so none is white, whatever the model found.
    for b in 0..36 {
        let centre = b * 10 + 5;
        assert_ne!(pixels[centre * width + centre], WHITE, "diagonal block {b}");
    }
}

/// The JSON data of the page at `path`.
fn page_data(path: &Path) -> serde_json::Value {
    let page = std::fs::read_to_string(path).unwrap();
    let start = page.find(r#"type="application/json">"#).unwrap() + 24;
    let end = start + page[start..].find("</script>").unwrap();
    serde_json::from_str(&page[start..end]).unwrap()
}

#[test]
fn render_html_writes_the_page_of_a_given_transform_without_a_png() {
    let dir = Scratch::new("render-html-given");
    let (src, tgt, pose) = clouds(&dir);
    let transform = dir.join("t.txt");
    write_transform(&transform, &pose);
    let page = dir.join("page.html");
    let out = rgm(&[
        "render",
        &src,
        &tgt,
        "--transform",
        transform.to_str().unwrap(),
        "--html",
        page.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let data = page_data(&page);
    assert_eq!(data["source"]["points"], 1024);
    assert_eq!(data["target"]["shown"], 1024);
    assert!(data["method"].as_str().unwrap().contains("t.txt"));
    let rows = data["transform"].as_array().unwrap();
    assert!((rows[0][3].as_f64().unwrap() - 0.2).abs() < 1e-12);
    // The true transform puts every source point on the target: 1,024 flag bytes of 1, in
    // base64 "AQEB" per three.
    let every_one = "AQEB".repeat(341) + "AQ==";
    assert_eq!(data["inlier"], every_one.as_str());
}

#[test]
fn register_html_thins_to_the_budget_and_lists_the_candidates() {
    let dir = Scratch::new("render-html-register");
    let (src, tgt, _) = clouds(&dir);
    let page = dir.join("page.html");
    let out = rgm(&[
        "register",
        &src,
        &tgt,
        "--method",
        "icp",
        "--html",
        page.to_str().unwrap(),
        "--html-points",
        "500",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let data = page_data(&page);
    assert_eq!(data["method"], "icp");
    assert_eq!(
        (
            data["source"]["shown"].as_u64(),
            data["target"]["shown"].as_u64()
        ),
        (Some(250), Some(250))
    );
    assert_eq!(data["budget"], 500);
    assert_eq!(data["correspondences"]["total"], 0);
}

#[test]
fn html_options_are_checked_before_any_work() {
    let dir = Scratch::new("render-html-bad");
    let (src, tgt, _) = clouds(&dir);
    let txt = dir.join("page.txt");
    let out = rgm(&["register", &src, &tgt, "--html", txt.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("give the file an .html name"));
    assert!(!txt.exists());
    let html = dir.join("page.html");
    let out = rgm(&[
        "register",
        &src,
        &tgt,
        "--html",
        html.to_str().unwrap(),
        "--html-points",
        "1",
    ]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("1 is too few"));
    let out = rgm(&["register", &src, &tgt, "--html-points", "100"]);
    assert!(!out.status.success(), "--html-points needs --html");
    let out = rgm(&["render", &src, &tgt]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("--out"));
    assert!(!html.exists());
}
