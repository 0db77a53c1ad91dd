//! The Gaussian kernel arithmetic shared by the exact E-step ([`super::estep`]) and the fast
//! Gauss transform ([`super::fgt`]), and the sums of one E-step (seed eq. (3.9)–(3.11)).

/// `a·b + c`, fused when the caller runs with FMA enabled.
#[inline(always)]
pub(crate) fn madd<const FMA: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FMA { a.mul_add(b, c) } else { a * b + c }
}

/// Vectorisable `exp(x)` for `x ≤ 0`, relative error below 1e−14 (Cody–Waite reduction
/// `x = k·ln2 + r`, `|r| ≤ ln2/2`, degree-11 Taylor polynomial, `2^k` assembled in the exponent
/// bits). Arguments below −708 return ≈ 2.2e−308 instead of 0, which no sum here can notice.
#[inline(always)]
pub(crate) fn exp_neg(x: f64) -> f64 {
    exp_neg_f::<false>(x)
}

/// [`exp_neg`] with the Horner steps fused when `FMA` (only inside FMA-enabled code).
#[inline(always)]
pub(crate) fn exp_neg_f<const FMA: bool>(x: f64) -> f64 {
    const LOG2E: f64 = std::f64::consts::LOG2_E;
    const LN2_HI: f64 = 6.931_471_803_691_238e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    // 1.5·2^52: adding it rounds to an integer held in the low mantissa bits.
    const MAGIC: f64 = 6_755_399_441_055_744.0;
    let x = x.max(-708.0);
    let t = madd::<FMA>(x, LOG2E, MAGIC);
    let k = t - MAGIC;
    let r = madd::<FMA>(-k, LN2_LO, madd::<FMA>(-k, LN2_HI, x));
    // Horner on the Taylor coefficients 1/11!, …, 1/1!, 1 (a fixed-length loop the compiler
    // unrolls).
    const C: [f64; 12] = [
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ];
    let mut p = C[0];
    for c in &C[1..] {
        p = madd::<FMA>(p, r, *c);
    }
    let bits = t.to_bits().wrapping_sub(MAGIC.to_bits()).wrapping_add(1023) << 52;
    p * f64::from_bits(bits)
}

/// The sums of one E-step.
#[derive(Debug, Clone)]
pub(crate) struct EStepSums<const D: usize> {
    /// `P1 = P·1`, length M.
    pub p1: Vec<f64>,
    /// `Pᵀ1`, length N.
    pub pt1: Vec<f64>,
    /// `P·X`, M rows.
    pub px: Vec<[f64; D]>,
    /// `N_P = 1ᵀP1`.
    pub np: f64,
}
