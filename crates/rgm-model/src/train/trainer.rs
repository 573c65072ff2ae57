//! The training loop: batches of pairs spread over worker threads, their gradients summed into
//! the main network, the optimiser's step, and a checkpoint every few batches and after every
//! epoch's validation.

use std::ops::ControlFlow;
use std::path::Path;
use std::time::Instant;

use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rayon::prelude::*;
use rgm_data::pairs::train_seed;
use rgm_data::{ModelNet40, Pair, PairGenerator, Shape, Split};
use rgm_match::Correspondences;
use rgm_nn::optim::{MultiStepLr, Optimizer};
use rgm_nn::{Compute, Parameters, Scalar};

use super::run_dir::{read_json, write_json, CheckpointFile, RunDir};
use super::{Event, LogRecord, Result, TrainConfig, TrainError, TrainState};
use crate::network::{Rgm, RgmCache};
use crate::procedure::as_rows;

/// One worker's network copy and forward/backward buffers.
pub(super) struct Worker {
    pub(super) network: Rgm<f32>,
    pub(super) cache: RgmCache<f32>,
}

/// The pair's ground-truth correspondences, as the loss takes them.
pub(super) fn ground_truth(pair: &Pair) -> Result<Correspondences> {
    let c = &pair.correspondence;
    Ok(Correspondences::new(
        c.n_source,
        c.n_target,
        c.pairs.clone(),
    )?)
}

/// A training run bound to its folder.
pub struct Trainer {
    pub(super) config: TrainConfig,
    /// The run folder, held (locked) as long as the trainer lives.
    pub(super) dir: RunDir,
    network: Rgm<f32>,
    optimizer: Box<dyn Optimizer<f32>>,
    state: TrainState,
    pub(super) workers: Vec<Worker>,
}

impl Trainer {
    /// The run in `dir`: resumed from its last checkpoint when `dir` holds one (its saved
    /// configuration must equal `config` except for the number of epochs), a new run otherwise.
    pub fn open(config: TrainConfig, dir: &Path) -> Result<Self> {
        config.validate()?;
        let (run_dir, committed) = RunDir::open(dir)?;
        let (network, optimizer, state) = if let Some(state) = committed {
            let saved: TrainConfig = read_json(&dir.join("config.json"))?;
            if !config.same_run(&saved) {
                return Err(TrainError::Config {
                    why: format!(
                        "{} holds a run with other settings ({}); give the same options (only \
                         --epochs may change) or another --out folder",
                        dir.display(),
                        dir.join("config.json").display()
                    ),
                });
            }
            let network = Rgm::load(config.network.clone(), &dir.join("last.safetensors"))?;
            // A finished run may be committed without its optimiser state (the largest file,
            // needed by no resume until the run is extended): it then goes on with a fresh one.
            let optim = dir.join("last.optim.safetensors");
            let optimizer = if optim.exists() {
                config.optimizer.load(&optim)?
            } else {
                config.optimizer.fresh(&config)
            };
            (network, optimizer, state)
        } else {
            let network = match &config.init {
                Some(init) => Rgm::load(config.network.clone(), init)?,
                None => Rgm::new(config.network.clone(), config.seed)?,
            };
            (
                network,
                config.optimizer.fresh(&config),
                TrainState::default(),
            )
        };
        let mut network = network;
        network.set_compute(Compute::with_precision(config.precision)); // the workers' copies inherit it
        write_json(&dir.join("config.json"), &config)?;
        let workers = (0..config.workers)
            .map(|_| Worker {
                network: network.clone(),
                cache: RgmCache::default(),
            })
            .collect();
        Ok(Self {
            config,
            dir: run_dir,
            network,
            optimizer,
            state,
            workers,
        })
    }

    pub fn config(&self) -> &TrainConfig {
        &self.config
    }

    pub fn state(&self) -> &TrainState {
        &self.state
    }

    /// The network being trained.
    pub fn network(&self) -> &Rgm<f32> {
        &self.network
    }

    /// The learning rate of `epoch`.
    pub fn lr(&self, epoch: usize) -> f64 {
        MultiStepLr {
            base: self.config.lr,
            milestones: self.config.milestones.clone(),
            gamma: self.config.gamma,
        }
        .lr(epoch)
    }

