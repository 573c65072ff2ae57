//! Checks that a PyTorch state dict under the authors' parameter names loads into rgm and gives
//! the same C̃: the proof of the checkpoint path (`Rgm::load` is the converter).
//!
//! ```sh
//! python3 tools/reference/rgm_reference.py export --out /tmp/paper_random.safetensors
//! cargo run --release -p rgm-model --example check_state_dict -- /tmp/paper_random.safetensors paper
//! ```
//! The file holds the state dict, `input.x`, `input.y` and PyTorch's evaluation-mode
//! `output.c_soft_eval`; this prints the largest absolute difference of C̃ and exits non-zero
//! above 1e-4.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use rgm_model::network::{Config, Mode, Rgm, RgmCache};

fn main() -> ExitCode {
    let mut args = std::env::args().skip(1);
    let (Some(path), preset) = (
        args.next().map(PathBuf::from),
        args.next().unwrap_or_else(|| "paper".into()),
    ) else {
        eprintln!("usage: check_state_dict FILE [PRESET]");
        return ExitCode::FAILURE;
    };
    let run = || -> Result<f32, Box<dyn std::error::Error>> {
        let config = Config::preset(&preset)?;
        let mut network = Rgm::<f32>::load(config, &path)?;
        let (tensors, _) = rgm_nn::io::read_tensors::<f32>(&path)?;
        let get = |name: &str| -> Result<ndarray::Array2<f32>, Box<dyn std::error::Error>> {
            let t = tensors
                .get(name)
                .ok_or_else(|| format!("{} has no tensor {name}", path.display()))?;
            Ok(t.clone().into_dimensionality()?)
        };
        let (x, y, expected) = (get("input.x")?, get("input.y")?, get("output.c_soft_eval")?);
        let mut cache = RgmCache::default();
        let start = Instant::now();
        network.forward(x.view(), y.view(), Mode::Eval, &mut cache)?;
        println!(
            "forward of {}×{} points: {:.1} ms",
            x.nrows(),
            y.nrows(),
            start.elapsed().as_secs_f64() * 1e3
        );
        let c_soft = cache.c_soft(); // (N, M)
        if c_soft.dim() != expected.dim() {
            let (got, want) = (c_soft.dim(), expected.dim());
            return Err(format!("C̃ is {got:?}, PyTorch's is {want:?}").into());
        }
        Ok((&c_soft - &expected).fold(0.0f32, |worst, d| worst.max(d.abs())))
    };
    match run() {
        Ok(worst) => {
            println!("largest |C̃(rgm) − C̃(PyTorch)| = {worst:.3e}");
            if worst <= 1e-4 {
                ExitCode::SUCCESS
            } else {
                ExitCode::FAILURE
            }
        }
        Err(err) => {
            eprintln!("check_state_dict: {err}");
            ExitCode::FAILURE
        }
    }
}
