//! The phase of a rate record, `x[0] = 0, x[k] = Σ_{i<k} (y_i − ȳ)` (AllanTools'
//! `frequency2phase`), built on all cores with its buffer advised as huge pages.
use super::kernels::LANES;
use super::pool::cores;
use crate::AllanError;

/// Phase in "rate × samples" units with the mean rate removed and a leading 0.
#[cfg(test)]
pub(super) fn phase_from_rate(y: &[f64]) -> Vec<f64> {
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let mut x = Vec::with_capacity(y.len() + 1);
    let mut acc = 0.0;
    x.push(0.0);
    for v in y {
        acc += v - mean;
        x.push(acc);
    }
    x
}

/// Σ (v − shift) in eight independent lanes (vectorisable; the order differs from a
/// sequential sum only in rounding).
pub(super) fn lane_sum(y: &[f64], shift: f64) -> f64 {
    let mut acc = [0.0f64; LANES];
    let mut c = y.chunks_exact(LANES);
    for v in &mut c {
        for l in 0..LANES {
            acc[l] += v[l] - shift;
        }
    }
    acc.iter().sum::<f64>() + c.remainder().iter().map(|v| v - shift).sum::<f64>()
}

/// The same phase as [`phase_from_rate`] (equal up to rounding), built on all cores: each
/// core sums its share of the samples, then writes its share of the cumulative sum starting
/// from the sum of the shares before it. The sums are taken about the first sample, so a
/// large mean rate (gravity on an accelerometer) does not cost the shares' starting values
/// their low bits. The zeroed buffer is fresh from the allocator, so its pages are first
/// touched (and faulted in) by the cores that write them. Checks the input on the way: a
/// non-finite sample makes the total non-finite, and only then is it looked for.
pub(super) fn phase_from_rate_checked(y: &[f64]) -> Result<Vec<f64>, AllanError> {
    // Several shares a core, so a core that is held up (shared machine) delays little.
    let threads = (4 * cores()).min(y.len() / (1 << 16)).max(1);
    let chunk = y.len().div_ceil(threads).max(1);
    let shift = y.first().copied().unwrap_or(0.0);
    let sums: Vec<f64> = if threads == 1 {
        vec![lane_sum(y, shift)]
    } else {
        std::thread::scope(|s| {
            let hs: Vec<_> = y
                .chunks(chunk)
                .map(|c| s.spawn(move || lane_sum(c, shift)))
                .collect();
            hs.into_iter()
                .map(|h| h.join().expect("worker panicked"))
                .collect()
        })
    };
    let total: f64 = sums.iter().sum();
    if !(total.is_finite() && shift.is_finite()) {
        super::all_finite(y)?;
    }
    super::long_enough(y)?;
    let mean = shift + total / y.len() as f64;
    let mut x = vec![0.0f64; y.len() + 1];
    advise_huge_pages(&mut x);
    let fill = |out: &mut [f64], ys: &[f64], mut acc: f64| {
        for (o, v) in out.iter_mut().zip(ys) {
            acc += v - mean;
            *o = acc;
        }
    };
    if threads == 1 {
        fill(&mut x[1..], y, 0.0);
    } else {
        std::thread::scope(|s| {
            let mut start = 0.0;
            for ((out, ys), sum) in x[1..].chunks_mut(chunk).zip(y.chunks(chunk)).zip(&sums) {
                let acc = start;
                s.spawn(move || fill(out, ys, acc));
                start += sum - ys.len() as f64 * (mean - shift);
            }
        });
    }
    Ok(x)
}

/// Ask Linux to back the 2 MiB-aligned interior of a fresh, not yet touched buffer with
/// transparent huge pages (`madvise(MADV_HUGEPAGE)`; this machine class runs THP in `madvise`
/// mode). Filling a 43 MB phase otherwise takes ~10,000 page faults, about a quarter of the
/// whole computation; with huge pages it takes ~20. Advice only: contents are unchanged, and a
/// refusal (or another OS) just leaves small pages.
#[cfg(target_os = "linux")]
fn advise_huge_pages(buf: &mut [f64]) {
    const HUGE: usize = 2 << 20;
    let start = buf.as_mut_ptr() as usize;
    let end = start + std::mem::size_of_val(buf);
    let (lo, hi) = (start.next_multiple_of(HUGE), end / HUGE * HUGE);
    if hi > lo {
        // SAFETY: madvise(2) on whole pages inside memory this buffer owns; MADV_HUGEPAGE does
        // not change contents, and the result is deliberately ignored (advice only).
        unsafe {
            libc::madvise(lo as *mut libc::c_void, hi - lo, libc::MADV_HUGEPAGE);
        }
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_huge_pages(_: &mut [f64]) {}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_rng::rng;

    #[test]
    fn parallel_phase_matches_the_sequential_one_and_checks_the_input() {
        let mut u = rng(0x5eed);
        let y: Vec<f64> = (0..300_000).map(|_| 9.81 + u()).collect();
        let (a, b) = (phase_from_rate(&y), phase_from_rate_checked(&y).unwrap());
        assert_eq!(a.len(), b.len());
        // Both round: a sequential sum of n samples near ȳ is itself uncertain by ~n·|ȳ|·ε.
        // A different rounding of the mean is a linear phase (no difference sees it), so that
        // is taken out before comparing.
        let tol = 4.0 * y.len() as f64 * 9.81 * f64::EPSILON;
        let n = y.len() as f64;
        let drift = (a[y.len()] - b[y.len()]) / n;
        for (k, (p, q)) in a.iter().zip(&b).enumerate() {
            let e = p - q - drift * k as f64;
            assert!(e.abs() < tol, "k = {k}: {p} vs {q}");
        }
        let mut bad = y.clone();
        bad[200_000] = f64::NAN;
        bad[250_000] = f64::INFINITY;
        assert_eq!(
            phase_from_rate_checked(&bad),
            Err(AllanError::NotFinite { index: 200_000 })
        );
        assert_eq!(
            phase_from_rate_checked(&[1.0, 2.0]),
            Err(AllanError::TooShort {
                samples: 2,
                needed: 3
            })
        );
        assert_eq!(
            phase_from_rate_checked(&[1.0, f64::NAN]),
            Err(AllanError::NotFinite { index: 1 })
        );
    }
}
