//! What an observation of a part's sample count says ([`Seen`]), and how it fitted the clock's
//! interval ([`Fit`]).

/// What a reader saw at an observation's latch instant τ about the samples around it: always
/// that the newest sample counted had been produced by τ; with a count that also shows the
/// next one missing (a FIFO count, a data-ready bit found clear), that τ lies before it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Seen {
    /// Sample `newest` had been produced by τ; nothing is said about the next (a data-ready
    /// bit found set).
    Produced,
    /// Sample `newest` had been produced and `newest + 1` had not. A next sample later than
    /// the interval allows only bounds it: the part may have stopped producing.
    NextNotYet,
    /// As [`Seen::NextNotYet`], and the reader has seen the part go on producing since, so a
    /// next sample later than the interval allows by at most a period is a phase to correct.
    NextNotYetTrusted,
}

impl Seen {
    /// Whether the observation says sample `newest + 1` had not been produced by τ.
    #[inline]
    pub const fn next_not_yet(self) -> bool {
        !matches!(self, Seen::Produced)
    }

    /// Whether a late next sample is to be taken for a phase error.
    #[inline]
    pub const fn trust_late(self) -> bool {
        matches!(self, Seen::NextNotYetTrusted)
    }
}

/// How an observation fitted the clock's interval.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fit {
    /// Within it (it narrowed the interval).
    Fits,
    /// A sample came earlier than the interval allows: the phase was wrong, the interval
    /// replaced.
    Early,
    /// A sample came later than the interval allows (replaced only if trusted).
    Late,
}
