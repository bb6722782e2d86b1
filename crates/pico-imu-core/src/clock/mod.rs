//! Sample clocks: where a sensor's samples fall on the RP2040's time base. The one owner of
//! timestamps: every sample time the firmware reports comes from [`SampleClock::stamps`].
//!
//! A sensor samples on its own oscillator (the MPU-6050's is specified only to a few percent),
//! so sample `k` of a run happened at `t_k = t₀ + k·T` with `T` the part's true period. The
//! firmware cannot see `t_k`; it sees, at instants `τ` it knows to a microsecond (when a bus
//! transfer latched a register, [`BusTiming`]), how many samples the part had produced: a FIFO
//! count, or a data-ready bit. Each such observation says on which side of `τ` one or two
//! sample instants lie. The clock keeps a line `t̂_k = t̂_a + (k − a)·T̂` and the interval of
//! prediction errors `(lo, hi]` that every observation so far allows:
//!
//! * an observation "sample `n` was produced by `τ`" gives `e ≤ τ − t̂_n`, and "sample `n + 1`
//!   was not" gives `e > τ − t̂_{n+1}`; the interval is intersected with them;
//! * each observation's bounds are loosened by the latch jitter ([`JITTER`]); between
//!   observations the interval widens by what the period's uncertainty allows over the samples in
//!   between, so the line may drift;
//! * the line is moved to the middle of the interval after every observation;
//! * a reader that chooses *when* to observe places the latch in the middle of the interval
//!   ([`SampleClock::probe_after`]): each such probe halves it (bisection), so the phase is
//!   known to a few µs after a handful of probes;
//! * reads placed after the late end find the sample whether the line is right or late, so a
//!   reader that places them there looks before the early end now and then
//!   ([`SampleClock::poll_offset`], a guard): only that shows a line running late (a period
//!   wrong beyond its bound), and the period is then measured again
//!   ([`SampleClock::distrust_period`]);
//! * `T̂` starts at the nominal period; the number of samples counted between two observations
//!   far apart corrects it to `T/Δn` (coarse), and once the interval is narrow, two located
//!   sample instants far apart give `T̂ = Δt/Δk` to a fraction of a nanosecond.
//!
//! An observation that contradicts the interval (a restarted part, a wrong assumption about
//! when its first sample comes) replaces it by what the observation alone allows.
//!
//! The stamp of a sample is `t̂_k` at the time it is reported; the remaining error is the
//! interval's half-width plus a constant: the difference between the modelled latch instant
//! (start of the transfer + the bit times before the latched byte) and the instant the part
//! really latches it, which docs/firmware.md reports as measured in the emulator.
//!
//! Times are µs × 2^16 ([`Fine`]), on the RP2040's µs timer; no floating point, and a
//! division only when the period is re-estimated (a few times per run).
//!
//! One file per concept: `fine` the unit of time ([`Fine`]); `arithmetic` the integer products
//! and quotients shaped for the M0+; `bus_timing` where in a transfer a byte is latched
//! ([`BusTiming`]); `observation` what an observation says ([`Seen`]) and how it fitted
//! ([`Fit`]); `sample_clock` the clock itself ([`SampleClock`]); `stamps` what it issues
//! ([`Stamps`]).

mod arithmetic;
mod bus_timing;
mod fine;
mod observation;
mod sample_clock;
mod stamps;

pub(crate) use arithmetic::mul;
pub use bus_timing::{read_bits, BusTiming, READ_FIRST_BIT, READ_SECOND_BIT, WRITE_DATA_BIT};
pub use fine::{fine, whole_us, Fine, FINE_BITS, US};
pub use observation::{Fit, Seen};
pub use sample_clock::{SampleClock, GUARD_EVERY, GUARD_MARGIN, JITTER, LOCKED_WIDTH, PROBE_WIDTH};
pub use stamps::Stamps;
