//! Seeded fuzzing on stable Rust, as plain tests: inputs made by mutating small valid files
//! (and some made from nothing), each handed to a reader that must return, not panic, in
//! bounded memory. The same seed always makes the same inputs, so a failure names the input
//! that reproduces it.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// An allocator that counts, per thread, the bytes live and their peak, so a fuzz run can
/// bound what a reader allocates for an input. A test binary installs it with
/// `#[global_allocator] static ALLOC: CountingAllocator = CountingAllocator;`.
pub struct CountingAllocator;

thread_local! {
    static LIVE: Cell<usize> = const { Cell::new(0) };
    static PEAK: Cell<usize> = const { Cell::new(0) };
}

// SAFETY: every call is forwarded to the system allocator; the counters only observe.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let ptr = System.alloc(layout);
        if !ptr.is_null() {
            count(layout.size() as isize);
        }
        ptr
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout);
        count(-(layout.size() as isize));
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let new = System.realloc(ptr, layout, new_size);
        if !new.is_null() {
            count(new_size as isize - layout.size() as isize);
        }
        new
    }
}

fn count(delta: isize) {
    // `try_with`: the counters may be gone while a thread ends.
    let _ = LIVE.try_with(|live| {
        let now = live.get().saturating_add_signed(delta);
        live.set(now);
        let _ = PEAK.try_with(|peak| peak.set(peak.get().max(now)));
    });
}

/// The most bytes `f` held at once beyond what was live when it started (0 unless
/// [`CountingAllocator`] is installed), and its result.
pub fn peak_bytes<T>(f: impl FnOnce() -> T) -> (usize, T) {
    let base = LIVE.with(Cell::get);
    PEAK.with(|p| p.set(base));
    let out = f();
    (PEAK.with(Cell::get) - base, out)
}

/// Tokens that readers of numbers and counts trip on.
const NASTY: &[&[u8]] = &[
    b"0",
    b"-1",
    b"1e309",
    b"-0",
    b"nan",
    b"inf",
    b"18446744073709551616",
    b"1000000000000000000",
    b"4294967295",
    b"99999999999",
    b" ",
    b"\n",
    b"\r\n",
    b",",
    b"#",
    b"\x00",
    b"\xff",
    b"list",
    b"element",
    b"property",
    b"end_header",
    b"{",
    b"}",
    b"[",
    b"]",
    b"\"",
    b"'",
    b":",
];

/// Numbers that counts, lengths and sizes trip on.
const NASTY_NUMBERS: &[&[u8]] = &[
    b"0",
    b"1",
    b"2",
    b"255",
    b"65535",
    b"4294967295",
    b"4294967296",
    b"99999999999",
    b"1000000000000000000",
    b"18446744073709551615",
    b"-1",
    b"1e309",
    b"nan",
];

/// One input made from `seed` by one to four random edits: flipped bits, replaced, inserted,
/// removed or repeated bytes, nasty tokens, a number (a count, a length) replaced by a nasty
/// one, a cut.
pub fn mutate(seed: &[u8], rng: &mut StdRng) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..rng.gen_range(1..=4) {
        let at = rng.gen_range(0..=b.len());
        match rng.gen_range(0..8) {
            7 => {
                // The run of digits at or after `at`.
                let Some(start) = b[at..].iter().position(u8::is_ascii_digit).map(|i| at + i)
                else {
                    continue;
                };
                let end = b[start..]
                    .iter()
                    .position(|c| !c.is_ascii_digit())
                    .map_or(b.len(), |i| start + i);
                let number = NASTY_NUMBERS[rng.gen_range(0..NASTY_NUMBERS.len())];
                b.splice(start..end, number.iter().copied());
            }
            0 if at < b.len() => b[at] ^= 1 << rng.gen_range(0..8),
            1 if at < b.len() => b[at] = rng.gen(),
            2 => {
                let token = NASTY[rng.gen_range(0..NASTY.len())];
                b.splice(at..at, token.iter().copied());
            }
            3 => {
                let end = rng.gen_range(at..=b.len().min(at + 16));
                let token = NASTY[rng.gen_range(0..NASTY.len())];
                b.splice(at..end, token.iter().copied());
            }
            4 => {
                let end = rng.gen_range(at..=b.len().min(at + 32));
                b.drain(at..end);
            }
            5 => {
                let end = rng.gen_range(at..=b.len().min(at + 64));
                let piece = b[at..end].to_vec();
                for _ in 0..rng.gen_range(1..8) {
                    b.splice(at..at, piece.iter().copied());
                }
            }
            _ => b.truncate(at),
        }
    }
    b
}

