//! How long reading a point-cloud file takes, in any format `rgm register` reads.
//!
//! ```text
//! cargo run --release -p rgm-benches --example read_cloud -- FILE [REPEATS]
//! ```
//!
//! Reads FILE REPEATS times (20 when left out) with `rgm_data::io::read_point_cloud`, as the
//! command line does, and prints the points and the fastest read in milliseconds: unzipping and
//! parsing, the part of `rgm register`'s wall time that comes before any registration.

use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [file, rest @ ..] = args.as_slice() else {
        return Err("usage: read_cloud FILE [REPEATS]".into());
    };
    let repeats: usize = match rest.first() {
        Some(n) => n.parse().map_err(|e| format!("REPEATS {n:?}: {e}"))?,
        None => 20,
    };
    let mut fastest = f64::INFINITY;
    let mut points = 0;
    for _ in 0..repeats {
        let start = Instant::now();
        let cloud = rgm_data::io::read_point_cloud(file)?;
        fastest = fastest.min(start.elapsed().as_secs_f64() * 1e3);
        points = cloud.len();
    }
    println!("points {points} fastest {fastest:.2} ms of {repeats}");
    Ok(())
}
