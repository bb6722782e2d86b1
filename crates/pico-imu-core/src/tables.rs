//! The table scheduler: a round takes one snapshot of every engine (one instant) and sends the
//! ten tables from it one at a time, spaced out so that no 100 ms of CPU carries more than one
//! table's encoding, and none carries the snapshot and a table both.
//!
//! The device sends only the engines' exact integer sums; the deviation, its EDF and its bounds
//! are the host's (`allan::ci`), which recomputes them from the sums anyway: on the M0+ each
//! row's soft-float square roots cost ≈ 0.3 ms.
use imu_proto::{AllanTable, Channel, Scales, Sensor, Vec};

use crate::engines::{table_levels, Engines, Snapshot, CHANNELS};
use crate::outbox::{FrameSink, Outbox, Sent};

/// Least time between a round's snapshot and its first table frame, and between two table
/// frames, µs.
pub const TABLE_SPACING_US: u64 = 100_000;

/// Queue room a table frame needs (a full table with worst-case varints is < 2 KiB).
pub const TABLE_FRAME_ROOM: usize = 2048;

/// The table rounds.
pub struct Tables {
    snapshot: Snapshot,
    /// Round number of the snapshot (0: none yet).
    round: u32,
    t_us: u64,
    /// The sensors' periods at the snapshot, ns.
    period_ns: [u32; 2],
    /// Next channel of the round to send.
    next: Option<usize>,
    /// When the last table frame went out, µs.
    last_sent_us: Option<u64>,
}

impl Default for Tables {
    fn default() -> Self {
        Self::new()
    }
}

impl Tables {
    pub const fn new() -> Self {
        Tables {
            snapshot: Snapshot::new(),
            round: 0,
            t_us: 0,
            period_ns: [0; 2],
            next: None,
            last_sent_us: None,
        }
    }

    /// Take a snapshot of every engine now and start sending its tables (a round in progress is
    /// abandoned). `period_ns`: the IMU's and magnetometer's sample periods (τ0). Returns the
    /// round number.
    pub fn start(&mut self, engines: &Engines, t_us: u64, period_ns: [u32; 2]) -> u32 {
        engines.snapshot(&mut self.snapshot);
        self.round = self.round.wrapping_add(1).max(1);
        self.t_us = t_us;
        self.period_ns = period_ns;
        self.next = Some(0);
        self.last_sent_us = Some(t_us);
        self.round
    }

    /// Stop the round in progress (its remaining tables are not sent).
    pub fn abandon(&mut self) {
        self.next = None;
    }

    /// Whether a round is in progress.
    pub fn pending(&self) -> bool {
        self.next.is_some()
    }

    /// The table of channel index `c` of the current snapshot.
    pub fn table(&self, c: usize, scales: &Scales) -> AllanTable {
        let ch = Channel::ALL[c];
        let s = &self.snapshot.channels[c];
        let mut levels = Vec::new();
        for l in table_levels(s) {
            // At most MAX_LEVELS: never full.
            let _ = levels.push(l);
        }
        AllanTable {
            channel: ch,
            snapshot: self.round,
            t_us: self.t_us,
            tau0_ns: match ch.sensor() {
                Sensor::Imu => self.period_ns[0],
                Sensor::Mag => self.period_ns[1],
            },
            scale: scales.of(ch),
            pushed: s.samples(),
            gaps: s.gaps(),
            levels,
        }
    }

    /// Send the round's next table if it is time ([`TABLE_SPACING_US`] after the previous one)
    /// and the queue has room for it (tables wait for room rather than being dropped). Returns
    /// the channel sent.
    pub fn step(
        &mut self,
        now_us: u64,
        scales: &Scales,
        outbox: &mut Outbox,
        sink: &mut impl FrameSink,
    ) -> Option<Channel> {
        let c = self.next?;
        if self
            .last_sent_us
            .is_some_and(|t| now_us.saturating_sub(t) < TABLE_SPACING_US)
            || sink.room() < TABLE_FRAME_ROOM
        {
            return None;
        }
        let t = self.table(c, scales);
        if matches!(outbox.send_table(&t, sink), Sent::Dropped) {
            return None;
        }
        self.last_sent_us = Some(now_us);
        self.next = (c + 1 < CHANNELS).then_some(c + 1);
        Some(t.channel)
    }
}