/// How a fuzz run goes: how many inputs, and the memory a reader may use for an input of
/// `len` bytes (`bytes_per_input_byte · len + slack`).
#[derive(Clone, Copy, Debug)]
pub struct Fuzz {
    pub inputs: usize,
    pub bytes_per_input_byte: usize,
    pub slack: usize,
}

impl Default for Fuzz {
    /// 10,000 inputs; 64 bytes per input byte and 1 MiB besides (a point is 24 bytes, from at
    /// least 3 bytes of a file, and a growing vector may double).
    fn default() -> Self {
        Self {
            inputs: 10_000,
            bytes_per_input_byte: 64,
            slack: 1 << 20,
        }
    }
}

/// An input that has run this long is taken for a hang: the run stops, naming it. Generous,
/// as a busy machine may be slow: readers take microseconds on these inputs.
const HANG: Duration = Duration::from_secs(30);

impl Fuzz {
    /// Feeds `read` the inputs made from `seeds` (nine in ten mutated seeds, one in ten random
    /// bytes), each seeded by `name` and its number: a panic, a hang or memory beyond the bound
    /// fails the run, naming the input.
    pub fn run(&self, name: &str, seeds: &[Vec<u8>], read: impl Fn(&[u8])) {
        assert!(!seeds.is_empty(), "{name}: no seed");
        // A panic that a reader catches itself (laz's, in rgm-data) runs the panic hook inside
        // the measured read: the default hook, when RUST_BACKTRACE is set, loads the binary's
        // debug symbols for the backtrace (≈ 100 MB), which is no allocation of the reader's.
        // The message alone is printed.
        std::panic::set_hook(Box::new(|info| eprintln!("{info}")));
        for seed in seeds {
            read(seed); // the seeds themselves
        }
        let name_seed = name
            .bytes()
            .fold(0u64, |h, b| h.wrapping_mul(31).wrapping_add(b as u64));
        // When the input under test started, in ms since `origin` (IDLE between inputs).
        const IDLE: u64 = u64::MAX;
        let started = Arc::new(AtomicU64::new(IDLE));
        let finished = Arc::new(AtomicBool::new(false));
        let origin = Instant::now();
        let watchdog = {
            let (started, finished) = (Arc::clone(&started), Arc::clone(&finished));
            let name = name.to_string();
            std::thread::spawn(move || {
                while !finished.load(Ordering::Relaxed) {
                    std::thread::sleep(Duration::from_millis(100));
                    let at = started.load(Ordering::Relaxed);
                    let now = origin.elapsed().as_millis() as u64;
                    if at != IDLE && now > at + HANG.as_millis() as u64 {
                        eprintln!("{name}: an input ran for more than {HANG:?}: a hang");
                        std::process::abort();
                    }
                }
            })
        };
        for i in 0..self.inputs {
            let mut rng =
                StdRng::seed_from_u64(name_seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
            let input = if rng.gen_bool(0.1) {
                let len = rng.gen_range(0..512);
                (0..len).map(|_| rng.gen()).collect()
            } else {
                mutate(&seeds[rng.gen_range(0..seeds.len())], &mut rng)
            };
            started.store(origin.elapsed().as_millis() as u64, Ordering::Relaxed);
            let (peak, outcome) = peak_bytes(|| catch_unwind(AssertUnwindSafe(|| read(&input))));
            if outcome.is_err() || peak > self.bytes_per_input_byte * input.len() + self.slack {
                finished.store(true, Ordering::Relaxed);
            }
            started.store(IDLE, Ordering::Relaxed);
            let shown = String::from_utf8_lossy(&input[..input.len().min(300)]).into_owned();
            if let Err(panic) = outcome {
                eprintln!(
                    "{name}: input {i} ({} bytes) panicked: {shown:?}",
                    input.len()
                );
                std::panic::resume_unwind(panic);
            }
            let bound = self.bytes_per_input_byte * input.len() + self.slack;
            assert!(
                peak <= bound,
                "{name}: input {i} ({} bytes) took {peak} bytes, more than {bound}: {shown:?}",
                input.len()
            );
        }
        finished.store(true, Ordering::Relaxed);
        watchdog.join().unwrap();
    }
}

/// The files of `tests/fuzz_corpus/` whose names end with one of `endings`.
pub fn corpus(endings: &[&str]) -> Vec<Vec<u8>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz_corpus");
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| endings.iter().any(|end| p.to_string_lossy().ends_with(end)))
        .collect();
    names.sort();
    names.iter().map(|p| std::fs::read(p).unwrap()).collect()
}