    /// Trains until the configured number of epochs is done, validating after each epoch and
    /// checkpointing as it goes. `dataset` must be the one the run started on. When `on_event`
    /// answers `Break` to a batch, the run saves a checkpoint there and returns; to an epoch's
    /// validation record, it returns after that epoch's checkpoint (either way a later
    /// [`Trainer::open`] + `run` goes on from it exactly as if never stopped).
    pub fn run(
        &mut self,
        dataset: &ModelNet40,
        on_event: &mut dyn FnMut(Event) -> ControlFlow<()>,
    ) -> Result<()> {
        let setting = self.config.setting;
        let generator = PairGenerator::new(setting);
        let mut train = dataset.split(Split::Train, self.config.unseen);
        train.truncate(self.config.train_shapes.unwrap_or(usize::MAX));
        let val = self.config.val_sample.take(
            &dataset.split(Split::Validation, self.config.unseen),
            self.config.val_shapes.unwrap_or(usize::MAX),
        );
        if train.is_empty() || val.is_empty() {
            return Err(TrainError::Config {
                why: format!(
                    "{} training and {} validation shapes: both must be non-empty",
                    train.len(),
                    val.len()
                ),
            });
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(self.config.workers)
            .start_handler(|_| {
                rgm_nn::threads::flush_denormals_to_zero();
            })
            .build()
            .map_err(|e| TrainError::Config {
                why: format!("cannot start {} worker threads: {e}", self.config.workers),
            })?;
        rgm_nn::threads::set_blas_threads(1);
        let batches = train.len().div_ceil(self.config.batch);
        let mut since_log = (0.0, 0usize); // (loss sum, batches)
        while self.state.epoch < self.config.epochs {
            let epoch = self.state.epoch;
            let lr = self.lr(epoch);
            self.optimizer.set_lr(lr);
            let mut order: Vec<usize> = (0..train.len()).collect();
            order.shuffle(&mut StdRng::seed_from_u64(
                self.config.seed ^ train_seed(epoch, 0),
            ));
            let mut clock = Instant::now();
            while self.state.batch < batches {
                let b = self.state.batch;
                let chunk =
                    &order[b * self.config.batch..((b + 1) * self.config.batch).min(order.len())];
                let loss = pool.install(|| self.step(&generator, &train, epoch, chunk))?;
                self.state.batch += 1;
                self.state.steps += 1;
                self.state.pairs_seen += chunk.len() as u64;
                since_log = (since_log.0 + loss, since_log.1 + 1);
                let stop = on_event(Event::Batch {
                    epoch,
                    batch: b + 1,
                    batches,
                    loss,
                })
                .is_break();
                let due = self
                    .state
                    .batch
                    .is_multiple_of(self.config.checkpoint_every);
                if due || stop || self.state.batch == batches {
                    self.state.seconds += clock.elapsed().as_secs_f64();
                    clock = Instant::now();
                    let record = LogRecord::Train {
                        epoch,
                        batch: self.state.batch,
                        batches,
                        pairs_seen: self.state.pairs_seen,
                        lr,
                        loss: since_log.0 / since_log.1 as f64,
                        seconds: self.state.seconds,
                    };
                    since_log = (0.0, 0);
                    self.log(&record)?;
                    let _ = on_event(Event::Logged(record));
                    self.checkpoint(false)?;
                }
                if stop {
                    return Ok(());
                }
            }
            let _ = on_event(Event::Validating {
                done: 0,
                total: val.len(),
            });
            let result = pool.install(|| self.validate(&generator, &val, epoch))?;
            let _ = on_event(Event::Validating {
                done: val.len(),
                total: val.len(),
            });
            self.state.seconds += clock.elapsed().as_secs_f64();
            let new_best = self
                .state
                .best
                .is_none_or(|best| result.beats(&best, self.config.best_by));
            if new_best {
                self.state.best = Some(result);
            }
            self.state.epoch += 1;
            self.state.batch = 0;
            let record = LogRecord::Validation {
                result,
                pairs_seen: self.state.pairs_seen,
                seconds: self.state.seconds,
            };
            self.log(&record)?;
            self.checkpoint(new_best)?;
            if on_event(Event::Logged(record)).is_break() {
                return Ok(());
            }
        }
        Ok(())
    }

    /// One optimiser step on the training shapes `chunk` of `epoch`; returns the mean loss.
    fn step(
        &mut self,
        generator: &PairGenerator,
        shapes: &[&Shape],
        epoch: usize,
        chunk: &[usize],
    ) -> Result<f64> {
        let workers = self.workers.len();
        let match_points = self.config.match_points;
        let losses: Vec<Result<f64>> = self
            .workers
            .par_iter_mut()
            .enumerate()
            .map(|(w, worker)| {
                worker.network.zero_grad();
                let mut sum = 0.0;
                for &i in chunk.iter().skip(w).step_by(workers) {
                    let mut pair = generator.train_pair(shapes, epoch, i)?;
                    if let Some(points) = match_points {
                        let seed = !train_seed(epoch, i);
                        pair = pair.subsampled(points, &mut StdRng::seed_from_u64(seed));
                    }
                    let gt = ground_truth(&pair)?;
                    let (x, y) = (as_rows(&pair.source), as_rows(&pair.target));
                    let loss = worker.network.forward_backward(
                        x.view(),
                        y.view(),
                        &gt,
                        &mut worker.cache,
                    )?;
                    sum += loss.to_f64();
                }
                Ok(sum)
            })
            .collect();
        let mut total = 0.0;
        for loss in losses {
            total += loss?;
        }
        let scale = 1.0 / chunk.len() as f32;
        self.network.zero_grad();
        for worker in &mut self.workers {
            let mut grads = Vec::new();
            worker
                .network
                .visit_params_ref("", &mut |_, p| grads.push(p.grad));
            let mut grads = grads.into_iter();
            self.network.visit_params("", &mut |_, mut p| {
                let g = grads.next().expect("same network layout");
                p.grad.scaled_add(scale, &g);
            });
        }
        self.average_buffers();
        self.optimizer.step(&mut self.network)?;
        self.broadcast();
        Ok(total / chunk.len() as f64)
    }

    /// Sets the main network's batch-norm running statistics to the workers' mean.
    fn average_buffers(&mut self) {
        let scale = 1.0 / self.workers.len() as f32;
        let mut sums = Vec::new();
        for (k, worker) in self.workers.iter().enumerate() {
            let mut n = 0;
            worker.network.visit_buffers_ref("", &mut |_, b| {
                if k == 0 {
                    sums.push(b.mapv(|v| v * scale));
                } else {
                    sums[n].scaled_add(scale, &b);
                }
                n += 1;
            });
        }
        let mut sums = sums.into_iter();
        self.network.visit_buffers("", &mut |_, mut b| {
            b.assign(&sums.next().expect("same network layout"))
        });
    }

    /// Copies the main network's weights and buffers into every worker.
    fn broadcast(&mut self) {
        for worker in &mut self.workers {
            worker.network.clone_from(&self.network);
        }
    }

    /// Appends `record` to `log.jsonl`.
    fn log(&mut self, record: &LogRecord) -> Result<()> {
        let line = serde_json::to_string(record).map_err(|source| TrainError::Json {
            path: self.dir.file("log.jsonl"),
            source,
        })?;
        self.dir.append_log(&line)
    }

    /// Saves the run as one commit (see the module's documentation): weights, optimiser and
    /// state, and the weights as `best.safetensors` when `new_best`.
    fn checkpoint(&mut self, new_best: bool) -> Result<()> {
        let network = &self.network;
        let optimizer = &self.optimizer;
        let weights = |path: &Path| Ok(rgm_nn::io::save_params(path, network)?);
        let optimizer_state = |path: &Path| Ok(optimizer.save(path)?);
        let mut files: Vec<CheckpointFile<'_>> = vec![
            ("last.safetensors", &weights),
            ("last.optim.safetensors", &optimizer_state),
        ];
        if new_best {
            files.push(("best.safetensors", &weights));
        }
        self.dir.checkpoint(&mut self.state, &files)
    }
}
