//! The table scheduler: a round takes one snapshot of every engine (one instant) and sends the
//! ten tables from it, each encoded and framed a few levels at a time, in steps spaced out so
//! that no 100 ms of CPU carries more than one step, and none carries the snapshot and a step
//! both. A table's frame is built in its own buffer ([`FrameBuilder`]), so the sample batches
//! framed between its steps do not disturb it, and is queued whole when its last level is in.
//!
//! The device sends only the engines' exact integer sums; the deviation, its EDF and its bounds
//! are the host's (`allan::confidence`), which recomputes them from the sums anyway: on the M0+ each
//! row's soft-float square roots cost ≈ 0.3 ms.
use imu_proto::{table, AllanTable, Channel, FrameBuilder, Scales, Sensor, Vec};

use crate::engines::{table_levels, Engines, Snapshot, CHANNELS};
use crate::outbox::{FrameSink, Outbox, Sent, FRAME_ALIGN};

/// Least time between a round's snapshot and its first table step, and between two steps, µs.
pub const TABLE_SPACING_US: u64 = 100_000;

/// Levels encoded and framed per step (the first step also writes the table's head): a step
/// costs about a third of a whole table of a long run (24 levels take six steps).
pub const LEVELS_PER_STEP: usize = 4;

/// Queue room a table frame needs (a full table with worst-case varints, padded, is < 2 KiB).
pub const TABLE_FRAME_ROOM: usize = 2048;
const _: () = assert!(
    1 + table::HEAD_MAX + imu_proto::MAX_LEVELS * table::LEVEL_MAX + 4 + 2 * 1024 / 254 + 8
        <= TABLE_FRAME_ROOM
);

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
    /// Levels of that channel's table already in `frame`, and how many it has (`None`: its
    /// frame is not started).
    progress: Option<(u8, u8)>,
    /// When the last step ran (or the round's snapshot was taken), µs.
    last_step_us: Option<u64>,
    /// The frame of the table being sent.
    frame: FrameBuilder<TABLE_FRAME_ROOM>,
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
            progress: None,
            last_step_us: None,
            frame: FrameBuilder::new(),
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
        self.progress = None;
        self.last_step_us = Some(t_us);
        self.round
    }

    /// Stop the round in progress (its remaining tables are not sent).
    pub fn abandon(&mut self) {
        self.next = None;
        self.progress = None;
    }

    /// Whether a round is in progress.
    pub fn pending(&self) -> bool {
        self.next.is_some()
    }

    /// The table of channel index `c` of the current snapshot.
    pub fn table(&self, c: usize, scales: &Scales) -> AllanTable {
        let mut t = self.head(c, scales);
        for l in table_levels(&self.snapshot.channels[c]) {
            // At most MAX_LEVELS: never full.
            let _ = t.levels.push(l);
        }
        t
    }

    /// The table of channel index `c` without its levels.
    fn head(&self, c: usize, scales: &Scales) -> AllanTable {
        let ch = Channel::ALL[c];
        let s = &self.snapshot.channels[c];
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
            levels: Vec::new(),
        }
    }

    /// Run the round's next step if it is time ([`TABLE_SPACING_US`] after the previous one):
    /// the next [`LEVELS_PER_STEP`] levels of the current table into its frame (its head
    /// first), and once all are in, the frame queued if there is room for it (tables wait for
    /// room rather than being dropped). Returns the channel whose table was queued.
    pub fn step(
        &mut self,
        now_us: u64,
        scales: &Scales,
        outbox: &mut Outbox,
        sink: &mut impl FrameSink,
    ) -> Option<Channel> {
        let c = self.next?;
        if self
            .last_step_us
            .is_some_and(|t| now_us.saturating_sub(t) < TABLE_SPACING_US)
        {
            return None;
        }
        let s = &self.snapshot.channels[c];
        let (mut done, total) = match self.progress {
            Some(p) => p,
            None => {
                let total = s.levels_with_terms();
                let mut head = [0; table::HEAD_MAX];
                let n = table::write_head(&self.head(c, scales), total, &mut head).unwrap_or(0);
                self.frame.start();
                self.frame.push(&head[..n]);
                (0, total as u8)
            }
        };
        if done < total {
            self.last_step_us = Some(now_us);
            let to = total.min(done.saturating_add(LEVELS_PER_STEP as u8));
            let mut bytes = [0; table::LEVEL_MAX];
            for k in done..to {
                if let Some(l) = s.level(k.into()) {
                    let n = table::write_level(&l, &mut bytes).unwrap_or(0);
                    self.frame.push(&bytes[..n]);
                }
            }
            done = to;
        }
        self.progress = Some((done, total));
        // Once every level is in, the frame is queued when there is room (checked first, so
        // that the frame is finished only once).
        if done < total || sink.room() < TABLE_FRAME_ROOM {
            return None;
        }
        self.last_step_us = Some(now_us);
        self.progress = None;
        self.next = (c + 1 < CHANNELS).then_some(c + 1);
        match outbox.queue_built(self.frame.finish(FRAME_ALIGN), sink) {
            Sent::Queued(_) => Some(Channel::ALL[c]),
            // Too large for its buffer (a firmware bug, counted): the table is skipped.
            _ => None,
        }
    }
}
