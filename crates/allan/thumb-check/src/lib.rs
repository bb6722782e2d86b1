//! Per-call differential test of allan's hand-written Thumb routines
//! (`pico_imu_allan_push_pair_small`, `pico_imu_allan_push_small`,
//! `pico_imu_allan_mag_push` in crates/allan/src/stream/thumb.rs) against the pure-Rust path
//! they replace. The magnetometer's routine has its own run, [`run_mag`].
//!
//! Two [`DeviceEngine`]s run in lock step on one deterministic stream of calls: engine A takes
//! every call the firmware's way ([`Engine::push_pair`] / [`Engine::push`], which enter the Thumb
//! code when the samples are steady and small), engine B the pure-Rust way
//! ([`Engine::push_pair_portable`] / [`Engine::push_portable`]). After every call their whole
//! states are compared ([`Engine::first_difference`]). A mismatch is counted, the first one is
//! recorded, and A is set back to B's state so the run goes on.
//!
//! The stream is made of episodes, each a new or continued segment (resets and gaps between
//! them), an amplitude and a waveform: uniform noise, square waves (the largest second and
//! third differences a level can see, up to the 2^16 limit of the one-multiply squares), random
//! walks, gate edges (|y − offset| = gate − 1, gate, gate + 1), values around 2^10 and 2^11 for
//! the gate (the Thumb routines' own limits), large inputs that leave the small path and the
//! extremes of i32. Calls are pairs or single samples, so segments run at both parities.
//!
//! The run also predicts from the inputs alone when the Thumb routines must take a call (a
//! mirror of the segment's offset, largest |z| and count gives the gate), so a routine that
//! wrongly declines is caught too, and a run where they never ran cannot pass.
//!
//! [`Engine::push_pair`]: allan::Engine::push_pair
//! [`Engine::push`]: allan::Engine::push
//! [`Engine::push_pair_portable`]: allan::Engine::push_pair_portable
//! [`Engine::push_portable`]: allan::Engine::push_portable
//! [`Engine::first_difference`]: allan::Engine::first_difference
#![no_std]

use allan::{DeviceEngine, Engine, MagEngine};
use thumb_check_rt::Rng;

/// Calls compared in a run (each `push` or `push_pair` on both engines).
pub const CASES: u32 = 22_000;

/// The generator's seed.
pub const SEED: u32 = 0x2545_f491;

/// Calls compared in the magnetometer run ([`run_mag`]).
pub const MAG_CASES: u32 = 10_000;

/// Its generator's seed.
pub const MAG_SEED: u32 = 0x6d61_6721;

pub use thumb_check_rt::{DONE, RUNNING};

/// [`Report::first_routine`] of a mismatch in a `push_pair` call.
pub const ROUTINE_PAIR: u32 = 1;
/// [`Report::first_routine`] of a mismatch in a `push` call.
pub const ROUTINE_SINGLE: u32 = 2;

/// Edge counters of the magnetometer run ([`run_mag`], [`Report::edges`]).
pub mod mag_edge {
    /// A steady sample with |z| = gate − 1 (the largest the routine takes without a new gate).
    pub const GATE_MINUS_ONE: usize = 0;
    /// A new largest |z| in the steady state (the gate is raised, the routine takes it).
    pub const RAISED: usize = 1;
    /// A steady sample with gate < 2^11 (the IMU engines' small range: no wide square).
    pub const GATE_BELOW_2_11: usize = 2;
    /// A steady sample with |z| ≥ 2^15 (every unit-stride square of a square wave is wide).
    pub const Z_FROM_2_15: usize = 3;
    /// A steady sample with |z| = 2^16 − 1 (one i16 extreme after the other).
    pub const Z_I16_SPAN: usize = 4;
    /// A sample of i16::MIN or i16::MAX.
    pub const I16_EXTREME: usize = 5;
    /// A steady sample of a square wave with |z| ≥ 2^14.
    pub const SQUARE_WAVE: usize = 6;
    /// A steady sample at a count of 4096 or more (levels up to m = 2^10 full).
    pub const LONG_SEGMENT: usize = 7;
    /// A sample with |z| ≥ 2^26 (a wide base ring: the routine must not run).
    pub const WIDE: usize = 8;
    /// Their names, for reports.
    pub const NAMES: [&str; super::edge::COUNT] = [
        "|z| = gate - 1",
        "gate raised",
        "gate < 2^11",
        "|z| >= 2^15",
        "|z| = 2^16 - 1",
        "i16 extremes",
        "square waves at |z| >= 2^14",
        "counts >= 4096",
        "|z| >= 2^26",
    ];
}

