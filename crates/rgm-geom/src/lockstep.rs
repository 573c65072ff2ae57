//! Two workers through a sequence of steps cut in two parts: for iterative methods whose every
//! step is short (tens of microseconds), where handing each step to rayon's pool anew costs as
//! much as the step (docs/speed.md). Both workers stay in one parallel region for all steps and
//! claim the parts in order from a shared counter; a part starts only when every part of the
//! steps before it is done. One worker alone (a pool of one thread, or the other thread busy
//! elsewhere) runs every part in order, so the results never depend on the number of threads,
//! as long as the two parts of a step touch different data.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// Runs `part(&mut scratch, step, half)` for `step` in `0..steps` and `half` in 0 and 1, on up
/// to two of rayon's workers when `side_by_side` and the pool has two threads, else on this
/// one; each worker makes its own `scratch` first. Step `s`'s two halves may run at once, but
/// both only after every half of steps `0..s` returned, whose writes they then see. A panic in
/// one half ends the other worker's wait and reaches the caller.
pub fn two_halves<S>(
    steps: usize,
    side_by_side: bool,
    scratch: impl Fn() -> S + Sync,
    part: impl Fn(&mut S, usize, usize) + Sync,
) {
    let parts = 2 * steps;
    let claimed = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let failed = AtomicBool::new(false);
    let worker = || {
        let _flag = FlagOnPanic(&failed);
        let mut scratch = scratch();
        loop {
            let h = claimed.fetch_add(1, Ordering::Relaxed);
            if h >= parts {
                return;
            }
            let step = h / 2;
            let mut spins = 0u32;
            while done.load(Ordering::Acquire) < 2 * step {
                // The other worker's half panicked: end this one too, so that rayon's join
                // hands the panic to the caller instead of waiting for ever.
                assert!(!failed.load(Ordering::Relaxed), "a lockstep worker failed");
                spins += 1;
                if spins.is_multiple_of(1024) {
                    std::thread::yield_now();
                } else {
                    std::hint::spin_loop();
                }
            }
            part(&mut scratch, step, h % 2);
            done.fetch_add(1, Ordering::Release);
        }
    };
    if side_by_side && rayon::current_num_threads() > 1 {
        rayon::join(worker, worker);
    } else {
        worker();
    }
}

/// Sets its flag when the thread unwinds through it (a panic).
struct FlagOnPanic<'a>(&'a AtomicBool);

impl Drop for FlagOnPanic<'_> {
    fn drop(&mut self) {
        if std::thread::panicking() {
            self.0.store(true, Ordering::Relaxed);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    /// The (step, half) order of a run on a pool of `threads`.
    fn order(threads: usize, side_by_side: bool) -> Vec<(usize, usize, usize)> {
        let log = Mutex::new(Vec::new());
        // Each half records the last step both halves of which it saw finished.
        let finished = AtomicUsize::new(0);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            two_halves(
                50,
                side_by_side,
                || (),
                |_, step, half| {
                    let seen = finished.load(Ordering::SeqCst);
                    log.lock().unwrap().push((step, half, seen));
                    std::thread::sleep(std::time::Duration::from_micros(20));
                    finished.fetch_add(1, Ordering::SeqCst);
                },
            )
        });
        log.into_inner().unwrap()
    }

    #[test]
    fn every_half_runs_once_after_the_steps_before_it() {
        for (threads, side_by_side) in [(1, true), (2, true), (2, false), (3, true)] {
            let mut log = order(threads, side_by_side);
            assert_eq!(log.len(), 100);
            // When step s starts, both halves of every earlier step have finished.
            for &(step, _, seen) in &log {
                assert!(
                    seen >= 2 * step,
                    "step {step} started after only {seen} halves"
                );
            }
            log.sort();
            let runs: Vec<(usize, usize)> = log.iter().map(|&(s, h, _)| (s, h)).collect();
            let expected: Vec<(usize, usize)> = (0..50).flat_map(|s| [(s, 0), (s, 1)]).collect();
            assert_eq!(runs, expected);
        }
    }

    #[test]
    fn one_worker_runs_the_halves_in_order() {
        let log = order(1, true);
        let runs: Vec<(usize, usize)> = log.iter().map(|&(s, h, _)| (s, h)).collect();
        let expected: Vec<(usize, usize)> = (0..50).flat_map(|s| [(s, 0), (s, 1)]).collect();
        assert_eq!(runs, expected);
    }

    #[test]
    fn a_panic_in_one_half_reaches_the_caller() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            pool.install(|| {
                two_halves(
                    10,
                    true,
                    || (),
                    |_, step, half| assert!(!(step == 3 && half == 1), "half (3, 1) fails"),
                )
            })
        }));
        assert!(outcome.is_err());
    }
}
