//! The hot loops of the batch estimators: sums of squared second and third differences of the
//! phase at lag m (portable eight-lane code and an AVX2 + FMA copy chosen at run time), the
//! cache-blocked fused pass that serves many m at once, and the modified and total variance
//! sums. Each returns the plain sum the statistic's formula names; `batch` normalises it.
use crate::noise_id;

/// Sum of squared d-th differences at lag m over start indices 0, stride, 2·stride, …
pub(super) fn diff_sum(x: &[f64], m: usize, d: u32, stride: usize) -> (f64, u64) {
    let span = d as usize * m;
    if x.len() <= span {
        return (0.0, 0);
    }
    if stride == 1 {
        return (overlapping_sum(x, m, d), (x.len() - span) as u64);
    }
    let (mut s, mut n) = (0.0, 0u64);
    let mut i = 0;
    while i + span < x.len() {
        let v = if d == 2 {
            x[i + 2 * m] - 2.0 * x[i + m] + x[i]
        } else {
            x[i + 3 * m] - 3.0 * x[i + 2 * m] + 3.0 * x[i + m] - x[i]
        };
        s += v * v;
        n += 1;
        i += stride;
    }
    (s, n)
}

pub(super) const LANES: usize = 8;

/// The fully overlapping sum over equal-length shifted slices, in eight independent lanes so
/// the compiler can keep the loop in vector registers (the hot loop of every octave table).
pub(super) fn overlapping_sum(x: &[f64], m: usize, d: u32) -> f64 {
    let mut acc = [0.0f64; LANES];
    let tail = accumulate(x, m, d, 0, x.len() - d as usize * m, &mut acc);
    acc.iter().sum::<f64>() + tail
}

/// Add the squared d-th differences at lag m for start indices `i0..i1` into `acc`; returns
/// the sum of the part that does not fill a whole lane group.
///
/// On x86-64 CPUs with AVX2 and FMA (checked at run time, cached by std) a copy compiled for
/// them runs: four lanes a register and fused multiply-adds, which round once where the
/// portable code rounds twice (a difference in the last bit of a term).
pub(super) fn accumulate(
    x: &[f64],
    m: usize,
    d: u32,
    i0: usize,
    i1: usize,
    acc: &mut [f64; LANES],
) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU has the features the copy was compiled for.
        return unsafe { accumulate_avx2_fma(x, m, d, i0, i1, acc) };
    }
    accumulate_lanes::<false>(x, m, d, i0, i1, acc)
}

/// [`accumulate`] in AVX2 registers: the eight lanes are two 4-wide vectors, each term
/// `v = (c − 2b) + a` (or `(e − a) + 3(b − c)`) and `acc += v²` by fused multiply-adds. Written
/// with intrinsics so that it vectorises whatever the optimisation level (the workspace's
/// release profile optimises for size, which turns the auto-vectoriser off).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn accumulate_avx2_fma(
    x: &[f64],
    m: usize,
    d: u32,
    i0: usize,
    i1: usize,
    acc: &mut [f64; LANES],
) -> f64 {
    use std::arch::x86_64::*;
    let n = i1 - i0;
    let full = n / LANES * LANES;
    // Every load below is inside x: the last one starts at i1 − 4 + d·m.
    assert!(i1 + d as usize * m <= x.len());
    let p = x.as_ptr();
    // SAFETY: `acc` holds 8 f64, and every x index is in bounds by the assertion above.
    unsafe {
        let mut lo = _mm256_loadu_pd(acc.as_ptr());
        let mut hi = _mm256_loadu_pd(acc.as_ptr().add(4));
        // A macro, not closures or an inner loop: the body must inherit this function's
        // features and keep both accumulators in registers at any optimisation level.
        macro_rules! second {
            ($j:expr) => {{
                let j = $j;
                let c = _mm256_loadu_pd(p.add(j + 2 * m));
                let v = _mm256_fmadd_pd(_mm256_set1_pd(-2.0), _mm256_loadu_pd(p.add(j + m)), c);
                _mm256_add_pd(v, _mm256_loadu_pd(p.add(j)))
            }};
        }
        macro_rules! third {
            ($j:expr) => {{
                let j = $j;
                let (a, b) = (_mm256_loadu_pd(p.add(j)), _mm256_loadu_pd(p.add(j + m)));
                let c = _mm256_loadu_pd(p.add(j + 2 * m));
                let e = _mm256_loadu_pd(p.add(j + 3 * m));
                _mm256_fmadd_pd(
                    _mm256_set1_pd(3.0),
                    _mm256_sub_pd(b, c),
                    _mm256_sub_pd(e, a),
                )
            }};
        }
        let mut i = i0;
        if d == 2 {
            while i < i0 + full {
                let (v, w) = (second!(i), second!(i + 4));
                lo = _mm256_fmadd_pd(v, v, lo);
                hi = _mm256_fmadd_pd(w, w, hi);
                i += LANES;
            }
        } else {
            while i < i0 + full {
                let (v, w) = (third!(i), third!(i + 4));
                lo = _mm256_fmadd_pd(v, v, lo);
                hi = _mm256_fmadd_pd(w, w, hi);
                i += LANES;
            }
        }
        _mm256_storeu_pd(acc.as_mut_ptr(), lo);
        _mm256_storeu_pd(acc.as_mut_ptr().add(4), hi);
    }
    let mut rest = [0.0f64; LANES];
    accumulate_lanes::<true>(x, m, d, i0 + full, i1, &mut rest) + rest.iter().sum::<f64>()
}