/// Edge counters ([`Report::edges`]), each the number of calls that hit that edge.
pub mod edge {
    /// A steady small sample with |z| = gate − 1 (the largest the Thumb routines take).
    pub const GATE_MINUS_ONE: usize = 0;
    /// A sample with |z| = gate (a new largest |z|: the gate grows by one).
    pub const AT_GATE: usize = 1;
    /// A steady sample with gate = 2^11 − 1 (the largest small gate).
    pub const GATE_BELOW_2_11: usize = 2;
    /// A steady sample with gate = 2^11 (the Rust path's wide squares, no Thumb code).
    pub const GATE_AT_2_11: usize = 3;
    /// A steady small sample with gate 2^10 − 1, 2^10 or 2^10 + 1 (the Thumb routines do level
    /// K0 themselves below 2^10 and hand it to `strided` from there).
    pub const GATE_AROUND_2_10: usize = 4;
    /// A sample of i32::MIN or i32::MAX.
    pub const I32_EXTREME: usize = 5;
    /// A steady small sample of a square wave at |z| ≥ 1000 (differences near 2^16 for the
    /// unit-stride levels and level K0).
    pub const SQUARE_WAVE: usize = 6;
    /// A pair that starts at an odd count (the pair routine declines; single samples follow).
    pub const ODD_PAIR: usize = 7;
    /// A steady sample at a count of 4096 or more (levels up to m = 2^10 full).
    pub const LONG_SEGMENT: usize = 8;
    /// Number of edge counters.
    pub const COUNT: usize = 9;
    /// Their names, for reports.
    pub const NAMES: [&str; COUNT] = [
        "|z| = gate - 1",
        "|z| = gate",
        "gate = 2^11 - 1",
        "gate = 2^11",
        "gate around 2^10",
        "i32 extremes",
        "square waves near 2^16",
        "pairs at odd counts",
        "counts >= 4096",
    ];
}

/// What a run found, laid out for a reader outside the program (the emulator test reads it from
/// RAM by its symbol): `u32`/`i32` words and one byte string, no padding.
#[derive(Clone, Debug, PartialEq, Eq)]
#[repr(C)]
pub struct Report {
    /// 0 before the run, [`RUNNING`] during it, [`DONE`] after it.
    pub state: u32,
    /// Calls compared.
    pub cases: u32,
    /// `push_pair` calls.
    pub pair_calls: u32,
    /// `push` calls.
    pub single_calls: u32,
    /// Pairs `pico_imu_allan_push_pair_small` took.
    pub pair_taken: u32,
    /// Samples `pico_imu_allan_push_small` took (single calls and declined pairs).
    pub single_taken: u32,
    /// Pairs the pair routine must take, predicted from the inputs.
    pub pair_predicted: u32,
    /// Samples the single routine must take, predicted from the inputs.
    pub single_predicted: u32,
    /// Calls after which the two engines' states differed.
    pub mismatches: u32,
    /// Index of the first such call (`u32::MAX`: none).
    pub first_case: u32,
    /// Its kind: [`ROUTINE_PAIR`] or [`ROUTINE_SINGLE`].
    pub first_routine: u32,
    /// Its samples (the second is 0 for `push`).
    pub first_y: [i32; 2],
    /// What the Thumb routines did in it: 1 = the pair routine took both, else 2 × the number
    /// of samples the single routine took.
    pub first_taken: u32,
    /// The segment count (samples since the last gap) before it.
    pub first_t: u32,
    /// The name of the first field that differed, NUL-padded.
    pub first_field: [u8; 16],
    /// Segments started (resets and gaps).
    pub segments: u32,
    /// Largest segment count reached.
    pub max_t: u32,
    /// Calls that hit each edge (see [`edge`]).
    pub edges: [u32; edge::COUNT],
    /// The source line of a panic, 0 if none.
    pub panic_line: u32,
}

