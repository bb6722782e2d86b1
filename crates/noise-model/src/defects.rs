//! Data defects no noise model describes: a stretch where the sensor repeats one value far
//! longer than its noise allows (a stuck reading), and isolated samples far off their neighbours
//! (glitches). Both bend the Allan curve the way noise does — a stuck stretch lowers it, a
//! single spike of size A adds A²/(m·n) at every τ = m·τ0, the slope of white noise — so the
//! Allan fit alone passes them (a 1e6 spike on white noise read as N 10⁵ times the truth, and
//! adequate). They are found in the time series and make the lab's verdict not adequate.
//!
//! Both tests are deliberately conservative (a false alarm on a good record is worse than a
//! missed small glitch, which the noise terms absorb):
//! * **Stuck**: with q the fraction of consecutive samples that repeat elsewhere in the record,
//!   a run of L equal samples has probability ≈ n·q^(L−1) somewhere among n (independent
//!   repeats; correlated ones make runs longer, hence the margins). A run counts when that is
//!   below 1e-9, L ≥ 64 and L is 8 times the longest other run; only where repeats are rare
//!   (q ≤ 0.5: the noise spans a few LSB), since a signal below one LSB repeats by itself.
//! * **Glitch**: a sample beyond both its neighbours on one side, by the smaller of its two
//!   distances to them (a step, one neighbour on each level, is none; a ramp or a slow drift
//!   moves both distances alike), against 1.4826 × the first differences' median absolute
//!   deviation, a robust σ a few spikes do not move. A sample counts beyond 12 robust σ (for
//!   Gaussian noise both distances beyond it: p ≈ 1e-60), and only while such samples are rare
//!   (at most one in 10,000, or 3): many of them are the noise's own tails, not glitches.

/// Runs and glitches found in one column, as sample positions in the concatenated data.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Defects {
    /// (first sample, length, value) of each stuck run.
    pub stuck: Vec<(usize, usize, f64)>,
    /// (sample, the smaller of its distances to its neighbours in robust σ of the first
    /// difference) of each glitch.
    pub glitches: Vec<(usize, f64)>,
}

impl Defects {
    pub fn is_empty(&self) -> bool {
        self.stuck.is_empty() && self.glitches.is_empty()
    }
}

/// Shortest run that may count as stuck, samples.
const MIN_RUN: usize = 64;
/// A stuck run is this many times the longest other run.
const RUN_RATIO: usize = 8;
/// Family-wise probability below which a run is not the noise's own.
const P_RUN: f64 = 1e-9;
/// Glitch threshold, robust σ of the first difference.
const GLITCH_SIGMA: f64 = 12.0;
/// A glitch on a lattice is more than this many LSB off both its neighbours.
const GLITCH_LSB: f64 = 4.0;
/// Glitches listed at most (a record with more has heavy-tailed noise, not glitches).
const MAX_GLITCHES: usize = 3;

/// The defects of `y`, whose `lengths` are its segments' (differences never span two), its
/// values on a lattice of `lsb` when they are.
pub fn find(y: &[f64], lengths: &[usize], lsb: Option<f64>) -> Defects {
    Defects {
        stuck: stuck_runs(y, lengths),
        glitches: glitches(y, lengths, lsb),
    }
}

/// The segments' ranges in `y`.
fn ranges(y: &[f64], lengths: &[usize]) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut at = 0;
    for &l in lengths {
        let end = (at + l).min(y.len());
        out.push(at..end);
        at = end;
    }
    out
}

fn stuck_runs(y: &[f64], lengths: &[usize]) -> Vec<(usize, usize, f64)> {
    // every maximal run of equal values: (start, length)
    let mut runs = Vec::new();
    let (mut pairs, mut repeats) = (0usize, 0usize);
    for r in ranges(y, lengths) {
        let s = &y[r.clone()];
        let mut i = 0;
        while i < s.len() {
            let mut j = i + 1;
            while j < s.len() && s[j] == s[i] {
                j += 1;
            }
            runs.push((r.start + i, j - i));
            repeats += j - i - 1;
            i = j;
        }
        pairs += s.len().saturating_sub(1);
    }
    let Some(&(start, len)) = runs.iter().max_by_key(|r| r.1) else {
        return Vec::new();
    };
    if len < MIN_RUN {
        return Vec::new();
    }
    let others = runs
        .iter()
        .filter(|r| r.0 != start)
        .map(|r| r.1)
        .max()
        .unwrap_or(1);
    // the repeats outside the candidate run
    let q = (repeats - (len - 1)) as f64 / (pairs - (len - 1)).max(1) as f64;
    let n = y.len() as f64;
    let p = n * q.powi(len as i32 - 1);
    if q <= 0.5 && p < P_RUN && len >= RUN_RATIO * others {
        vec![(start, len, y[start])]
    } else {
        Vec::new()
    }
}