/// The body of [`accumulate`]; `FMA` only where the target has fused multiply-add in hardware
/// (elsewhere `mul_add` is a slow library call).
#[inline(always)]
pub(super) fn accumulate_lanes<const FMA: bool>(
    x: &[f64],
    m: usize,
    d: u32,
    i0: usize,
    i1: usize,
    acc: &mut [f64; LANES],
) -> f64 {
    let n = i1 - i0;
    let mut tail = 0.0;
    if d == 2 {
        let (a, b, c) = (
            &x[i0..i1],
            &x[i0 + m..i0 + m + n],
            &x[i0 + 2 * m..i0 + 2 * m + n],
        );
        let mut ca = a.chunks_exact(LANES);
        let mut cb = b.chunks_exact(LANES);
        let mut cc = c.chunks_exact(LANES);
        for ((a, b), c) in (&mut ca).zip(&mut cb).zip(&mut cc) {
            for l in 0..LANES {
                if FMA {
                    let v = (-2.0f64).mul_add(b[l], c[l]) + a[l];
                    acc[l] = v.mul_add(v, acc[l]);
                } else {
                    let v = c[l] - 2.0 * b[l] + a[l];
                    acc[l] += v * v;
                }
            }
        }
        for ((a, b), c) in ca
            .remainder()
            .iter()
            .zip(cb.remainder())
            .zip(cc.remainder())
        {
            let v = c - 2.0 * b + a;
            tail += v * v;
        }
    } else {
        let (a, b, c, e) = (
            &x[i0..i1],
            &x[i0 + m..i0 + m + n],
            &x[i0 + 2 * m..i0 + 2 * m + n],
            &x[i0 + 3 * m..i0 + 3 * m + n],
        );
        let mut ca = a.chunks_exact(LANES);
        let mut cb = b.chunks_exact(LANES);
        let mut cc = c.chunks_exact(LANES);
        let mut ce = e.chunks_exact(LANES);
        for (((a, b), c), e) in (&mut ca).zip(&mut cb).zip(&mut cc).zip(&mut ce) {
            for l in 0..LANES {
                if FMA {
                    let v = 3.0f64.mul_add(b[l] - c[l], e[l] - a[l]);
                    acc[l] = v.mul_add(v, acc[l]);
                } else {
                    let v = e[l] - 3.0 * c[l] + 3.0 * b[l] - a[l];
                    acc[l] += v * v;
                }
            }
        }
        for (((a, b), c), e) in ca
            .remainder()
            .iter()
            .zip(cb.remainder())
            .zip(cc.remainder())
            .zip(ce.remainder())
        {
            let v = e - 3.0 * c + 3.0 * b - a;
            tail += v * v;
        }
    }
    tail
}

/// Start indices per block of the fused pass. A block reads `BLOCK` phase values at each
/// shift k·m (k = 0 … d) and sums every m of the group over them; for octave m the shift 2m
/// of one m is the shift m of the next (still in L1), so 22 octaves read 23 shifted blocks of
/// 16 KiB, those up to a few MiB ahead already in L2 from earlier blocks, the farthest from
/// L3. One pass serves every m instead of one pass per m.
pub(super) const BLOCK: usize = 2048;
/// Most m summed in one fused pass (more shifted blocks would fall out of L2).
pub(super) const FUSED_MAX: usize = 32;