impl Report {
    /// An empty report (nothing run yet).
    pub const fn new() -> Report {
        Report {
            state: 0,
            cases: 0,
            pair_calls: 0,
            single_calls: 0,
            pair_taken: 0,
            single_taken: 0,
            pair_predicted: 0,
            single_predicted: 0,
            mismatches: 0,
            first_case: u32::MAX,
            first_routine: 0,
            first_y: [0; 2],
            first_taken: 0,
            first_t: 0,
            first_field: [0; 16],
            segments: 0,
            max_t: 0,
            edges: [0; edge::COUNT],
            panic_line: 0,
        }
    }
}

impl Default for Report {
    fn default() -> Self {
        Self::new()
    }
}

/// What the engine's gate is, from the inputs alone: the segment's offset (its first sample,
/// clamped to ±2^30), its largest |z| = |y − offset| and its count. The engine's steady path
/// runs for |z| < gate, gate = amax + 1 once t ≥ 3P = 24 while the base ring is narrow
/// (amax < 2^26), else 0; the Thumb routines take it when also gate < 2^11.
#[derive(Clone, Copy, Default)]
struct Mirror {
    t: u64,
    offset: i32,
    amax: u32,
}

impl Mirror {
    fn gate(&self) -> u32 {
        if self.t >= 24 && self.amax < 1 << 26 {
            self.amax + 1
        } else {
            0
        }
    }

    /// |z| for a sample pushed now.
    fn z_abs(&self, y: i32) -> u32 {
        let offset = if self.t == 0 { clamp(y) } else { self.offset };
        (y as i64 - offset as i64).unsigned_abs() as u32
    }

    /// Whether `y` is a steady, small sample under the current gate (what the pair routine
    /// checks of both its samples).
    fn inside(&self, y: i32) -> bool {
        let gate = self.gate();
        gate != 0 && gate < 1 << 11 && self.z_abs(y) < gate
    }

    /// Whether the Thumb single routine must take `y` now: a steady, small sample, or a new
    /// largest |z| in the steady state that leaves the gate small (the engine raises the gate
    /// first).
    fn small(&self, y: i32) -> bool {
        let gate = self.gate();
        gate != 0 && self.z_abs(y).max(gate - 1) < (1 << 11) - 1
    }

    fn push(&mut self, y: i32) {
        if self.t == 0 {
            self.offset = clamp(y);
        }
        self.amax = self.amax.max(self.z_abs(y));
        self.t += 1;
    }

    fn gap(&mut self) {
        *self = Mirror {
            offset: self.offset,
            ..Mirror::default()
        };
    }
}

fn clamp(y: i32) -> i32 {
    y.clamp(-(1 << 30), 1 << 30)
}

/// The waveforms of an episode.
#[derive(Clone, Copy)]
enum Wave {
    /// Uniform in ±amp.
    Noise,
    /// ±amp, switching sign every `half` samples.
    Square { half: u32 },
    /// A random walk within ±amp.
    Walk { step: u32 },
    /// The gate's edges (gate − 1, gate, gate + 1) between noise within the current largest |z|.
    Edges,
    /// Raw values around the extremes of i32 and the offset clamp.
    Extremes,
}

/// One episode's sample source.
struct Source {
    base: i32,
    amp: u32,
    wave: Wave,
    k: u32,
    walk: i64,
    sign: i64,
}