fn glitches(y: &[f64], lengths: &[usize], lsb: Option<f64>) -> Vec<(usize, f64)> {
    // first differences within each segment, and each inner sample's spike size: the smaller
    // of its distances to its two neighbours when it lies beyond both on one side (a step has
    // one neighbour on each level, so none)
    let (mut d, mut spike) = (Vec::new(), Vec::new());
    for r in ranges(y, lengths) {
        let s = &y[r.clone()];
        d.extend(s.windows(2).map(|w| w[1] - w[0]));
        for i in 1..s.len().saturating_sub(1) {
            let (a, b) = (s[i] - s[i - 1], s[i] - s[i + 1]);
            if a * b > 0.0 {
                spike.push((r.start + i, a.abs().min(b.abs())));
            }
        }
    }
    if d.len() < 16 {
        return Vec::new();
    }
    // the differences' robust σ: 1.4826 × their median absolute deviation
    d.sort_by(f64::total_cmp);
    let med = d[d.len() / 2];
    let mut dev: Vec<f64> = d.iter().map(|x| (x - med).abs()).collect();
    dev.sort_by(f64::total_cmp);
    let mut sigma = 1.4826 * dev[dev.len() / 2];
    if sigma == 0.0 {
        // More than half the samples repeat their neighbour (noise below an LSB): σ from the
        // mean deviation (σ·√(2/π) for Gaussian noise) of all but the largest 0.1 %.
        let kept = &dev[..dev.len() - dev.len() / 1000];
        sigma = 1.2533 * kept.iter().sum::<f64>() / kept.len() as f64;
    }
    if !(sigma > 0.0 && sigma.is_finite()) {
        // a constant signal: no scale to judge by
        return Vec::new();
    }
    // On a lattice coarser than the noise most samples sit on one level and a lone step of an
    // LSB or two off it is the noise itself (σ = LSB/4 puts 5 % of the samples there): a
    // glitch is more than GLITCH_LSB of them.
    let least = lsb.map_or(0.0, |l| GLITCH_LSB * l);
    let mut out: Vec<(usize, f64)> = spike
        .iter()
        .filter(|s| s.1 > least)
        .map(|&(i, v)| (i, v / sigma))
        .filter(|&(_, z)| z > GLITCH_SIGMA)
        .collect();
    if out.len() > (y.len() / 10_000).max(MAX_GLITCHES) {
        return Vec::new();
    }
    out.sort_by(|a, b| b.1.total_cmp(&a.1));
    out.truncate(MAX_GLITCHES);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(n: usize, key: u64, sigma: f64, lsb: f64) -> Vec<f64> {
        let mut g = crate::test_noise(key);
        (0..n)
            .map(|_| {
                let v = sigma * g();
                if lsb > 0.0 {
                    (v / lsb).round() * lsb
                } else {
                    v
                }
            })
            .collect()
    }

    /// A fresh key per run, or `PICO_IMU_TEST_KEY` to replay one a failure printed.
    fn key() -> u64 {
        if let Some(k) = std::env::var("PICO_IMU_TEST_KEY")
            .ok()
            .and_then(|v| v.parse().ok())
        {
            return k;
        }
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(9, |d| d.subsec_nanos() as u64)
    }

    /// Stuck stretches and spikes of drawn sizes and places are found where they are; white,
    /// quantised (down to a noise of 0.6 LSB), random-walk and low-pass noise without them, and
    /// white noise with a bias step of any size, give nothing.
    #[test]
    fn finds_stuck_runs_and_glitches_and_nothing_in_clean_noise() {
        let key = key();
        let mut g = crate::test_noise(key ^ 0x77);
        let mut u = move || g().abs().fract();
        for round in 0..20 {
            let n = 5_000 + (u() * 60_000.0) as usize;
            let sigma = 0.01 + u() * 0.1;
            let lsb = if round % 2 == 0 {
                0.0
            } else {
                sigma / (0.6 + 4.0 * u())
            };
            let clean = noise(n, key.wrapping_add(round), sigma, lsb);
            // clean: white, then its running sum (a random walk), then a one-pole low-pass
            let walk: Vec<f64> = clean
                .iter()
                .scan(0.0, |s, v| {
                    *s += v;
                    Some(*s)
                })
                .collect();
            let lp: Vec<f64> = clean
                .iter()
                .scan(0.0, |s, v| {
                    *s += 0.3 * (v - *s);
                    Some(*s)
                })
                .collect();
            // a bias step of any size: no glitch
            let at = 1 + (u() * (n - 2) as f64) as usize;
            let size = sigma * 10f64.powf(1.0 + 3.0 * u());
            let stepped: Vec<f64> = clean
                .iter()
                .enumerate()
                .map(|(i, v)| if i >= at { v + size } else { *v })
                .collect();
            // the same noise rounded to an LSB of 3–6 σ: most samples on one level, lone
            // excursions of an LSB
            let coarse_lsb = sigma * (3.0 + 3.0 * u());
            let coarse: Vec<f64> = clean
                .iter()
                .map(|v| (v / coarse_lsb).round() * coarse_lsb)
                .collect();
            let lattice = (lsb > 0.0).then_some(lsb);
            for (what, y, l) in [
                ("white", &clean, lattice),
                ("walk", &walk, None),
                ("low-pass", &lp, None),
                ("stepped", &stepped, lattice),
                ("coarse", &coarse, Some(coarse_lsb)),
            ] {
                let d = find(y, &[y.len()], l);
                assert!(
                    d.is_empty(),
                    "key {key} round {round}: {what} noise gave {d:?}"
                );
            }
            // a stuck stretch, long enough for the rule (8 times the longest run of repeats the
            // quantised noise makes by itself, 16 at 0.6 LSB)
            let natural = clean
                .chunk_by(|a, b| a == b)
                .map(<[f64]>::len)
                .max()
                .unwrap_or(1);
            let len = (8 * natural + 8).max(100) + (u() * 3_000.0) as usize;
            let at = 1 + (u() * (n - len - 2) as f64) as usize;
            let mut y = clean.clone();
            let v = y[at];
            y[at..at + len].fill(v);
            let d = find(&y, &[n], lattice);
            assert_eq!(d.stuck.len(), 1, "key {key} round {round}: {d:?}");
            let (s, l, _) = d.stuck[0];
            // the run may take in neighbours that happen to equal the stuck value
            assert!(
                s <= at && s + l >= at + len && l <= len + 40,
                "key {key}: {d:?} vs {at}+{len}"
            );
            // spikes, far apart
            let mut y = clean.clone();
            let k = 1 + (u() * 2.99) as usize;
            let mut at: Vec<usize> = (0..k)
                .map(|j| 2 + j * (n / k) + (u() * 100.0) as usize)
                .collect();
            at.sort();
            for &i in &at {
                y[i] += sigma * (30.0 + u() * 1e4) * if u() < 0.5 { 1.0 } else { -1.0 };
            }
            let d = find(&y, &[n], lattice);
            let mut got: Vec<usize> = d.glitches.iter().map(|g| g.0).collect();
            got.sort();
            assert_eq!(got, at, "key {key} round {round}: {d:?}");
        }
    }

    /// A sample's neighbours are its segment's: the last sample of a segment, far off, has one
    /// neighbour there and is no glitch; inside one segment it is one.
    #[test]
    fn segments_are_kept_apart() {
        let mut z = noise(4_000, key(), 0.05, 0.0);
        z[1_999] += 1e3;
        assert!(find(&z, &[2_000, 2_000], None).glitches.is_empty());
        assert_eq!(find(&z, &[4_000], None).glitches.len(), 1);
    }
}