/// Largest m whose noise-identification sums ride along the fused pass; beyond it the
/// averages are few and far apart and a pass of their own costs little.
pub(super) const ACF_FUSED_MAX: usize = 256;

/// Fully overlapping sums of squared d-th differences for every m in `ms` over the start
/// indices `lo..hi` (each m clipped to its own last start), in one cache-blocked pass, and the
/// noise-identification sums ([`noise_id::AvgSums`]) of the averages over the first `acf` of
/// the `ms` that start in `lo..hi` (to the end of the record when `tail`).
pub(super) fn overlapping_partial(
    x: &[f64],
    ms: &[usize],
    d: u32,
    (lo, hi): (usize, usize),
    acf: usize,
    tail: bool,
) -> (Vec<f64>, Vec<noise_id::AvgSums>) {
    let mut acc = vec![[0.0f64; LANES]; ms.len()];
    let mut tails = vec![0.0f64; ms.len()];
    let mut avg = vec![noise_id::AvgSums::default(); acf];
    let ends: Vec<usize> = ms
        .iter()
        .map(|&m| x.len().saturating_sub(d as usize * m).min(hi))
        .collect();
    let mut i0 = lo;
    while i0 < hi {
        let i1 = (i0 + BLOCK).min(hi);
        for (k, &m) in ms.iter().enumerate() {
            let e = i1.min(ends[k]);
            if e > i0 {
                tails[k] += accumulate(x, m, d, i0, e, &mut acc[k]);
            }
        }
        for (a, &m) in avg.iter_mut().zip(ms) {
            let j1 = if tail && i1 == hi {
                usize::MAX
            } else {
                i1.div_ceil(m)
            };
            a.add(x, m, i0.div_ceil(m), j1);
        }
        i0 = i1;
    }
    let sums = acc
        .iter()
        .zip(tails)
        .map(|(a, t)| a.iter().sum::<f64>() + t)
        .collect();
    (sums, avg)
}

