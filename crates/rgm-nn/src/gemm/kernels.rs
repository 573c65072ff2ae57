//! All the unsafe code of the bf16 GEMM: its two kernels ([`Kernel`]) and the packing
//! conversions. AMX: detecting it, asking Linux for the tile registers, and the tile instructions
//! themselves, through `asm!` (their intrinsics are nightly-only). AVX-512 BF16 (`vdpbf16ps`,
//! the processors without AMX that have it: AMD Zen 4 and later, Intel Cooper Lake): stable
//! intrinsics in `#[target_feature]` functions, called after runtime detection.
//!
//! AMX has eight tile registers `tmm0..tmm7` of up to 16 rows × 64 bytes. `tdpbf16ps C, A, B`
//! adds the product of a 16 × 32 bf16 tile A and a 32 × 16 bf16 tile B into a 16 × 16 f32 tile
//! C; B is stored in "VNNI pairs": row r holds, for each of the 16 columns, the two bf16 of rows
//! 2r and 2r + 1 side by side (so a B tile is also 16 rows × 64 bytes). The processor rounds
//! each step to nearest even, treats bf16 denormals as zero and ignores MXCSR.
//!
//! [`Tiles`] holds the configuration below on its thread while it lives: tmm0..tmm3 are a
//! 32 × 32 f32 block of the result (2 × 2 tiles), tmm4/tmm5 the two 16-row halves of A's
//! 32 × 32 slice, tmm6/tmm7 the two 16-column halves of B's 32 × 32 slice; one step is 4
//! `tdpbf16ps`, 32 × 32 × 32 multiply-adds.

use ndarray::ArrayViewMut2;
use std::marker::PhantomData;
use std::sync::OnceLock;

/// Elements (u16) of one packed 32 × 32 bf16 slice of A or of B: 2 KiB, two tiles.
pub(super) const SLICE: usize = 32 * 32;

/// A kernel computing one 32 × 32 block of the product from packed strips (see [`Tiles::block`]).
pub(super) enum Kernel {
    Amx(Tiles),
    Avx512Bf16(Avx512Bf16),
}

impl Kernel {
    /// The fastest kernel this processor runs (AMX, then AVX-512 BF16), set up on the calling
    /// thread; `None` without either.
    pub(super) fn new() -> Option<Self> {
        if let Some(tiles) = Tiles::configure() {
            return Some(Self::Amx(tiles));
        }
        Avx512Bf16::new().map(Self::Avx512Bf16)
    }

    /// See [`Tiles::block`]; both kernels compute the same block (each step rounds to nearest
    /// even and flushes bf16 denormals) up to the order of the f32 additions.
    pub(super) fn block(
        &mut self,
        a: &[u16],
        b: &[u16],
        out: ArrayViewMut2<'_, f32>,
        accumulate: bool,
    ) {
        match self {
            Self::Amx(tiles) => tiles.block(a, b, out, accumulate),
            Self::Avx512Bf16(k) => k.block(a, b, out, accumulate),
        }
    }
}

/// The name of the kernel [`Kernel::new`] picks here: "amx", "avx512_bf16", or `None`.
pub fn backend() -> Option<&'static str> {
    if amx_available() {
        Some("amx")
    } else if has_avx512_bf16() {
        Some("avx512_bf16")
    } else {
        None
    }
}

/// Whether this process may run AMX-BF16: the processor has it, the kernel saves its state, and
/// Linux granted the permission. Checked once per process.
pub fn amx_available() -> bool {
    static AVAILABLE: OnceLock<bool> = OnceLock::new();
    *AVAILABLE.get_or_init(detect)
}

