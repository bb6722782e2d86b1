//! What the bare-metal differential tests share (`crates/allan/thumb-check`,
//! `crates/imu-proto/thumb-check`): the generator their cases are drawn from, the words their
//! report's `state` takes, and the breakpoints that end a run on the emulated RP2040
//! (sim/test/thumb-diff.test.js and sim/test/frame-thumb.test.js read the report by its symbol
//! once the emulator stops on one). Its build script puts the RP2040's memory map (memory.x)
//! on their link search path.
#![no_std]

/// A report's `state` while the run goes on.
pub const RUNNING: u32 = 0x5255_4e21;
/// A report's `state` once the run is complete.
pub const DONE: u32 = 0x444f_4e45;

/// xorshift32 (Marsaglia, "Xorshift RNGs", J. Stat. Softw. 8(14), 2003; shifts 13, 17, 5).
pub struct Rng(u32);

impl Rng {
    /// The generator from `seed` (made odd: a zero state would stay zero).
    pub const fn new(seed: u32) -> Self {
        Rng(seed | 1)
    }

    pub fn next_u32(&mut self) -> u32 {
        let mut s = self.0;
        s ^= s << 13;
        s ^= s >> 17;
        s ^= s << 5;
        self.0 = s;
        s
    }

    /// Uniform in 0..n (n ≥ 1).
    pub fn below(&mut self, n: u32) -> u32 {
        ((u64::from(self.next_u32()) * u64::from(n)) >> 32) as u32
    }

    /// Uniform in −a..=a.
    pub fn within(&mut self, a: u32) -> i64 {
        let a = i64::from(a);
        i64::from(self.below((2 * a + 1).min(i64::from(u32::MAX)) as u32)) - a
    }

    pub fn coin(&mut self) -> bool {
        self.next_u32() & 0x8000_0000 != 0
    }
}

/// Stop the run as complete: `bkpt #1`, which the emulator ends the run on (the asm block is a
/// compiler barrier, so the report is in RAM by then).
#[cfg(all(target_arch = "arm", target_os = "none"))]
pub fn done() -> ! {
    loop {
        // SAFETY: a breakpoint; the emulator ends the run on it.
        unsafe { core::arch::asm!("bkpt #1") };
    }
}

/// Stop the run as panicked: `bkpt #2`.
#[cfg(all(target_arch = "arm", target_os = "none"))]
pub fn panicked() -> ! {
    loop {
        // SAFETY: a breakpoint; the emulator ends the run on it.
        unsafe { core::arch::asm!("bkpt #2") };
    }
}

#[cfg(test)]
mod tests {
    use super::Rng;

    /// The generator's first outputs from seed 1 are Marsaglia's xorshift32 (13, 17, 5), and
    /// `below` and `within` stay in their ranges and reach both ends.
    #[test]
    fn the_generator_is_xorshift32_and_its_ranges_hold() {
        let mut r = Rng::new(1);
        assert_eq!(
            [r.next_u32(), r.next_u32(), r.next_u32()],
            [270_369, 67_634_689, 2_647_435_461]
        );
        let mut r = Rng::new(0x5eed);
        let (mut lo, mut hi) = (false, false);
        for _ in 0..10_000 {
            let b = r.below(7);
            assert!(b < 7);
            let w = r.within(3);
            assert!((-3..=3).contains(&w));
            lo |= w == -3;
            hi |= w == 3;
        }
        assert!(lo && hi, "within(3) never reached an end");
    }
}
