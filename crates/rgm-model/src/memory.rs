//! Whether the network's registration of N × M matched points fits in memory: its peak,
//! estimated from the sizes, against what this process may still take
//! ([`rgm_data::memory::available`]: free memory, `ulimit -v`, the cgroup's limit). The
//! network's memory grows with N·M, so a large request is refused before it starts rather than
//! killed half-way (past a process limit OpenBLAS spins on its failed allocations and Rust
//! aborts on its own).

use crate::error::MethodError;
use crate::network::Config;

/// Refuses ([`MethodError::TooMuchMemory`]) a registration of `points` (source, target)
/// matched points by a network of `config` with `params` parameters (both chains when
/// `cycle_consistency`) when its estimated peak exceeds the memory available now; a system
/// that does not say passes.
pub fn check_fits(
    config: &Config,
    params: usize,
    points: (usize, usize),
    cycle_consistency: bool,
) -> Result<(), MethodError> {
    let estimate = estimated_peak_bytes(config, params, points.0, points.1, cycle_consistency);
    match rgm_data::memory::available() {
        Some(available) if estimate > available => Err(MethodError::TooMuchMemory {
            points,
            estimate,
            available,
        }),
        _ => Ok(()),
    }
}

/// The peak memory, in bytes, of registering N source and M target matched points with a
/// network of `config` holding `params` parameters (both chains when `cycle_consistency`).
///
/// The part that grows with N·M is counted from the buffers a pass keeps (f32): per block,
/// each side's six R×R adjacency buffers, the edge transformer's attention weights
/// (H·(2N² + 2M² + 2NM)) and seven N×M matrices of scoring and Sinkhorn; one such pass cache per
/// chain. The part linear in the points (60 bytes per point, neighbour and DGCNN channel) and
/// the constant (64 MiB and the weights) are fitted to the peaks measured for the `fast` and
/// `paper` presets, which it must not undercut (docs/speed.md has them and the command).
pub fn estimated_peak_bytes(
    config: &Config,
    params: usize,
    n: usize,
    m: usize,
    cycle_consistency: bool,
) -> u64 {
    let (n, m) = (n as u64, m as u64);
    let (h, blocks) = (config.heads as u64, config.blocks as u64);
    let per_pass = 4 * blocks * ((6 + 2 * h) * (n * n + m * m) + (7 + 2 * h) * n * m);
    let chains = if cycle_consistency { 2 } else { 1 };
    let channels: u64 = config.dgcnn.iter().map(|&c| c as u64).sum();
    let features = 60 * (n + m) * config.k as u64 * channels;
    chains * per_pass + features + (64 << 20) + 4 * params as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_memory_estimate_counts_the_pass_buffers() {
        // fast preset, 1,024 × 1,024 points, both chains: 2 × 4·2·(14·2N² + 15N²) bytes of pass
        // buffers, 60·2N·20·128 of features, 64 MiB and the weights.
        let fast = Config::fast();
        let n = 1024u64;
        let expected = 2 * 8 * 43 * n * n + 60 * 2 * n * 20 * 128 + (64 << 20) + 4 * 1_572_324;
        assert_eq!(
            estimated_peak_bytes(&fast, 1_572_324, 1024, 1024, true),
            expected
        );
        let one_chain = estimated_peak_bytes(&fast, 1_572_324, 1024, 1024, false);
        assert_eq!(expected - one_chain, 8 * 43 * n * n);
    }
}