impl Source {
    fn next(&mut self, rng: &mut Rng, mirror: &Mirror) -> i32 {
        let k = self.k;
        self.k += 1;
        let z = match self.wave {
            Wave::Noise => rng.within(self.amp),
            Wave::Square { half } => {
                if (k / half) & 1 == 0 {
                    self.sign * self.amp as i64
                } else {
                    -self.sign * self.amp as i64
                }
            }
            Wave::Walk { step } => {
                self.walk =
                    (self.walk + rng.within(step)).clamp(-(self.amp as i64), self.amp as i64);
                self.walk
            }
            Wave::Edges => {
                let gate = mirror.gate() as i64;
                let sign = if rng.coin() { 1 } else { -1 };
                // Mostly at or inside the gate; a step past it (which widens the gate) rarely,
                // so a long episode stays in the small range.
                match rng.below(32) {
                    0..=9 if gate > 0 => sign * (gate - 1),
                    10 if gate > 0 => sign * gate,
                    11 if gate > 0 => sign * (gate + 1),
                    _ => rng.within(mirror.amax.max(1)),
                }
            }
            Wave::Extremes => {
                return match rng.below(8) {
                    0 => i32::MIN,
                    1 => i32::MAX,
                    2 => (1 << 30) + rng.within(2) as i32,
                    3 => -(1 << 30) + rng.within(2) as i32,
                    _ => self.base.wrapping_add(rng.within(self.amp) as i32),
                }
            }
        };
        // z stays within ±(2^31 − 1) here, so it is exact; the sum wraps like the engine's
        // inputs may.
        self.base.wrapping_add(z as i32)
    }
}

/// A new segment's first value (its offset, clamped).
fn pick_base(rng: &mut Rng) -> i32 {
    match rng.below(16) {
        0 => i32::MIN,
        1 => i32::MAX,
        2 => 1 << 30,
        3 => -(1 << 30) - 1,
        4..=7 => rng.within(1 << 29) as i32,
        8..=11 => rng.within(5000) as i32,
        _ => 0,
    }
}

/// An episode's largest |z|: mostly in the Thumb routines' range, often at its edges, sometimes
/// beyond it (the Rust-only steady path, wide levels, the wide base ring).
fn pick_amp(rng: &mut Rng) -> u32 {
    const EDGES: [u32; 14] = [
        0, 1, 2, 1021, 1022, 1023, 1024, 1025, 2045, 2046, 2047, 2048, 4095, 4096,
    ];
    match rng.below(100) {
        0..=31 => 1 + rng.below(1023),
        32..=53 => 1023 + rng.below(1024),
        54..=85 => EDGES[rng.below(EDGES.len() as u32) as usize],
        86..=93 => 2048 + rng.below(1 << 16),
        _ => (1u32 << (12 + rng.below(19))).wrapping_add(rng.within(1) as u32),
    }
}

fn pick_wave(rng: &mut Rng, amp: u32) -> Wave {
    match rng.below(16) {
        0..=4 => Wave::Noise,
        5..=8 => Wave::Square {
            half: 1 << rng.below(8),
        },
        9..=10 => Wave::Walk {
            step: 1 + rng.below(amp.clamp(1, 1 << 20)),
        },
        11..=14 => Wave::Edges,
        _ => Wave::Extremes,
    }
}