#[cfg(all(target_arch = "x86_64", target_os = "linux"))]
fn detect() -> bool {
    use std::arch::x86_64::{__cpuid, __cpuid_count};
    // SAFETY: cpuid exists on every x86-64 processor and only reads identification registers;
    // leaf 7 is asked for only when the processor reports it (max leaf ≥ 7).
    #[allow(unused_unsafe)]
    let (leaf1, leaf7) = unsafe {
        if __cpuid(0).eax < 7 {
            return false;
        }
        (__cpuid(1), __cpuid_count(7, 0))
    };
    let osxsave = leaf1.ecx & (1 << 27) != 0; // the OS enabled XSAVE and xgetbv
    let amx_bf16 = leaf7.edx & (1 << 22) != 0;
    let amx_tile = leaf7.edx & (1 << 24) != 0;
    if !(osxsave && amx_bf16 && amx_tile) {
        return false;
    }
    let (lo, hi): (u32, u32);
    // SAFETY: xgetbv with ecx = 0 reads XCR0; it is valid because OSXSAVE is set (checked above).
    unsafe {
        std::arch::asm!("xgetbv", in("ecx") 0, out("eax") lo, out("edx") hi,
                        options(nomem, nostack, preserves_flags));
    }
    let xcr0 = (u64::from(hi) << 32) | u64::from(lo);
    // XCR0 bit 17 (XTILECFG) and bit 18 (XTILEDATA): the OS saves the tile state on switches.
    if xcr0 & (0b11 << 17) != 0b11 << 17 {
        return false;
    }
    // Linux (5.16+) keeps the 8 KiB tile data off until a process asks for it: without this call
    // the first tile instruction is killed with SIGILL. The permission is process-wide.
    const ARCH_REQ_XCOMP_PERM: libc::c_long = 0x1023;
    const XFEATURE_XTILEDATA: libc::c_long = 18;
    // SAFETY: arch_prctl(ARCH_REQ_XCOMP_PERM, feature) takes two integers, touches no memory of
    // ours, and only widens the signal frame and the state the kernel saves for this process.
    let granted = unsafe {
        libc::syscall(
            libc::SYS_arch_prctl,
            ARCH_REQ_XCOMP_PERM,
            XFEATURE_XTILEDATA,
        )
    };
    granted == 0
}

#[cfg(not(all(target_arch = "x86_64", target_os = "linux")))]
fn detect() -> bool {
    false
}

/// The 64-byte operand of `ldtilecfg` (palette 1): bytes per row and rows of each tile.
#[repr(C, align(64))]
struct TileConfig {
    palette: u8,
    start_row: u8,
    reserved: [u8; 14],
    colsb: [u16; 16], // bytes per row of tmm0..tmm15 (only 0..7 exist)
    rows: [u8; 16],   // rows of tmm0..tmm15
}

/// The tile registers configured on this thread (see the module doc) while the value lives;
/// dropping it releases them (`tilerelease`), so the thread saves no tile state afterwards.
/// Not `Send`: the configuration belongs to the thread that loaded it.
pub(super) struct Tiles {
    _on_this_thread: PhantomData<*const ()>,
}