/// Split the start indices of the fused pass over `ms` into `pieces` ranges of about equal
/// work (m has `len − d·m` starts, so the ranges near the end serve fewer m).
pub(super) fn split_work(len: usize, ms: &[usize], d: u32, pieces: usize) -> Vec<(usize, usize)> {
    let ends: Vec<usize> = ms
        .iter()
        .map(|&m| len.saturating_sub(d as usize * m))
        .collect();
    let last = ends.iter().copied().max().unwrap_or(0);
    let work = |a: usize| ends.iter().map(|&e| e.min(a) as u128).sum::<u128>();
    let total = work(last);
    let mut cuts = vec![0usize];
    for p in 1..pieces {
        let target = total * p as u128 / pieces as u128;
        let (mut lo, mut hi) = (*cuts.last().unwrap(), last);
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if work(mid) < target {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        cuts.push(lo);
    }
    cuts.push(last);
    cuts.windows(2)
        .filter(|w| w[1] > w[0])
        .map(|w| (w[0], w[1]))
        .collect()
}

/// Modified Allan variance sum: Σ_j [Σ_{i=j}^{j+m−1} (x[i+2m] − 2x[i+m] + x[i])]² (SP 1065 eq. 14).
pub(super) fn mod_sum(x: &[f64], m: usize) -> (f64, u64) {
    let np = x.len();
    if np < 3 * m + 1 {
        return (0.0, 0);
    }
    let d2 = |i: usize| x[i + 2 * m] - 2.0 * x[i + m] + x[i];
    let mut inner: f64 = (0..m).map(d2).sum();
    let mut s = inner * inner;
    let n = (np - 3 * m + 1) as u64;
    for j in 1..n as usize {
        inner += d2(j + m - 1) - d2(j - 1);
        s += inner * inner;
    }
    (s, n)
}

/// Total variance sum with reflection at both ends (SP 1065 eq. 25; AllanTools `totdev`).
pub(super) fn tot_sum(x: &[f64], m: usize) -> (f64, u64) {
    let np = x.len();
    // x*[1−j] = 2x[0] − x[j], x*[np−2+j] = 2x[np−1] − x[np−1−j], j = 1..np−2
    let at = |i: isize| -> f64 {
        let last = np as isize - 1;
        if i < 0 {
            2.0 * x[0] - x[(-i) as usize]
        } else if i > last {
            2.0 * x[last as usize] - x[(2 * last - i) as usize]
        } else {
            x[i as usize]
        }
    };
    let mut s = 0.0;
    for i in 1..np - 1 {
        let i = i as isize;
        let v = at(i - m as isize) - 2.0 * at(i) + at(i + m as isize);
        s += v * v;
    }
    (s, (np - 2) as u64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_rng::rng;

    /// Σ over i0..i1 of the squared d-th difference at lag m, term by term.
    fn straightforward(x: &[f64], m: usize, d: u32, i0: usize, i1: usize) -> f64 {
        (i0..i1)
            .map(|i| {
                let v = if d == 2 {
                    x[i + 2 * m] - 2.0 * x[i + m] + x[i]
                } else {
                    x[i + 3 * m] - 3.0 * x[i + 2 * m] + 3.0 * x[i + m] - x[i]
                };
                v * v
            })
            .sum()
    }

    #[test]
    fn difference_kernels_match_the_formula_on_random_data() {
        let mut u = rng(0x1234_5678);
        let mut acc = 0.0;
        let x: Vec<f64> = (0..30_011)
            .map(|_| {
                acc += 9.81 + u();
                acc
            })
            .collect();
        for d in [2u32, 3] {
            for (m, i0, i1) in [
                (1usize, 0usize, 29_000usize),
                (3, 5, 13),
                (64, 101, 20_000),
                (997, 7, 27_000),
            ] {
                let want = straightforward(&x, m, d, i0, i1);
                let mut lanes = [0.0; LANES];
                let tail = accumulate_lanes::<false>(&x, m, d, i0, i1, &mut lanes);
                let portable = lanes.iter().sum::<f64>() + tail;
                let mut lanes = [0.0; LANES];
                let tail = accumulate(&x, m, d, i0, i1, &mut lanes);
                let dispatched = lanes.iter().sum::<f64>() + tail;
                for got in [portable, dispatched] {
                    assert!(
                        (got / want - 1.0).abs() < 1e-11,
                        "d={d} m={m}: {got} vs {want}"
                    );
                }
            }
        }
    }

    #[test]
    fn fused_pass_matches_direct_sums_however_split() {
        let mut u = rng(0x0bad_cafe);
        let mut acc = 0.0;
        let x: Vec<f64> = (0..50_001)
            .map(|i| {
                acc += u() + if i % 7000 < 3500 { 0.1 } else { -0.1 };
                acc
            })
            .collect();
        for d in [2u32, 3] {
            for ms in [
                vec![
                    1usize, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048, 4096, 8192,
                ],
                vec![1, 3, 10, 30, 100, 5000, 16_000],
            ] {
                let n_acf = ms
                    .iter()
                    .take_while(|&&m| noise_id::averages(x.len(), m) >= 30)
                    .count();
                for pieces in [1usize, 2, 5] {
                    let ranges = split_work(x.len(), &ms, d, pieces);
                    let mut sums = vec![0.0; ms.len()];
                    let mut avg = vec![noise_id::AvgSums::default(); n_acf];
                    for (k, &r) in ranges.iter().enumerate() {
                        let (s, a) =
                            overlapping_partial(&x, &ms, d, r, n_acf, k + 1 == ranges.len());
                        sums.iter_mut().zip(s).for_each(|(t, v)| *t += v);
                        avg.iter_mut().zip(&a).for_each(|(t, v)| t.merge(v));
                    }
                    for (k, &m) in ms.iter().enumerate() {
                        let want = straightforward(&x, m, d, 0, x.len() - d as usize * m);
                        assert!(
                            (sums[k] / want - 1.0).abs() < 1e-11,
                            "d={d} m={m} pieces={pieces}"
                        );
                        if k < n_acf {
                            let mut whole = noise_id::AvgSums::default();
                            whole.add(&x, m, 0, usize::MAX);
                            let (a, b) = (avg[k], whole);
                            for (p, q) in [
                                (a.sb, b.sb),
                                (a.stb, b.stb),
                                (a.sbb, b.sbb),
                                (a.sbb1, b.sbb1),
                            ] {
                                assert!(
                                    (p - q).abs() <= 1e-9 * q.abs().max(1.0),
                                    "m={m}: {p} vs {q}"
                                );
                            }
                        }
                    }
                }
            }
        }
    }
}
