//! The ten streaming Allan engines and their snapshots.
use allan::stream::{DeviceEngine, Frozen, LevelSums, MagEngine, DEVICE_PARAMS, MAG_PARAMS};
use imu_proto::{Channel, Sensor, MAX_LEVELS};

/// Channels with an Allan engine (ax ay az gx gy gz mx my mz temp).
pub const CHANNELS: usize = 10;

/// The IMU channels in the order of their engines.
pub const IMU_CHANNELS: [Channel; 7] = [
    Channel::Ax,
    Channel::Ay,
    Channel::Az,
    Channel::Gx,
    Channel::Gy,
    Channel::Gz,
    Channel::Temp,
];

/// The input of IMU channel `ch` among a sample's engine inputs (`None`: not an IMU channel, or
/// no temperature).
pub fn imu_input(ch: Channel, (accel, gyro, temp): &ImuInputs) -> Option<i32> {
    match ch {
        Channel::Ax => Some(accel[0]),
        Channel::Ay => Some(accel[1]),
        Channel::Az => Some(accel[2]),
        Channel::Gx => Some(gyro[0]),
        Channel::Gy => Some(gyro[1]),
        Channel::Gz => Some(gyro[2]),
        Channel::Temp => *temp,
        Channel::Mx | Channel::My | Channel::Mz => None,
    }
}

/// The seven IMU engines' inputs for one sample: corrected accel, gyro and the raw temperature
/// (`None`: the sample carried none; the temperature engine skips it).
pub type ImuInputs = ([i32; 3], [i32; 3], Option<i32>);

/// The engines: the seven 1 kHz channels (ax ay az gx gy gz temp, in that order) and the three
/// 200 Hz magnetometer channels, each sized for the same reach in seconds.
pub struct Engines {
    imu: [DeviceEngine; 7],
    mag: [MagEngine; 3],
    /// The last IMU sample of a burst that did not complete a pair: it waits for the first of
    /// the next burst, so the IMU engines take every sample in pairs (`push_pair`, two samples
    /// in one hand-scheduled Thumb call) and their counts stay even. Not yet pushed: a table's
    /// `pushed` leaves it out, and a split pushes it first (it came before the gap).
    imu_pending: Option<ImuInputs>,
}

/// Bytes of Allan state on the device: the ten engines (size_of on the target, checked against
/// the 32 KiB budget at compile time).
pub const ALLAN_STATE_BYTES: usize = core::mem::size_of::<Engines>();
const _: () = assert!(ALLAN_STATE_BYTES <= 32 * 1024, "Allan state over 32 KiB");

/// One channel's engine as it stood at a snapshot: its count, gaps and level sums, frozen (a
/// copy of a few words per level, taken between two samples); the levels are worked out when
/// the channel's table is sent ([`table_levels`]).
pub type ChannelSnapshot = Frozen<{ DEVICE_PARAMS[0] }, MAX_LEVELS>;
// Every engine freezes into the same type.
const _: () = assert!(DEVICE_PARAMS[0] == MAG_PARAMS[0]);
const _: () = assert!(DEVICE_PARAMS[1] <= MAX_LEVELS && MAG_PARAMS[1] <= MAX_LEVELS);

/// A snapshot's levels as a table lists them: level 0 up, ending at the first without second
/// differences (a level has differences only if every level below it has: each needs more
/// history than the one below).
pub fn table_levels(s: &ChannelSnapshot) -> impl Iterator<Item = LevelSums> + '_ {
    (0..s.levels_with_terms()).filter_map(|k| s.level(k))
}

/// Every channel at one instant.
pub struct Snapshot {
    pub channels: [ChannelSnapshot; CHANNELS],
}

impl Snapshot {
    pub const fn new() -> Self {
        Snapshot {
            channels: [ChannelSnapshot::EMPTY; CHANNELS],
        }
    }
}

impl Default for Snapshot {
    fn default() -> Self {
        Self::new()
    }
}

impl Default for Engines {
    fn default() -> Self {
        Self::new()
    }
}

impl Engines {
    pub fn new() -> Self {
        Engines {
            imu: core::array::from_fn(|_| DeviceEngine::new()),
            mag: core::array::from_fn(|_| MagEngine::new()),
            imu_pending: None,
        }
    }

