//! The host copy of the streaming engine's estimator: the exact integer sums
//! [`crate::Engine`] accumulates, computed directly from the samples ([`stride_sums`]), and the
//! table rows made from such sums ([`stream_rows`], also used on the engine's own sums).
use super::{bounds, redder, Estimator, Row};
use crate::confidence::{self, Variance};
use crate::stream::LevelSums;

/// The host "stride" estimator: exactly the integer sums the streaming engine
/// [`crate::Engine`]`<P, L, _, _>` accumulates over the same samples, computed directly from the
/// phase array. `segments` are runs of samples separated by gaps.
pub fn stride_sums(segments: &[&[i32]], p: usize, levels: usize) -> Vec<LevelSums> {
    let mut out: Vec<LevelSums> = (0..levels)
        .map(|k| {
            let m = 1u32 << k;
            LevelSums {
                m,
                stride: if m as usize <= p { 1 } else { m / p as u32 },
                ..Default::default()
            }
        })
        .collect();
    for seg in segments {
        let mut theta = Vec::with_capacity(seg.len() + 1);
        let mut acc = 0i64;
        theta.push(0i64);
        for &y in *seg {
            acc = acc.wrapping_add(y as i64);
            theta.push(acc);
        }
        let n = seg.len() as u64;
        for lv in out.iter_mut() {
            let (m, s) = (lv.m as u64, lv.stride as u64);
            let mut t = (2 * m).div_ceil(s) * s;
            while t <= n {
                let th = |i: u64| theta[i as usize] as i128;
                let d2 = th(t) - 2 * th(t - m) + th(t - 2 * m);
                lv.sum2 += (d2 * d2) as u128;
                lv.n2 += 1;
                if t >= 3 * m {
                    let d3 = th(t) - 3 * th(t - m) + 3 * th(t - 2 * m) - th(t - 3 * m);
                    lv.sum3 += (d3 * d3) as u128;
                    lv.n3 += 1;
                }
                t += s;
            }
        }
    }
    out
}

/// Table rows from streaming-engine sums: OADEV (or OHDEV with `hadamard`) in input units ×
/// `scale`, EDF by Greenhall with the estimator's stride factor S = m/stride, and the noise
/// exponent read from the slope to the neighbouring level.
pub fn stream_rows(levels: &[LevelSums], tau0: f64, scale: f64, hadamard: bool) -> Vec<Row> {
    let mut ceiling = None;
    let d = if hadamard { 3 } else { 2 };
    let var = |l: &LevelSums| if hadamard { l.ohdev(1.0) } else { l.oadev(1.0) };
    let mut rows = Vec::new();
    for (k, l) in levels.iter().enumerate() {
        let n = if hadamard { l.n3 } else { l.n2 };
        let Some(dev) = var(l).filter(|_| n >= 2) else {
            continue;
        };
        let neighbour = levels
            .get(k + 1)
            .and_then(|h| var(h).filter(|_| (if hadamard { h.n3 } else { h.n2 }) >= 2))
            .map(|v| (dev, v))
            .or_else(|| {
                k.checked_sub(1)
                    .and_then(|j| var(&levels[j]))
                    .map(|v| (v, dev))
            });
        let alpha = redder(
            neighbour.map(|(a, b)| confidence::alpha_from_slope(a * a, b * b, 2.0, d)),
            &mut ceiling,
        );
        let m = l.m as f64;
        let np = (n - 1) as f64 * l.stride as f64 + d as f64 * m + 1.0;
        let edf = confidence::edf_greenhall(
            alpha,
            m,
            np,
            Variance::Unmodified {
                d,
                s_factor: m / l.stride as f64,
            },
        )
        .unwrap_or(f64::NAN);
        let dev = dev * scale;
        let (lo, hi) = bounds(dev, edf);
        let estimator = if l.stride == 1 {
            Estimator::Exact
        } else {
            Estimator::Stride {
                stride: l.stride as u64,
            }
        };
        rows.push(Row {
            tau: m * tau0,
            m: l.m as u64,
            dev,
            n,
            alpha,
            edf,
            lo,
            hi,
            estimator,
        });
    }
    rows
}
