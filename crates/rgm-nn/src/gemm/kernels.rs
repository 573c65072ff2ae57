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

use ndarray::{ArrayView2, ArrayViewMut2};
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

    /// `out = alpha · (a · b) + beta · out` for one block (`beta = 0` ignores what `out` held),
    /// `a`, `b` and `out` as in [`Tiles::block`]; both kernels compute the same block (each step
    /// rounds to nearest even and flushes bf16 denormals) up to the order of the f32 additions.
    pub(super) fn block(
        &mut self,
        a: &[u16],
        b: &[u16],
        out: ArrayViewMut2<'_, f32>,
        alpha: f32,
        beta: f32,
    ) {
        match self {
            Self::Amx(tiles) => super::scaled_block(
                |out, accumulate| tiles.block(a, b, out, accumulate),
                out,
                alpha,
                beta,
            ),
            Self::Avx512Bf16(k) => k.block(a, b, out, alpha, beta),
        }
    }
}

/// The name of the kernel `Kernel::new` picks here: "amx", "avx512_bf16", or `None`.
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

/// Whether the AVX-512 BF16 conversions and BW's word permutations are there (every AMX
/// processor has them; checked anyway).
fn has_avx512_bf16() -> bool {
    static HAS: OnceLock<bool> = OnceLock::new();
    #[cfg(target_arch = "x86_64")]
    {
        *HAS.get_or_init(|| {
            std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx512bw")
                && std::arch::is_x86_feature_detected!("avx512bf16")
        })
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        *HAS.get_or_init(|| false)
    }
}

/// Packs `a` (M, K) into `out` in A's layout (see [`super::pack_a`]) with `vcvtneps2bf16`, where
/// the processor has AVX-512 BF16 and `a`'s rows or columns are contiguous; returns `false`,
/// writing nothing, otherwise. `out` holds the padded (Mp, Kp), every value of it written. The
/// conversion flushes f32 denormals to zero, which the kernels do with bf16 denormals anyway:
/// the products are those of [`super::bf16_bits`]'s rounding.
pub(super) fn pack_a(a: ArrayView2<'_, f32>, kp: usize, out: &mut [u16]) -> bool {
    #[cfg(target_arch = "x86_64")]
    if has_avx512_bf16() && (a.strides()[1] == 1 || a.strides()[0] == 1) {
        assert_eq!(
            out.len(),
            a.nrows().next_multiple_of(32) * kp,
            "pack_a: out"
        );
        // SAFETY: the processor has AVX-512 F, BW and BF16 (checked above); `out` is A's padded
        // size.
        unsafe { pack_a_avx512(a, kp, out) };
        return true;
    }
    let _ = (a, kp, out);
    false
}

/// Packs `b` (K, N) into `out` in B's layout of VNNI pairs (see [`super::pack_b`]), every value
/// of the padded (Kp, Np) written; as [`pack_a`] otherwise.
pub(super) fn pack_b(b: ArrayView2<'_, f32>, kp: usize, out: &mut [u16]) -> bool {
    #[cfg(target_arch = "x86_64")]
    if has_avx512_bf16() && (b.strides()[1] == 1 || b.strides()[0] == 1) {
        assert_eq!(
            out.len(),
            b.ncols().next_multiple_of(32) * kp,
            "pack_b: out"
        );
        // SAFETY: as in `pack_a`.
        unsafe { pack_b_avx512(b, kp, out) };
        return true;
    }
    let _ = (b, kp, out);
    false
}