/// Runs the differential test: `cases` calls from `seed`, results in `report`. The engines are
/// the caller's (on the device they live on the stack of `main`).
pub fn run(report: &mut Report, a: &mut DeviceEngine, b: &mut DeviceEngine, cases: u32, seed: u32) {
    *report = Report::new();
    report.state = RUNNING;
    a.reset();
    b.reset();
    let mut rng = Rng::new(seed);
    let mut mirror = Mirror::default();
    report.segments = 1;
    let mut episode = 0u32;
    while report.cases < cases {
        // A new segment (a gap, or a reset now and then) before some episodes, and almost
        // always once the segment has left the small range, so most calls can be steady.
        let spoiled = mirror.amax >= 2047;
        let roll = rng.below(16);
        if roll == 0 {
            a.reset();
            b.reset();
            mirror = Mirror::default();
            report.segments += 1;
        } else if roll <= 5 || (spoiled && roll < 14) {
            a.gap();
            b.gap();
            mirror.gap();
            report.segments += 1;
        }
        compare(report, a, b, None);
        let base = if mirror.t == 0 {
            pick_base(&mut rng)
        } else {
            mirror.offset
        };
        // Every 128th episode is long (levels up to m = 2^10 become full one after another) and
        // keeps to the small range; the short ones roam.
        let long = episode % 128 == 10;
        episode += 1;
        let (amp, wave) = loop {
            let amp = pick_amp(&mut rng);
            let wave = pick_wave(&mut rng, amp);
            if !long || (amp < 2047 && !matches!(wave, Wave::Extremes)) {
                break (amp, wave);
            }
        };
        let mut source = Source {
            base,
            amp,
            wave,
            k: 0,
            walk: 0,
            sign: if rng.coin() { 1 } else { -1 },
        };
        let len = if long {
            2200 + rng.below(800)
        } else {
            1 + rng.below(128)
        };
        // 0: single samples only, 1: mixed, else pairs only (the firmware's way).
        let mode = rng.below(4);
        for _ in 0..len {
            if report.cases >= cases {
                break;
            }
            let pair = match mode {
                0 => false,
                1 => rng.coin(),
                _ => true,
            };
            let t = mirror.t;
            if pair {
                let y0 = source.next(&mut rng, &mirror);
                let (inside0, small0) = (mirror.inside(y0), mirror.small(y0));
                note_edges(report, &mirror, y0, matches!(wave, Wave::Square { .. }));
                mirror.push(y0);
                let y1 = source.next(&mut rng, &mirror);
                let (inside1, small1) = (mirror.inside(y1), mirror.small(y1));
                note_edges(report, &mirror, y1, matches!(wave, Wave::Square { .. }));
                mirror.push(y1);
                let pair_small = inside0 && inside1 && t & 1 == 0;
                if inside0 && inside1 && t & 1 == 1 {
                    report.edges[edge::ODD_PAIR] += 1;
                }
                report.pair_predicted += pair_small as u32;
                if !pair_small {
                    report.single_predicted += small0 as u32;
                    // The second sample's gate is the one after the first sample.
                    report.single_predicted += small1 as u32;
                }
                let taken = a.push_pair_traced(y0, y1);
                b.push_pair_portable(y0, y1);
                report.pair_calls += 1;
                report.pair_taken += taken.pair as u32;
                report.single_taken += taken.singles as u32;
                let code = if taken.pair {
                    1
                } else {
                    2 * taken.singles as u32
                };
                compare(report, a, b, Some((ROUTINE_PAIR, [y0, y1], code, t)));
            } else {
                let y = source.next(&mut rng, &mirror);
                let small = mirror.small(y);
                note_edges(report, &mirror, y, matches!(wave, Wave::Square { .. }));
                mirror.push(y);
                report.single_predicted += small as u32;
                let taken = a.push_traced(y);
                b.push_portable(y);
                report.single_calls += 1;
                report.single_taken += taken as u32;
                compare(
                    report,
                    a,
                    b,
                    Some((ROUTINE_SINGLE, [y, 0], 2 * taken as u32, t)),
                );
            }
            report.cases += 1;
            report.max_t = report.max_t.max(mirror.t.min(u32::MAX as u64) as u32);
        }
    }
    report.state = DONE;
}