impl Tiles {
    /// Configures the tiles on the calling thread; `None` where AMX is not [`amx_available`].
    pub(super) fn configure() -> Option<Self> {
        if !amx_available() {
            return None;
        }
        let config = TileConfig {
            palette: 1,
            start_row: 0,
            reserved: [0; 14],
            colsb: [64, 64, 64, 64, 64, 64, 64, 64, 0, 0, 0, 0, 0, 0, 0, 0],
            rows: [16, 16, 16, 16, 16, 16, 16, 16, 0, 0, 0, 0, 0, 0, 0, 0],
        };
        // SAFETY: AMX is available and permitted (checked above); `config` is a valid palette-1
        // configuration of 64 aligned bytes that ldtilecfg only reads.
        #[cfg(target_arch = "x86_64")]
        unsafe {
            std::arch::asm!("ldtilecfg [{}]", in(reg) &config, options(nostack, readonly));
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = config;
        Some(Self {
            _on_this_thread: PhantomData,
        })
    }

    /// One 32 × 32 block of `a · b` into `out`, a (32, 32) view with unit column stride (a
    /// block of C, or a scratch block): `out = a · b`, or `out += a · b` when `accumulate`.
    /// `a` holds Kp/32 packed slices of A's 32 rows (each 32 rows × 32 bf16, row-major), `b`
    /// Kp/32 packed slices of B's 32 columns (each two VNNI-pair tiles of 16 columns: 16 pair
    /// rows × 16 columns × 2).
    pub(super) fn block(
        &mut self,
        a: &[u16],
        b: &[u16],
        mut out: ArrayViewMut2<'_, f32>,
        accumulate: bool,
    ) {
        assert!(
            a.len().is_multiple_of(SLICE) && a.len() == b.len(),
            "packed slices: a {} and b {} elements",
            a.len(),
            b.len()
        );
        let row_stride = out.strides()[0];
        assert!(
            out.dim() == (32, 32) && out.strides()[1] == 1 && row_stride >= 32,
            "a 32 × 32 block with unit column stride, got {:?} with strides {:?}",
            out.shape(),
            out.strides()
        );
        let (c, c_stride) = (out.as_mut_ptr(), row_stride as usize * 4); // row stride in bytes
        #[cfg(target_arch = "x86_64")]
        {
            // SAFETY: `self` proves the tiles are configured on this thread (16 rows × 64 bytes
            // each). Every A or B load reads 16 rows of 64 bytes at a 64-byte stride, i.e. 1 KiB,
            // from the start or the middle of a 2 KiB slice that lies inside `a` or `b` (lengths
            // checked above). The C loads and stores touch 16 rows of 16 f32 at `c_stride`
            // bytes, at row 0 or 16 and column 0 or 16: exactly the 32 × 32 elements of `out`
            // (checked above: rows ≥ 32 elements apart, unit column stride), which it borrows
            // mutably.
            unsafe {
                if accumulate {
                    std::arch::asm!(
                        "tileloadd tmm0, [{c} + {s}*1]",
                        "tileloadd tmm1, [{c} + {s}*1 + 64]",
                        "tileloadd tmm2, [{c16} + {s}*1]",
                        "tileloadd tmm3, [{c16} + {s}*1 + 64]",
                        c = in(reg) c,
                        c16 = in(reg) c.add(16 * row_stride as usize),
                        s = in(reg) c_stride,
                        options(nostack, readonly)
                    );
                } else {
                    std::arch::asm!(
                        "tilezero tmm0",
                        "tilezero tmm1",
                        "tilezero tmm2",
                        "tilezero tmm3",
                        options(nomem, nostack)
                    );
                }
                for (a, b) in a.chunks_exact(SLICE).zip(b.chunks_exact(SLICE)) {
                    std::arch::asm!(
                        "tileloadd tmm4, [{a} + {stride}*1]",
                        "tileloadd tmm5, [{a} + {stride}*1 + 1024]",
                        "tileloadd tmm6, [{b} + {stride}*1]",
                        "tileloadd tmm7, [{b} + {stride}*1 + 1024]",
                        "tdpbf16ps tmm0, tmm4, tmm6",
                        "tdpbf16ps tmm1, tmm4, tmm7",
                        "tdpbf16ps tmm2, tmm5, tmm6",
                        "tdpbf16ps tmm3, tmm5, tmm7",
                        a = in(reg) a.as_ptr(),
                        b = in(reg) b.as_ptr(),
                        stride = in(reg) 64usize,
                        options(nostack, readonly)
                    );
                }
                std::arch::asm!(
                    "tilestored [{c} + {s}*1], tmm0",
                    "tilestored [{c} + {s}*1 + 64], tmm1",
                    "tilestored [{c16} + {s}*1], tmm2",
                    "tilestored [{c16} + {s}*1 + 64], tmm3",
                    c = in(reg) c,
                    c16 = in(reg) c.add(16 * row_stride as usize),
                    s = in(reg) c_stride,
                    options(nostack)
                );
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        unreachable!("Tiles exist only where AMX is available ({c:?}, {c_stride}, {accumulate})");
    }
}

impl Drop for Tiles {
    fn drop(&mut self) {
        // SAFETY: tilerelease returns the tiles to their initial state; valid whenever AMX is
        // available, which constructing `self` checked.
        #[cfg(target_arch = "x86_64")]
        unsafe {
            std::arch::asm!("tilerelease", options(nomem, nostack));
        }
    }
}

/// `tdpbf16ps` on registers only, `steps` × 4 tiles of 16 × 16 × 32 multiply-adds: the unit's
/// peak, without memory traffic (the benches report it beside the GEMM). Returns the
/// multiply-adds done, or `None` without AMX.
pub fn register_peak_loop(steps: u64) -> Option<u64> {
    let _tiles = Tiles::configure()?;
    #[cfg(target_arch = "x86_64")]
    // SAFETY: the tiles are configured (`_tiles`); the loop only computes on tile registers
    // (their contents are whatever they hold, e.g. zeros after configuration) and a counter.
    unsafe {
        std::arch::asm!(
            "2:",
            "tdpbf16ps tmm0, tmm4, tmm6",
            "tdpbf16ps tmm1, tmm4, tmm7",
            "tdpbf16ps tmm2, tmm5, tmm6",
            "tdpbf16ps tmm3, tmm5, tmm7",
            "dec {n}",
            "jnz 2b",
            n = inout(reg) steps.max(1) => _,
            options(nomem, nostack)
        );
    }
    Some(steps.max(1) * 4 * 16 * 16 * 32)
}

/// Whether the AVX-512 BF16 conversions are there (every AMX processor has them; checked anyway).
fn has_avx512_bf16() -> bool {
    static HAS: OnceLock<bool> = OnceLock::new();
    #[cfg(target_arch = "x86_64")]
    {
        *HAS.get_or_init(|| {
            std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx512bf16")
        })
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        *HAS.get_or_init(|| false)
    }
}

/// `dst[i] = bf16(src[i])`, 16 at a time with `vcvtneps2bf16` where the processor has it. That
/// instruction flushes f32 denormals to zero, which the tile units do with bf16 denormals anyway:
/// the products are the same as with [`super::bf16_bits`].
pub(super) fn round_into(dst: &mut [u16], src: &[f32]) {
    assert_eq!(dst.len(), src.len(), "round_into: lengths");
    #[cfg(target_arch = "x86_64")]
    if has_avx512_bf16() {
        // SAFETY: the processor has AVX-512F and AVX-512 BF16 (checked above).
        unsafe { round_into_avx512(dst, src) };
        return;
    }
    for (d, &x) in dst.iter_mut().zip(src) {
        *d = super::bf16_bits(x);
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bf16")]
unsafe fn round_into_avx512(dst: &mut [u16], src: &[f32]) {
    use std::arch::x86_64::*;
    let (mut d, mut s) = (dst.chunks_exact_mut(16), src.chunks_exact(16));
    for (d, s) in (&mut d).zip(&mut s) {
        // SAFETY: `s` holds 16 f32 and `d` 16 u16 (32 bytes); unaligned load and store.
        unsafe {
            let bf = _mm512_cvtneps_pbh(_mm512_loadu_ps(s.as_ptr()));
            _mm256_storeu_si256(
                d.as_mut_ptr().cast(),
                std::mem::transmute::<__m256bh, __m256i>(bf),
            );
        }
    }
    for (d, &x) in d.into_remainder().iter_mut().zip(s.remainder()) {
        *d = super::bf16_bits(x);
    }
}

/// `dst[2j] = bf16(r0[j])`, `dst[2j + 1] = bf16(r1[j])`: two rows of B as VNNI pairs, 16 columns
/// at a time where the processor has AVX-512 BF16 (denormals as in [`round_into`]).
pub(super) fn pairs_into(dst: &mut [u16], r0: &[f32], r1: &[f32]) {
    assert!(
        dst.len() == 2 * r0.len() && r0.len() == r1.len(),
        "pairs_into: lengths"
    );
    #[cfg(target_arch = "x86_64")]
    if has_avx512_bf16() {
        // SAFETY: the processor has AVX-512F and AVX-512 BF16 (checked above).
        unsafe { pairs_into_avx512(dst, r0, r1) };
        return;
    }
    for ((d, &x0), &x1) in dst.chunks_exact_mut(2).zip(r0).zip(r1) {
        d[0] = super::bf16_bits(x0);
        d[1] = super::bf16_bits(x1);
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bf16")]
unsafe fn pairs_into_avx512(dst: &mut [u16], r0: &[f32], r1: &[f32]) {
    use std::arch::x86_64::*;
    let mut d = dst.chunks_exact_mut(32);
    let (mut s0, mut s1) = (r0.chunks_exact(16), r1.chunks_exact(16));
    for ((d, s0), s1) in (&mut d).zip(&mut s0).zip(&mut s1) {
        // SAFETY: `s0`, `s1` hold 16 f32 each and `d` 32 u16 (64 bytes); unaligned loads and
        // store. Each 32-bit lane j gets bf16(s0[j]) in its low half and bf16(s1[j]) above.
        unsafe {
            let lo = _mm512_cvtneps_pbh(_mm512_loadu_ps(s0.as_ptr()));
            let hi = _mm512_cvtneps_pbh(_mm512_loadu_ps(s1.as_ptr()));
            let lo = _mm512_cvtepu16_epi32(std::mem::transmute::<__m256bh, __m256i>(lo));
            let hi = _mm512_cvtepu16_epi32(std::mem::transmute::<__m256bh, __m256i>(hi));
            _mm512_storeu_si512(
                d.as_mut_ptr().cast(),
                _mm512_or_si512(lo, _mm512_slli_epi32::<16>(hi)),
            );
        }
    }
    let tail = d.into_remainder();
    for ((d, &x0), &x1) in tail
        .chunks_exact_mut(2)
        .zip(s0.remainder())
        .zip(s1.remainder())
    {
        d[0] = super::bf16_bits(x0);
        d[1] = super::bf16_bits(x1);
    }
}

/// The AVX-512 BF16 kernel: proof that the processor has it (made by [`Kernel::new`] only).
pub(super) struct Avx512Bf16 {
    _private: (),
}

impl Avx512Bf16 {
    /// The kernel, where the processor has AVX-512F and AVX-512 BF16.
    pub(super) fn new() -> Option<Self> {
        has_avx512_bf16().then_some(Self { _private: () })
    }

    /// One block as [`Tiles::block`] computes it, with `vdpbf16ps`: 8 rows at a time, 16
    /// accumulators of 16 f32 (the block's 8 × 32), each pair row of B loaded once per 8 rows.
    pub(super) fn block(
        &mut self,
        a: &[u16],
        b: &[u16],
        mut out: ArrayViewMut2<'_, f32>,
        accumulate: bool,
    ) {
        assert!(
            a.len().is_multiple_of(SLICE) && a.len() == b.len(),
            "packed slices: a {} and b {} elements",
            a.len(),
            b.len()
        );
        assert!(
            out.dim() == (32, 32) && out.strides()[1] == 1,
            "a 32 × 32 block with unit column stride, got {:?} with strides {:?}",
            out.shape(),
            out.strides()
        );
        #[cfg(target_arch = "x86_64")]
        for (group, rows) in out.axis_chunks_iter_mut(ndarray::Axis(0), 8).enumerate() {
            // SAFETY: `self` exists only where the processor has AVX-512F and AVX-512 BF16.
            unsafe { dp_rows_avx512(a, b, group * 8, rows, accumulate) };
        }
        #[cfg(not(target_arch = "x86_64"))]
        unreachable!("Avx512Bf16 exists only on x86-64 ({accumulate})");
    }
}

/// Rows `row0..row0 + 8` of the block into `out` (8, 32): see [`Avx512Bf16::block`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bf16")]
unsafe fn dp_rows_avx512(
    a: &[u16],
    b: &[u16],
    row0: usize,
    mut out: ArrayViewMut2<'_, f32>,
    accumulate: bool,
) {
    use std::arch::x86_64::*;
    let mut each_row = out.rows_mut().into_iter();
    let mut rows: [&mut [f32]; 8] = std::array::from_fn(|_| {
        let row = each_row.next().expect("8 rows");
        row.into_slice().expect("unit column stride")
    });
    let mut acc = [[_mm512_setzero_ps(); 2]; 8]; // (8 rows, 2 × 16 columns)
    if accumulate {
        for (acc, row) in acc.iter_mut().zip(&rows) {
            // SAFETY: each row holds 32 f32 (a block row); unaligned loads.
            unsafe {
                acc[0] = _mm512_loadu_ps(row.as_ptr());
                acc[1] = _mm512_loadu_ps(row.as_ptr().add(16));
            }
        }
    }
    for (a, b) in a.chunks_exact(SLICE).zip(b.chunks_exact(SLICE)) {
        for r in 0..16 {
            let (b0, b1) = (&b[r * 32..][..32], &b[512 + r * 32..][..32]);
            // SAFETY: `b0`, `b1` hold 32 u16 (64 bytes) each; unaligned loads.
            let (b0, b1): (__m512bh, __m512bh) = unsafe {
                (
                    std::mem::transmute::<__m512i, __m512bh>(_mm512_loadu_si512(
                        b0.as_ptr().cast(),
                    )),
                    std::mem::transmute::<__m512i, __m512bh>(_mm512_loadu_si512(
                        b1.as_ptr().cast(),
                    )),
                )
            };
            for (i, acc) in acc.iter_mut().enumerate() {
                let at = (row0 + i) * 32 + 2 * r; // row row0 + i, k pair r
                let pair = u32::from(a[at]) | (u32::from(a[at + 1]) << 16);
                let pair: __m512bh = std::mem::transmute(_mm512_set1_epi32(pair as i32));
                acc[0] = _mm512_dpbf16_ps(acc[0], pair, b0);
                acc[1] = _mm512_dpbf16_ps(acc[1], pair, b1);
            }
        }
    }
    for (acc, row) in acc.iter().zip(&mut rows) {
        // SAFETY: each row holds 32 f32; unaligned stores.
        unsafe {
            _mm512_storeu_ps(row.as_mut_ptr(), acc[0]);
            _mm512_storeu_ps(row.as_mut_ptr().add(16), acc[1]);
        }
    }
}
