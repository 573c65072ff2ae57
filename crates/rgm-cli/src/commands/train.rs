//! `rgm train`: train the RGM network on ModelNet40 pairs, resumable.

use std::ops::ControlFlow;
use std::path::PathBuf;

use anyhow::{Context, Result};
use rgm_data::{ModelNet40, Setting};
use rgm_model::network::{Config, TestStatistics};
use rgm_model::train::{
    BestBy, Event, LogRecord, OptimizerKind, TrainConfig, Trainer, ValSample, DEFAULT_PRESET,
};
use rgm_model::weights::Variant;

use crate::args::checked_precision;
use crate::progress;

/// What `rgm train` runs when given no option ([`TrainConfig::default`]: the built-in model's
/// recipe, the paper's schedule of spec §3): the defaults of the options below.
fn defaults() -> TrainConfig {
    TrainConfig::default()
}

/// Options of `rgm train`, defaults from [`defaults`].
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The ModelNet40 `.npy` tree (e.g. ../shared/data/modelnet40_npy1024).
    #[arg(long, env = "RGM_DATA", value_name = "DIR")]
    data: PathBuf,
    /// The run folder: checkpoints, log.jsonl, best.safetensors. If it already holds a run,
    /// training resumes from its last checkpoint (same options required; --epochs may grow).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// The pair protocol to train on.
    #[arg(long, value_enum, default_value_t = defaults().setting)]
    setting: Setting,
    /// Train and validate on categories 0–19 only (the unseen-categories protocol).
    #[arg(long)]
    unseen: bool,
    /// Network sizes: paper, small, fast or tiny.
    #[arg(long, default_value = DEFAULT_PRESET, value_name = "NAME")]
    preset: String,
    /// The network: rgm, or one of the paper's ablations (spec §2.7): var1 scores pairs by
    /// feature distance (no affinity matrix, no instance norm), var2 connects every point to
    /// every other (no transformer edges).
    #[arg(long, value_enum, default_value_t = Variant::default())]
    variant: Variant,
    /// Cut each cloud of a pair to at most N points for matching (0: the whole clouds).
    #[arg(long, default_value_t = defaults().match_points.unwrap_or(0), value_name = "N")]
    match_points: usize,
    /// Epochs in all.
    #[arg(long, default_value_t = defaults().epochs)]
    epochs: usize,
    /// Stop once epoch N is validated and saved, leaving the run's schedule (--epochs,
    /// --milestones) as it is; running again with a larger N goes on. The training queue
    /// (runs/train.sh) uses it to share the cores between runs.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    until_epoch: Option<u64>,
    /// Pairs per optimiser step.
    #[arg(long, default_value_t = defaults().batch)]
    batch: usize,
    /// The optimiser.
    #[arg(long, value_enum, default_value_t = defaults().optimizer)]
    optimizer: OptimizerKind,
    /// Learning rate before the first milestone.
    #[arg(long, default_value_t = defaults().lr)]
    lr: f64,
    /// SGD momentum.
    #[arg(long, default_value_t = defaults().momentum)]
    momentum: f64,
    /// L2 weight decay.
    #[arg(long, default_value_t = defaults().weight_decay)]
    weight_decay: f64,
    /// Epochs at which the learning rate is multiplied by --gamma.
    #[arg(
        long,
        value_delimiter = ',',
        default_values_t = defaults().milestones,
        value_name = "E,E"
    )]
    milestones: Vec<usize>,
    /// Learning-rate factor at each milestone.
    #[arg(long, default_value_t = defaults().gamma)]
    gamma: f64,
    /// Use only the first N training shapes per epoch.
    #[arg(long, value_name = "N")]
    train_shapes: Option<usize>,
    /// Validate on N validation shapes after each epoch (default: all), taken as
    /// --val-sample says.
    #[arg(long, value_name = "N")]
    val_shapes: Option<usize>,
    /// Which --val-shapes shapes: spread (evenly over the split, so every category counts) or
    /// first (the split's first N, which is ordered by category: a few categories only; what
    /// runs started before this option validated on). May change when resuming: the first
    /// validation on the new sample then becomes the best.
    #[arg(long, value_enum, default_value_t = defaults().val_sample)]
    val_sample: ValSample,
    /// Which validation figure picks best.safetensors: refined (the recall after ICP, then the
    /// network's own: the model a registration refines) or alone (the network's own recall,
    /// what the paper's tables score). May change when resuming.
    #[arg(long, value_enum, default_value_t = defaults().best_by)]
    best_by: BestBy,
    /// Worker threads (default: one per core).
    #[arg(long, value_name = "N")]
    workers: Option<usize>,
    /// Save the last checkpoint every N batches.
    #[arg(long, default_value_t = defaults().checkpoint_every, value_name = "N")]
    checkpoint_every: usize,
    /// Seed of the initial weights and of the shape order.
    #[arg(long, default_value_t = defaults().seed)]
    seed: u64,
    /// Batch-norm statistics at validation: cloud (each cloud's own, as rgm trains) or running
    /// (the running averages, PyTorch's eval()). May change when resuming.
    #[arg(long, value_enum, default_value_t = defaults().test_statistics)]
    test_statistics: TestStatistics,
    /// The network's matrix products in training and validation: f32, or bf16 on the
    /// processor's AMX or AVX-512 BF16 units (weights, optimiser, reductions and loss stay
    /// f32). May change when resuming.
    #[arg(long, value_name = "f32|bf16", default_value_t = defaults().precision)]
    precision: rgm_nn::Precision,
    /// Start a new run from these weights (a .safetensors of the same network) instead of
    /// the seeded initialisation: fine-tuning, e.g. the noise model from the partial one.
    /// A resumed run loads its own checkpoint; give the same --init again.
    #[arg(long, value_name = "WEIGHTS")]
    init: Option<PathBuf>,
}