/// The magnetometer's engines (`MagEngine`, single samples, the firmware's way): two engines in
/// lock step as in [`run`], engine A through [`Engine::push`] (the Thumb routine
/// `pico_imu_allan_mag_push` for every steady sample, whatever its size), B through
/// [`Engine::push_portable`]. The inputs are the QMC5883L's: i16 counts around a random field,
/// noise and square waves up to the whole i16 span (|z| = 2^16 − 1: the widest unit-stride and
/// strided-level squares), i16 extremes, and now and then calibrated values beyond i16 (up to
/// |z| ≥ 2^26, where the routine must decline). Only `single_*` counts are used in `report`.
///
/// [`Engine::push`]: allan::Engine::push
/// [`Engine::push_portable`]: allan::Engine::push_portable
pub fn run_mag(report: &mut Report, a: &mut MagEngine, b: &mut MagEngine, cases: u32, seed: u32) {
    *report = Report::new();
    report.state = RUNNING;
    a.reset();
    b.reset();
    let mut rng = Rng::new(seed);
    let mut mirror = Mirror::default();
    report.segments = 1;
    let mut episode = 0u32;
    while report.cases < cases {
        if rng.below(3) == 0 || (mirror.amax >= 1 << 11 && rng.coin()) {
            a.gap();
            b.gap();
            mirror.gap();
            report.segments += 1;
        }
        compare(report, a, b, None);
        let base = if mirror.t == 0 {
            match rng.below(8) {
                0 => i16::MIN as i32,
                1 => i16::MAX as i32,
                _ => rng.within(1 << 15) as i32,
            }
        } else {
            mirror.offset
        };
        // Every 40th episode is long (a segment past 4096 samples).
        let long = episode % 40 == 5;
        episode += 1;

        let amp = match rng.below(8) {
            0..=2 => 1 + rng.below(2047),
            3..=4 => 2048 + rng.below(1 << 14),
            5..=6 => 1 << 16,
            _ if long => 1 << 16,
            _ => 1 << (20 + rng.below(10)),
        };
        let square = !long && rng.below(3) == 0;
        let half = 1 << rng.below(6);
        let sign = if rng.coin() { 1 } else { -1 };
        let len = if long {
            4200 + rng.below(400)
        } else {
            1 + rng.below(96)
        };
        for k in 0..len {
            if report.cases >= cases {
                break;
            }
            let v = if square {
                let v = if (k / half) & 1 == 0 { 1 } else { -1 };
                base as i64 + sign * v * amp as i64
            } else if amp > 1 << 16 {
                base as i64 + rng.within(amp)
            } else if amp == 1 << 16 && rng.below(16) == 0 {
                // An i16 extreme now and then: |z| up to 2^16 − 1.
                if rng.coin() {
                    i16::MIN as i64
                } else {
                    i16::MAX as i64
                }
            } else {
                base as i64 + rng.within(amp)
            };
            // Raw counts are i16; calibrated ones (`amp` > 2^16) may go beyond.
            let y = if amp > 1 << 16 {
                v.clamp(i32::MIN as i64, i32::MAX as i64) as i32
            } else {
                v.clamp(i16::MIN as i64, i16::MAX as i64) as i32
            };
            let t = mirror.t;
            let gate = mirror.gate();
            let z = mirror.z_abs(y);
            let taken_predicted = gate != 0 && z.max(gate - 1) < 1 << 26;
            let e = &mut report.edges;
            if taken_predicted {
                e[mag_edge::GATE_MINUS_ONE] += (z + 1 == gate) as u32;
                e[mag_edge::RAISED] += (z >= gate) as u32;
                e[mag_edge::GATE_BELOW_2_11] += (gate < 1 << 11) as u32;
                e[mag_edge::Z_FROM_2_15] += (z >= 1 << 15) as u32;
                e[mag_edge::Z_I16_SPAN] += (z == (1 << 16) - 1) as u32;
                e[mag_edge::SQUARE_WAVE] += (square && z >= 1 << 14) as u32;
                e[mag_edge::LONG_SEGMENT] += (t >= 4096) as u32;
            }
            e[mag_edge::I16_EXTREME] += (y == i16::MIN as i32 || y == i16::MAX as i32) as u32;
            e[mag_edge::WIDE] += (z >= 1 << 26) as u32;
            mirror.push(y);
            report.single_predicted += taken_predicted as u32;
            let taken = a.push_traced(y);
            b.push_portable(y);
            report.single_calls += 1;
            report.single_taken += taken as u32;
            compare(
                report,
                a,
                b,
                Some((ROUTINE_SINGLE, [y, 0], 2 * taken as u32, t)),
            );
            report.cases += 1;
            report.max_t = report.max_t.max(mirror.t.min(u32::MAX as u64) as u32);
        }
    }
    report.state = DONE;
}

