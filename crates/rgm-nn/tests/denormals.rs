//! `flush_denormals_everywhere` in a process of its own (it builds rayon's global pool and
//! restarts OpenBLAS's workers, so no other test may touch either first).

use ndarray::Array2;
use rgm_nn::threads::flush_denormals_everywhere;

/// A 256² product whose every entry is 2.5e-39, a denormal f32 (the normal minimum is 1.2e-38).
fn denormal_product() -> Array2<f32> {
    let a = Array2::<f32>::from_elem((256, 256), 1e-20);
    let b = Array2::<f32>::from_elem((256, 256), 1e-20 / 40.0);
    a.dot(&b)
}

#[test]
fn denormals_flush_on_every_compute_thread() {
    assert!(
        denormal_product().iter().all(|&v| v > 0.0),
        "denormal results before the call"
    );
    assert!(
        flush_denormals_everywhere(0),
        "rayon's pool was still unbuilt"
    );
    // OpenBLAS splits a 256² product over its workers: every entry zero means all of them flush.
    assert!(
        denormal_product().iter().all(|&v| v == 0.0),
        "flushed by every BLAS thread"
    );
    let tiny = std::hint::black_box(f32::MIN_POSITIVE);
    let (in_pool, _) = rayon::join(|| std::hint::black_box(tiny) / 4.0, || ());
    assert_eq!(in_pool, 0.0, "flushed in rayon's workers");
}