/// Fetches, for writing, the first `rows` rows (`row_stride` apart) of the 32 × 32 block of C
/// at `c` that a kernel writes next: the stores of a C too large for the caches (the
/// attention's kept scores) would otherwise each wait on memory. A prefetch never faults, so
/// rows past C's end are harmless.
pub(super) fn prefetch_block(c: *const f32, rows: usize, row_stride: isize) {
    #[cfg(target_arch = "x86_64")]
    for r in 0..rows.min(32) {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_ET0};
        let row = c.wrapping_offset(r as isize * row_stride);
        // SAFETY: a prefetch reads nothing the program sees and never faults.
        unsafe {
            _mm_prefetch::<_MM_HINT_ET0>(row.cast());
            _mm_prefetch::<_MM_HINT_ET0>(row.wrapping_add(16).cast());
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (c, rows, row_stride);
}

/// The first `n` of 16 lanes (all for n ≥ 16, none for n = 0).
#[inline]
#[cfg(target_arch = "x86_64")]
fn lanes(n: usize) -> u16 {
    if n >= 16 {
        !0
    } else {
        (1u16 << n) - 1
    }
}

/// 32 f32 from `p` (the first `n` of them, zeros after) rounded to bf16, in order.
///
/// # Safety
/// AVX-512 F and BF16; `p` reaches `min(n, 32)` values.
#[inline]
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bf16")]
unsafe fn bf16_x32(p: *const f32, n: usize) -> std::arch::x86_64::__m512i {
    use std::arch::x86_64::*;
    // SAFETY: the masks keep both loads inside the n values (a masked-off lane never faults).
    unsafe {
        let lo = _mm512_maskz_loadu_ps(lanes(n), p);
        let hi = _mm512_maskz_loadu_ps(lanes(n.saturating_sub(16)), p.wrapping_add(16));
        std::mem::transmute::<__m512bh, __m512i>(_mm512_cvtne2ps_pbh(hi, lo))
    }
}

/// 16 lanes of 32 bits: lane j is bf16(r0[j]) below bf16(r1[j]) (a VNNI pair), from the first
/// `n` values of each row (zeros after); a `None` row is zeros. One conversion of both rows
/// (r0's 16 words below r1's) and one word permutation that interleaves them.
///
/// # Safety
/// AVX-512 F, BW and BF16; each row reaches `min(n, 16)` values.
#[inline]
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512bf16")]
unsafe fn bf16_pairs_x16(
    r0: Option<*const f32>,
    r1: Option<*const f32>,
    n: usize,
) -> std::arch::x86_64::__m512i {
    use std::arch::x86_64::*;
    /// Word 2j takes word j (r0's j-th), word 2j + 1 takes word 16 + j (r1's j-th).
    const INTERLEAVE: [u16; 32] = {
        let mut index = [0u16; 32];
        let mut j = 0;
        while j < 16 {
            index[2 * j] = j as u16;
            index[2 * j + 1] = 16 + j as u16;
            j += 1;
        }
        index
    };
    // SAFETY: the mask keeps the load inside the row's n values.
    let row = |r: Option<*const f32>| match r {
        Some(p) => unsafe { _mm512_maskz_loadu_ps(lanes(n), p) },
        None => _mm512_setzero_ps(),
    };
    // SAFETY: AVX-512 F, BW and BF16 (this function's contract); the index is 64 bytes.
    unsafe {
        let both = std::mem::transmute::<__m512bh, __m512i>(_mm512_cvtne2ps_pbh(row(r1), row(r0)));
        _mm512_permutexvar_epi16(_mm512_loadu_si512(INTERLEAVE.as_ptr().cast()), both)
    }
}

/// Transposes 16 × 16 lanes of 32 bits (bf16 pairs) in registers.
///
/// # Safety
/// AVX-512 F.
#[inline]
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn transpose_words(w: &mut [std::arch::x86_64::__m512i; 16]) {
    use std::arch::x86_64::*;
    // SAFETY: 16 vectors of 512 bits either way (a cast of bits, as `_mm512_castsi512_ps`).
    let f = unsafe { &mut *(w as *mut [__m512i; 16]).cast::<[__m512; 16]>() };
    // SAFETY: AVX-512 F (this function's contract).
    unsafe { super::f32_avx512::transpose_16x16(f) };
}

/// See [`pack_a`].
///
/// # Safety
/// AVX-512 F, BW and BF16; a unit stride in `a`; `out` holds (Mp, Kp).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512bf16")]
unsafe fn pack_a_avx512(a: ArrayView2<'_, f32>, kp: usize, out: &mut [u16]) {
    use std::arch::x86_64::*;
    let ((m, k), [rs, cs]) = (a.dim(), [a.strides()[0], a.strides()[1]]);
    let base = a.as_ptr();
    let dst = out.as_mut_ptr();
    if cs == 1 {
        // Rows contiguous: each row's 32 values of a slice rounded into its slice row.
        // Rows M..Mp are zeros.
        for i in 0..m.next_multiple_of(32) {
            let row = base.wrapping_offset(i as isize * rs);
            let (k, strip_row) = (
                if i < m { k } else { 0 },
                (i / 32) * kp * 32 + (i % 32) * 32,
            );
            for s in 0..kp / 32 {
                // SAFETY: row i < m holds k values (none are read past m); the store is one
                // slice row of `out`.
                unsafe {
                    let v = bf16_x32(row.wrapping_add(32 * s), k.saturating_sub(32 * s));
                    _mm512_storeu_si512(dst.add(strip_row + s * 1024).cast(), v);
                }
            }
        }
        return;
    }
    // Columns contiguous (a transposed view, as `doutᵀ · inp`): per 16 rows and slice, the 16
    // pairs of columns (2p, 2p + 1) as VNNI pairs of the 16 rows, transposed into the rows'
    // 16 pairs.
    let column = |kk: usize| (kk < k).then(|| base.wrapping_offset(kk as isize * cs));
    let mut w = [_mm512_setzero_si512(); 16];
    for i0 in (0..m.next_multiple_of(32)).step_by(16) {
        let n = m.saturating_sub(i0); // rows M..Mp are zeros
        for s in 0..kp / 32 {
            for (p, w) in w.iter_mut().enumerate() {
                let (c0, c1) = (column(32 * s + 2 * p), column(32 * s + 2 * p + 1));
                // SAFETY: each column holds m values, so n from row i0.
                *w = unsafe {
                    bf16_pairs_x16(
                        c0.map(|c| c.wrapping_add(i0)),
                        c1.map(|c| c.wrapping_add(i0)),
                        n,
                    )
                };
            }
            // SAFETY: AVX-512 F.
            unsafe { transpose_words(&mut w) };
            let at = (i0 / 32) * kp * 32 + s * 1024 + (i0 % 32) * 32;
            for (r, w) in w.iter().enumerate() {
                // SAFETY: row i0 + r of the strip (< Mp), slice s: 32 u16.
                unsafe { _mm512_storeu_si512(dst.add(at + r * 32).cast(), *w) };
            }
        }
    }
}

/// See [`pack_b`].
///
/// # Safety
/// AVX-512 F, BW and BF16; a unit stride in `b`; `out` holds (Kp, Np).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512bf16")]
unsafe fn pack_b_avx512(b: ArrayView2<'_, f32>, kp: usize, out: &mut [u16]) {
    use std::arch::x86_64::*;
    let ((k, n), [rs, cs]) = (b.dim(), [b.strides()[0], b.strides()[1]]);
    let base = b.as_ptr();
    let dst = out.as_mut_ptr();
    let np = n.next_multiple_of(32);
    if cs == 1 {
        // Rows contiguous: two rows at a time, 16 columns into each tile row.
        let row = |kk: usize| (kk < k).then(|| base.wrapping_offset(kk as isize * rs));
        for pair in 0..kp / 2 {
            let (r0, r1) = (row(2 * pair), row(2 * pair + 1));
            let pair_row = (pair / 16) * 1024 + (pair % 16) * 32;
            for j in (0..np).step_by(16) {
                // SAFETY: each row holds n values; the store is one tile row of `out`.
                unsafe {
                    let v = bf16_pairs_x16(
                        r0.map(|r| r.wrapping_add(j)),
                        r1.map(|r| r.wrapping_add(j)),
                        n.saturating_sub(j),
                    );
                    _mm512_storeu_si512(
                        dst.add((j / 32) * kp * 32 + ((j % 32) / 16) * 512 + pair_row)
                            .cast(),
                        v,
                    );
                }
            }
        }
        return;
    }
    // Columns contiguous (a transposed view, as `inp · weightᵀ`): per 16 columns and slice, each
    // column's 32 values rounded (16 pairs), transposed into the tile's 16 pair rows.
    let mut w = [_mm512_setzero_si512(); 16];
    for j0 in (0..np).step_by(16) {
        for s in 0..kp / 32 {
            for (c, w) in w.iter_mut().enumerate() {
                *w = match j0 + c < n {
                    // SAFETY: column j0 + c holds k values.
                    true => unsafe {
                        let col = base.wrapping_offset((j0 + c) as isize * cs);
                        bf16_x32(col.wrapping_add(32 * s), k.saturating_sub(32 * s))
                    },
                    false => _mm512_setzero_si512(),
                };
            }
            // SAFETY: AVX-512 F.
            unsafe { transpose_words(&mut w) };
            let at = (j0 / 32) * kp * 32 + s * 1024 + ((j0 % 32) / 16) * 512;
            for (r, w) in w.iter().enumerate() {
                // SAFETY: tile row r of slice s of the strip: 32 u16.
                unsafe { _mm512_storeu_si512(dst.add(at + r * 32).cast(), *w) };
            }
        }
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

    /// One block as [`Kernel::block`] computes it, with `vdpbf16ps`: 8 rows at a time, 16
    /// accumulators of 16 f32 (the block's 8 × 32), each pair row of B loaded once per 8 rows;
    /// alpha and beta applied as the rows are stored, as [`super::finish`] does.
    pub(super) fn block(
        &mut self,
        a: &[u16],
        b: &[u16],
        mut out: ArrayViewMut2<'_, f32>,
        alpha: f32,
        beta: f32,
    ) {
        assert!(
            a.len().is_multiple_of(SLICE) && a.len() == b.len(),
            "packed slices: a {} and b {} elements",
            a.len(),
            b.len()
        );
        assert!(
            out.dim() == (32, 32) && out.strides()[1] == 1 && out.strides()[0] >= 32,
            "a 32 × 32 block with unit column stride, got {:?} with strides {:?}",
            out.shape(),
            out.strides()
        );
        #[cfg(target_arch = "x86_64")]
        {
            let (c, row_stride) = (out.as_mut_ptr(), out.strides()[0] as usize);
            // SAFETY: `self` exists only where the processor has AVX-512F and AVX-512 BF16;
            // `a` and `b` hold whole slices alike, `c` 32 rows of 32 at `row_stride` (checked
            // above).
            unsafe { block_avx512(a, b, c, row_stride, alpha, beta) };
        }
        #[cfg(not(target_arch = "x86_64"))]
        unreachable!("Avx512Bf16 exists only on x86-64 ({alpha}, {beta})");
    }
}

/// See [`Avx512Bf16::block`].
///
/// # Safety
/// AVX-512 F and BF16; `a` and `b` the same whole number of slices; `c` reaches 32 rows of 32
/// f32, `row_stride` apart.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bf16")]
unsafe fn block_avx512(
    a: &[u16],
    b: &[u16],
    c: *mut f32,
    row_stride: usize,
    alpha: f32,
    beta: f32,
) {
    use std::arch::x86_64::*;
    let slices = a.len() / SLICE;
    // With alpha = 1 the product is stored as it is (beta = 0) or summed onto C's rows, loaded
    // first (beta = 1); any other alpha or beta scales the finished product (and C) as the rows
    // are stored, as `finish` does.
    let accumulate = alpha == 1.0 && beta == 1.0;
    let scaled = !(alpha == 1.0 && (beta == 0.0 || beta == 1.0));
    let (alphas, betas) = (_mm512_set1_ps(alpha), _mm512_set1_ps(beta));
    for row0 in (0..32).step_by(8) {
        // SAFETY: rows row0..row0 + 8 of the block; each reaches 32 f32.
        let row = |i: usize| unsafe { c.add((row0 + i) * row_stride) };
        let mut acc = [[_mm512_setzero_ps(); 2]; 8]; // (8 rows, 2 × 16 columns)
        if accumulate {
            for (i, acc) in acc.iter_mut().enumerate() {
                // SAFETY: a block row of 32 f32; unaligned loads.
                unsafe {
                    acc[0] = _mm512_loadu_ps(row(i));
                    acc[1] = _mm512_loadu_ps(row(i).add(16));
                }
            }
        }
        for s in 0..slices {
            // SAFETY: slice s of `a` and of `b` (SLICE u16 each).
            let (a, b) = unsafe { (a.as_ptr().add(s * SLICE), b.as_ptr().add(s * SLICE)) };
            for r in 0..16 {
                // SAFETY: B's tile rows r of the two 16-column halves (64 bytes each) and A's
                // pair r of rows row0..row0 + 8 (4 bytes each), all inside the slices.
                unsafe {
                    let b0: __m512bh =
                        std::mem::transmute(_mm512_loadu_si512(b.add(r * 32).cast()));
                    let b1: __m512bh =
                        std::mem::transmute(_mm512_loadu_si512(b.add(512 + r * 32).cast()));
                    for (i, acc) in acc.iter_mut().enumerate() {
                        let pair = a
                            .add((row0 + i) * 32 + 2 * r)
                            .cast::<i32>()
                            .read_unaligned();
                        let pair: __m512bh = std::mem::transmute(_mm512_set1_epi32(pair));
                        acc[0] = _mm512_dpbf16_ps(acc[0], pair, b0);
                        acc[1] = _mm512_dpbf16_ps(acc[1], pair, b1);
                    }
                }
            }
        }
        for (i, acc) in acc.iter().enumerate() {
            for (h, &acc) in acc.iter().enumerate() {
                // SAFETY: half h of a block row of 32 f32; unaligned loads and stores.
                unsafe {
                    let at = row(i).add(16 * h);
                    let v = match (scaled, beta == 0.0) {
                        (false, _) => acc,
                        (true, true) => _mm512_mul_ps(alphas, acc),
                        (true, false) => _mm512_add_ps(
                            _mm512_mul_ps(alphas, acc),
                            _mm512_mul_ps(betas, _mm512_loadu_ps(at)),
                        ),
                    };
                    _mm512_storeu_ps(at, v);
                }
            }
        }
    }
}
