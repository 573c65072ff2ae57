//! The network's sizes and structure: named presets and the two ablations of spec §2.7.

use super::{NetworkError, Result};
use serde::{Deserialize, Serialize};

/// How the soft correspondence is scored from the graph features F'_X, F'_Y.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Scoring {
    /// AIS: S = F'_X ((W + Wᵀ)/2) F'_Yᵀ, instance norm, Sinkhorn (spec §2.4).
    Ais,
    /// "Var1": the Sinkhorn's log-domain input is −(‖F'_Xi − F'_Yj‖² − 0.5) (squared distance);
    /// no affinity matrix and no instance norm (spec §2.7).
    Var1,
}

/// Where each graph's adjacency comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Edges {
    /// The transformer edge generator: E = softmax_rows(T Tᵀ / √C) (spec §2.2).
    Transformer,
    /// "Var2": full connection without self-loops, A = 1 − I (1/(N − 1) off the diagonal once
    /// its columns are normalised); no transformer parameters (spec §2.7).
    Full,
}

/// The sizes of RGM. Dimension letters as everywhere: K neighbours, C channels, Q graph width,
/// H heads, L blocks.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Config {
    /// K, neighbours per point in the local feature extractor, the point itself included.
    pub k: usize,
    /// Output widths of the four DGCNN 1×1 convolutions; their sum is the node-feature width.
    pub dgcnn: [usize; 4],
    /// Width of the edge features (the fifth convolution).
    pub edge: usize,
    /// Q, the graph-feature width of every block's output.
    pub q: usize,
    /// H, attention heads of the edge generator.
    pub heads: usize,
    /// Hidden width of the transformer's feed-forward layers.
    pub ff: usize,
    /// L, matching blocks; the cross-graph convolution runs in block L − 2 (spec §2.5).
    pub blocks: usize,
    /// Sinkhorn rounds.
    pub sinkhorn_iters: usize,
    /// AIS or the Var1 ablation.
    pub scoring: Scoring,
    /// Transformer edges or the Var2 ablation.
    pub edges: Edges,
}

impl Config {
    /// The reference sizes (spec §2): K 20, DGCNN 64-64-128-256, edge 512 (C = 1,024), Q 512,
    /// H 4, FF 1,024, L 2, 20 Sinkhorn rounds — 25,000,836 parameters.
    pub fn paper() -> Self {
        Self {
            k: 20,
            dgcnn: [64, 64, 128, 256],
            edge: 512,
            q: 512,
            heads: 4,
            ff: 1024,
            blocks: 2,
            sinkhorn_iters: 20,
            scoring: Scoring::Ais,
            edges: Edges::Transformer,
        }
    }

    /// Every stage narrowed for training on a small CPU: DGCNN 32-32-64-128, edge 256
    /// (C = 512), Q 256, H 4, FF 512, K 20, L 2 — 6,263,236 parameters.
    pub fn small() -> Self {
        Self {
            dgcnn: [32, 32, 64, 128],
            edge: 256,
            q: 256,
            ff: 512,
            ..Self::paper()
        }
    }

    /// The preset rgm trains and ships: every stage a quarter of the paper's width — DGCNN
    /// 16-16-32-64, edge 128 (C = 256), Q 128, H 4, FF 256, K 20, L 2 — 1,572,324 parameters.
    /// Sized so that a model trains in days on two cores (docs/training/README.md has the step
    /// times).
    pub fn fast() -> Self {
        Self {
            dgcnn: [16, 16, 32, 64],
            edge: 128,
            q: 128,
            ff: 256,
            ..Self::paper()
        }
    }

    /// The configuration of the PyTorch reference fixture (tests and gradient checks): K 4,
    /// DGCNN 4-4-8-8, edge 24 (C = 48), Q 16, H 4, FF 32, L 2.
    pub fn tiny() -> Self {
        Self {
            k: 4,
            dgcnn: [4, 4, 8, 8],
            edge: 24,
            q: 16,
            ff: 32,
            ..Self::paper()
        }
    }

    /// The preset called `name` ("paper", "small", "fast" or "tiny").
    pub fn preset(name: &str) -> Result<Self> {
        match name {
            "paper" => Ok(Self::paper()),
            "small" => Ok(Self::small()),
            "fast" => Ok(Self::fast()),
            "tiny" => Ok(Self::tiny()),
            _ => Err(NetworkError::Config {
                why: format!("unknown preset {name:?} (paper, small, fast, tiny)"),
            }),
        }
    }

    /// Node-feature width: the sum of the DGCNN widths.
    pub fn node_width(&self) -> usize {
        self.dgcnn.iter().sum()
    }

    /// The input width of block `b`: node ⊕ edge features in block 0, Q after.
    pub fn block_width(&self, b: usize) -> usize {
        if b == 0 {
            self.node_width() + self.edge
        } else {
            self.q
        }
    }

    /// Whether block `b` ends with the cross-graph convolution (block L − 2 only).
    pub fn has_cross(&self, b: usize) -> bool {
        b + 2 == self.blocks
    }

    /// Checks that every size is usable: all positive, heads dividing each transformer width.
    pub fn validate(&self) -> Result<()> {
        let sizes = [
            ("k", self.k),
            ("edge", self.edge),
            ("q", self.q),
            ("heads", self.heads),
            ("ff", self.ff),
            ("blocks", self.blocks),
            ("sinkhorn_iters", self.sinkhorn_iters),
        ];
        for (what, v) in sizes {
            if v == 0 {
                return Err(NetworkError::Config {
                    why: format!("{what} must be positive"),
                });
            }
        }
        if self.dgcnn.contains(&0) {
            return Err(NetworkError::Config {
                why: format!("DGCNN widths must be positive, got {:?}", self.dgcnn),
            });
        }
        if self.edges == Edges::Transformer {
            for b in 0..self.blocks.min(2) {
                let c = self.block_width(b);
                if !c.is_multiple_of(self.heads) {
                    return Err(NetworkError::Config {
                        why: format!(
                            "block {b} width {c} is not divisible by {} heads",
                            self.heads
                        ),
                    });
                }
            }
        }
        Ok(())
    }
}