    /// Push a burst of IMU samples, in pairs (see `imu_pending`). A sample without temperature
    /// splits the temperature engine's series there (and goes through the single-sample path).
    pub fn push_imu(&mut self, burst: &[ImuInputs]) {
        if burst.iter().any(|s| s.2.is_none()) {
            return self.push_imu_singly(burst);
        }
        let mut rest = burst;
        if let Some(first) = self.imu_pending.take() {
            match rest.split_first() {
                Some((second, tail)) => {
                    self.push_imu_pair(&first, second);
                    rest = tail;
                }
                None => {
                    self.imu_pending = Some(first);
                    return;
                }
            }
        }
        let mut pairs = rest.chunks_exact(2);
        for pair in &mut pairs {
            self.push_imu_pair(&pair[0], &pair[1]);
        }
        if let [last] = pairs.remainder() {
            self.imu_pending = Some(*last);
        }
    }

    /// The rare path: one sample at a time, the temperature engine split where it is missing.
    #[cold]
    fn push_imu_singly(&mut self, burst: &[ImuInputs]) {
        if let Some(first) = self.imu_pending.take() {
            self.push_imu_one(&first);
        }
        for s in burst {
            self.push_imu_one(s);
        }
    }

    fn push_imu_one(&mut self, (accel, gyro, temp): &ImuInputs) {
        let [ax, ay, az, gx, gy, gz, t] = &mut self.imu;
        ax.push(accel[0]);
        ay.push(accel[1]);
        az.push(accel[2]);
        gx.push(gyro[0]);
        gy.push(gyro[1]);
        gz.push(gyro[2]);
        match temp {
            Some(v) => t.push(*v),
            None => t.gap(),
        }
    }

    fn push_imu_pair(&mut self, (a0, g0, t0): &ImuInputs, (a1, g1, t1): &ImuInputs) {
        let [ax, ay, az, gx, gy, gz, t] = &mut self.imu;
        ax.push_pair(a0[0], a1[0]);
        ay.push_pair(a0[1], a1[1]);
        az.push_pair(a0[2], a1[2]);
        gx.push_pair(g0[0], g1[0]);
        gy.push_pair(g0[1], g1[1]);
        gz.push_pair(g0[2], g1[2]);
        // Both present: `push_imu` sends bursts with a missing temperature the single path.
        t.push_pair(t0.unwrap_or(0), t1.unwrap_or(0));
    }

    /// Push one magnetometer sample.
    #[inline]
    pub fn push_mag(&mut self, mag: &[i32; 3]) {
        for (e, &v) in self.mag.iter_mut().zip(mag) {
            e.push(v);
        }
    }

    /// Every channel's engine frozen now, into `snap` (one instant: the caller runs this between
    /// two samples).
    pub fn snapshot(&self, snap: &mut Snapshot) {
        for (ch, out) in Channel::ALL.iter().zip(snap.channels.iter_mut()) {
            match ch {
                Channel::Mx => self.mag[0].freeze(out),
                Channel::My => self.mag[1].freeze(out),
                Channel::Mz => self.mag[2].freeze(out),
                _ => {
                    let i = IMU_CHANNELS.iter().position(|c| c == ch).unwrap_or(0);
                    self.imu[i].freeze(out);
                }
            }
        }
    }

    /// Split a sensor's engines; returns the split position (samples pushed) when the split
    /// counted, i.e. when the segment it closed was not empty.
    pub fn split(&mut self, sensor: Sensor) -> Option<u64> {
        let (before, after, at) = match sensor {
            Sensor::Imu => {
                if let Some(last) = self.imu_pending.take() {
                    self.push_imu_one(&last);
                }
                let before = self.imu[0].gaps();
                self.imu.iter_mut().for_each(DeviceEngine::gap);
                (before, self.imu[0].gaps(), self.imu[0].samples())
            }
            Sensor::Mag => {
                let before = self.mag[0].gaps();
                self.mag.iter_mut().for_each(MagEngine::gap);
                (before, self.mag[0].gaps(), self.mag[0].samples())
            }
        };
        (after != before).then_some(at)
    }

    /// Samples pushed into each of `sensor`'s engines since the last reset.
    pub fn pushed(&self, sensor: Sensor) -> u64 {
        match sensor {
            Sensor::Imu => self.imu[0].samples(),
            Sensor::Mag => self.mag[0].samples(),
        }
    }

    /// Forget everything.
    pub fn reset(&mut self) {
        // A waiting sample was taken before the reset: forgotten with the rest.
        self.imu_pending = None;
        self.imu.iter_mut().for_each(DeviceEngine::reset);
        self.mag.iter_mut().for_each(MagEngine::reset);
    }
}