/// Counts the edges sample `y` hits when pushed now.
fn note_edges(report: &mut Report, mirror: &Mirror, y: i32, square: bool) {
    let gate = mirror.gate();
    let small = mirror.small(y);
    let z = mirror.z_abs(y);
    let e = &mut report.edges;
    if gate != 0 {
        if z + 1 == gate && small {
            e[edge::GATE_MINUS_ONE] += 1;
        }
        if z == gate {
            e[edge::AT_GATE] += 1;
        }
        if z < gate {
            if gate == (1 << 11) - 1 {
                e[edge::GATE_BELOW_2_11] += 1;
            }
            if gate == 1 << 11 {
                e[edge::GATE_AT_2_11] += 1;
            }
        }
    }
    if small {
        if gate.abs_diff(1 << 10) <= 1 {
            e[edge::GATE_AROUND_2_10] += 1;
        }
        if square && z >= 1000 {
            e[edge::SQUARE_WAVE] += 1;
        }
        if mirror.t >= 4096 {
            e[edge::LONG_SEGMENT] += 1;
        }
    }
    if y == i32::MIN || y == i32::MAX {
        e[edge::I32_EXTREME] += 1;
    }
}

/// Compares the engines after call `case` (`None`: after a reset or gap); on a difference records
/// it (the first one in full) and sets A back to B's state.
fn compare<const P: usize, const L: usize, const R: usize, const S: usize>(
    report: &mut Report,
    a: &mut Engine<P, L, R, S>,
    b: &Engine<P, L, R, S>,
    call: Option<(u32, [i32; 2], u32, u64)>,
) {
    let Some(field) = a.first_difference(b) else {
        return;
    };
    report.mismatches += 1;
    if report.first_case == u32::MAX {
        report.first_case = report.cases;
        let (routine, y, taken, t) = call.unwrap_or((0, [0; 2], 0, 0));
        report.first_routine = routine;
        report.first_y = y;
        report.first_taken = taken;
        report.first_t = t.min(u32::MAX as u64) as u32;
        let n = field.len().min(report.first_field.len());
        report.first_field[..n].copy_from_slice(&field.as_bytes()[..n]);
    }
    a.clone_from(b);
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::boxed::Box;

    /// The host has no Thumb code: the run must find no difference, and the generator must
    /// offer the Thumb routines most of its calls and hit every edge.
    #[test]
    fn a_host_run_finds_no_difference_and_covers_the_edges() {
        let mut report = Box::new(Report::new());
        let (mut a, mut b) = (Box::new(DeviceEngine::new()), Box::new(DeviceEngine::new()));
        run(&mut report, &mut a, &mut b, CASES, SEED);
        std::println!("{report:?}");
        assert_eq!(report.state, DONE);
        assert_eq!(report.cases, CASES);
        assert_eq!(report.mismatches, 0);
        assert_eq!(
            report.pair_taken + report.single_taken,
            0,
            "no Thumb code on the host"
        );
        // What the emulator test asserts of the taken counts, here of the predicted ones.
        let steady = 2 * report.pair_predicted + report.single_predicted;
        let samples = 2 * report.pair_calls + report.single_calls;
        assert!(
            steady * 2 >= samples,
            "the Thumb routines would take only {steady} of {samples} samples"
        );
        assert!(report.pair_predicted >= 5000 && report.single_predicted >= 5000);
        for (i, &n) in report.edges.iter().enumerate() {
            assert!(n > 0, "edge `{}` never hit", edge::NAMES[i]);
        }
    }

    /// The same for the magnetometer run: no difference, most samples offered to the routine,
    /// every edge hit.
    #[test]
    fn a_host_mag_run_finds_no_difference_and_covers_the_edges() {
        let mut report = Box::new(Report::new());
        let (mut a, mut b) = (Box::new(MagEngine::new()), Box::new(MagEngine::new()));
        run_mag(&mut report, &mut a, &mut b, MAG_CASES, MAG_SEED);
        std::println!("{report:?}");
        assert_eq!(report.state, DONE);
        assert_eq!(report.cases, MAG_CASES);
        assert_eq!(report.mismatches, 0);
        assert_eq!(report.single_taken, 0, "no Thumb code on the host");
        assert!(
            report.single_predicted * 2 >= report.single_calls,
            "the Thumb routine would take only {} of {} samples",
            report.single_predicted,
            report.single_calls
        );
        for (i, &n) in report.edges.iter().enumerate() {
            assert!(n > 0, "edge `{}` never hit", mag_edge::NAMES[i]);
        }
    }
}
