//! The contract facts shared by the device, the host and the emulator harness: the channels,
//! their units, and how wire integers convert to those units.
use serde::{Deserialize, Serialize};

/// One characterised channel of the device.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Channel {
    Ax,
    Ay,
    Az,
    Gx,
    Gy,
    Gz,
    Mx,
    My,
    Mz,
    Temp,
}

impl Channel {
    /// All channels in wire order (the index used by [`Channel::index`]).
    pub const ALL: [Channel; 10] = [
        Channel::Ax,
        Channel::Ay,
        Channel::Az,
        Channel::Gx,
        Channel::Gy,
        Channel::Gz,
        Channel::Mx,
        Channel::My,
        Channel::Mz,
        Channel::Temp,
    ];

    /// Position in [`Channel::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// Column name in the CSV contract (`ax` … `mz`, `temp`).
    pub fn name(self) -> &'static str {
        ["ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp"][self as usize]
    }

    /// Contract unit of the channel after applying [`Scales`].
    pub fn unit(self) -> &'static str {
        match self {
            Channel::Ax | Channel::Ay | Channel::Az => "m/s²",
            Channel::Gx | Channel::Gy | Channel::Gz => "deg/s",
            Channel::Mx | Channel::My | Channel::Mz => "µT",
            Channel::Temp => "°C",
        }
    }
}

/// Conversion of wire integers to contract units: `value = lsb × scale` (and `+ temp_offset`
/// for temperature). Sent with every batch so a recording is self-describing.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Scales {
    /// m/s² per LSB.
    pub accel: f32,
    /// deg/s per LSB.
    pub gyro: f32,
    /// µT per LSB.
    pub mag: f32,
    /// °C per LSB.
    pub temp: f32,
    /// °C added after scaling the temperature.
    pub temp_offset: f32,
}

impl Scales {
    /// Scale of one channel (contract unit per LSB).
    pub fn of(&self, ch: Channel) -> f32 {
        match ch {
            Channel::Ax | Channel::Ay | Channel::Az => self.accel,
            Channel::Gx | Channel::Gy | Channel::Gz => self.gyro,
            Channel::Mx | Channel::My | Channel::Mz => self.mag,
            Channel::Temp => self.temp,
        }
    }
}