impl Args {
    fn config(&self) -> Result<TrainConfig> {
        let network = self.variant.apply(Config::preset(&self.preset)?);
        let workers = self
            .workers
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
        Ok(TrainConfig {
            setting: self.setting,
            unseen: self.unseen,
            network,
            match_points: (self.match_points > 0).then_some(self.match_points),
            epochs: self.epochs,
            batch: self.batch,
            optimizer: self.optimizer,
            lr: self.lr,
            momentum: self.momentum,
            weight_decay: self.weight_decay,
            milestones: self.milestones.clone(),
            gamma: self.gamma,
            train_shapes: self.train_shapes,
            val_shapes: self.val_shapes,
            val_sample: self.val_sample,
            best_by: self.best_by,
            workers,
            checkpoint_every: self.checkpoint_every,
            seed: self.seed,
            test_statistics: self.test_statistics,
            precision: checked_precision(self.precision),
            init: self.init.clone(),
        })
    }
}

pub fn run(args: Args) -> Result<()> {
    let config = args.config()?;
    let dataset = ModelNet40::open(&args.data)?;
    let mut trainer = Trainer::open(config, &args.out)
        .with_context(|| format!("opening the run in {}", args.out.display()))?;
    let state = trainer.state();
    if state.steps > 0 {
        eprintln!(
            "resuming {} at epoch {}, batch {} ({} pairs seen)",
            args.out.display(),
            state.epoch + 1,
            state.batch,
            state.pairs_seen
        );
    }
    let mut bar: Option<indicatif::ProgressBar> = None;
    let epochs = trainer.config().epochs;
    let until = args.until_epoch.map_or(epochs, |n| n as usize);
    if trainer.state().epoch < until {
        trainer.run(&dataset, &mut |event| {
            report(&event, &mut bar, epochs);
            match event {
                Event::Logged(LogRecord::Validation { ref result, .. })
                    if result.epoch + 1 >= until =>
                {
                    ControlFlow::Break(())
                }
                _ => ControlFlow::Continue(()),
            }
        })?;
    }
    if let Some(bar) = bar.take() {
        bar.finish_and_clear();
    }
    match trainer.state().best {
        Some(best) => eprintln!(
            "done: {} epochs; best weights {} (recall {:.1}%, refined {:.1}%)",
            trainer.state().epoch,
            args.out.join("best.safetensors").display(),
            100.0 * best.recall,
            100.0 * best.recall_refined
        ),
        None => eprintln!(
            "done: {} epochs; no validation yet, so no best weights",
            trainer.state().epoch
        ),
    }
    Ok(())
}

/// Shows `event` on stderr: a progress bar per epoch, a line per validation.
fn report(event: &Event, bar: &mut Option<indicatif::ProgressBar>, epochs: usize) {
    match *event {
        Event::Batch {
            epoch,
            batch,
            batches,
            loss,
        } => {
            let bar = bar.get_or_insert_with(|| {
                let bar = progress(batches, &format!("epoch {}/{epochs}", epoch + 1));
                bar.set_position(batch as u64 - 1);
                bar
            });
            bar.set_message(format!("loss {loss:.3}"));
            bar.set_position(batch as u64);
        }
        Event::Validating { done, total } => {
            if let Some(bar) = bar.take() {
                bar.finish_and_clear();
            }
            if done == 0 {
                eprintln!("epoch done; validating on {total} pairs");
            }
        }
        Event::Logged(LogRecord::Validation { ref result, .. }) => eprintln!(
            "epoch {}: validation loss {:.4}, matching accuracy {:.1}%, MIE(R) {:.2}°, \
             MIE(t) {:.4}, recall {:.1}% (refined {:.1}%)",
            result.epoch + 1,
            result.loss,
            100.0 * result.match_accuracy,
            result.mie_r_deg,
            result.mie_t,
            100.0 * result.recall,
            100.0 * result.recall_refined
        ),
        Event::Logged(LogRecord::Train { .. }) => {}
    }
}
