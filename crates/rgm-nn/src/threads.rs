//! Thread and floating-point-environment controls for compute threads.

extern "C" {
    fn openblas_set_num_threads(num_threads: std::ffi::c_int);
    fn openblas_get_num_threads() -> std::ffi::c_int;
    fn blas_thread_shutdown_() -> std::ffi::c_int;
}

/// Sets how many threads OpenBLAS uses for every later matrix product (process-wide). Set it to
/// 1 before running independent work on several rayon threads, so the two pools do not nest.
/// With 1, OpenBLAS's worker threads are also stopped: started when the library loads, they
/// spin waiting for work for about a tenth of a second, taking a core from a short run such
/// as one `rgm register` on a small machine. A later call with more starts them again.
pub fn set_blas_threads(n: usize) {
    let n = n.clamp(1, std::ffi::c_int::MAX as usize) as std::ffi::c_int;
    // SAFETY: a plain setter of OpenBLAS's global thread count; any positive value is valid.
    unsafe { openblas_set_num_threads(n) }
    if n == 1 {
        // SAFETY: joins OpenBLAS's idle workers and marks its pool stopped; a product with
        // more than one thread starts it again, and one thread needs no pool.
        unsafe { blas_thread_shutdown_() };
    }
}

/// The number of threads OpenBLAS currently uses.
pub fn blas_threads() -> usize {
    // SAFETY: a plain getter of OpenBLAS's global thread count.
    unsafe { openblas_get_num_threads() as usize }
}

/// Makes the calling thread flush denormal results to zero and read denormal inputs as zero
/// (x86-64 SSE flags FTZ and DAZ; a no-op elsewhere). Denormals appear when activations or
/// gradients decay towards zero and can slow float arithmetic a hundredfold; call this once at
/// the start of every compute thread. Returns whether the flags were set.
pub fn flush_denormals_to_zero() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        #[allow(deprecated)]
        // SAFETY: SSE is always present on x86-64; setting FTZ (bit 15) and DAZ (bit 6) of MXCSR
        // only changes how this thread rounds subnormal floats.
        unsafe {
            use std::arch::x86_64::{_mm_getcsr, _mm_setcsr};
            _mm_setcsr(_mm_getcsr() | (1 << 15) | (1 << 6));
        }
        true
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Runs `work` with denormals flushed on the calling thread ([`flush_denormals_to_zero`]) and
/// puts the thread's floating-point flags back as they were afterwards: for threads that are
/// not ours, such as a Python interpreter's, whose own arithmetic must keep denormals.
pub fn with_denormals_flushed<T>(work: impl FnOnce() -> T) -> T {
    #[cfg(target_arch = "x86_64")]
    {
        /// Restores the saved control word on drop, so a panic in `work` restores it too.
        struct Restore(u32);
        impl Drop for Restore {
            fn drop(&mut self) {
                #[allow(deprecated)]
                // SAFETY: writes back the control word read from this thread before.
                unsafe {
                    std::arch::x86_64::_mm_setcsr(self.0)
                };
            }
        }
        #[allow(deprecated)]
        // SAFETY: reading MXCSR has no effect.
        let _restore = Restore(unsafe { std::arch::x86_64::_mm_getcsr() });
        flush_denormals_to_zero();
        work()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        work()
    }
}

/// Flushes denormals on every thread that computes: the calling thread, OpenBLAS's workers (they
/// load the calling thread's SSE control word with each job, so they follow it — checked by
/// `tests/denormals.rs`) and rayon's global pool, built here with the flag set in each worker.
/// Call it once at the start of the program, before any op (rayon's pool can only be built
/// once); the pool has `threads` workers (0: rayon's default, one per core unless
/// `RAYON_NUM_THREADS` says otherwise). Returns false if rayon's pool already existed (its
/// workers then keep denormals).
pub fn flush_denormals_everywhere(threads: usize) -> bool {
    flush_denormals_to_zero();
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .start_handler(|_| {
            flush_denormals_to_zero();
        })
        .build_global()
        .is_ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blas_thread_count_round_trips() {
        let before = blas_threads();
        set_blas_threads(1);
        assert_eq!(blas_threads(), 1);
        set_blas_threads(before);
        assert_eq!(blas_threads(), before);
    }

    #[test]
    fn denormals_flush_to_zero_after_the_call() {
        // Runs on its own thread so the flag does not leak into other tests.
        std::thread::spawn(|| {
            let tiny = std::hint::black_box(f32::MIN_POSITIVE);
            assert!((tiny / 4.0) > 0.0, "denormal kept before the call");
            assert!(flush_denormals_to_zero());
            assert_eq!(std::hint::black_box(tiny) / 4.0, 0.0);
        })
        .join()
        .unwrap();
    }

    #[test]
    fn denormals_flush_inside_the_scope_only() {
        std::thread::spawn(|| {
            let tiny = std::hint::black_box(f32::MIN_POSITIVE);
            let inside = with_denormals_flushed(|| std::hint::black_box(tiny) / 4.0);
            #[cfg(target_arch = "x86_64")]
            assert_eq!(inside, 0.0);
            #[cfg(not(target_arch = "x86_64"))]
            let _ = inside;
            assert!(
                std::hint::black_box(tiny) / 4.0 > 0.0,
                "denormals kept after the scope"
            );
        })
        .join()
        .unwrap();
    }
}
