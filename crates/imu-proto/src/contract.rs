//! The contract facts shared by the device, the host and the emulator harness: the sensors and
//! their nominal rates, the channels and their units, and how wire integers convert to those
//! units. The emulator harness (Node) reads the same facts from `sim/src/contract.json`, which
//! [`contract_json`] writes and a test keeps equal to it.
use serde::{Deserialize, Serialize};

/// IMU output data rate, Hz (MPU-6050: 1 kHz gyro rate with the DLPF on, SMPLRT_DIV = 0).
pub const IMU_RATE_HZ: u32 = 1000;
/// IMU nominal sample period, µs.
pub const IMU_PERIOD_US: u64 = 1_000_000 / IMU_RATE_HZ as u64;
/// Magnetometer output data rate, Hz (QMC5883L ODR = 200 Hz).
pub const MAG_RATE_HZ: u32 = 200;
/// Magnetometer nominal sample period, µs.
pub const MAG_PERIOD_US: u64 = 1_000_000 / MAG_RATE_HZ as u64;

/// Which sensor (and which of its sample grids) something is about.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Sensor {
    /// The MPU-6050: accelerometer, gyroscope, die temperature.
    Imu,
    /// The QMC5883L magnetometer.
    Mag,
}

impl Sensor {
    /// Nominal output rate, Hz.
    pub const fn rate_hz(self) -> u32 {
        match self {
            Sensor::Imu => IMU_RATE_HZ,
            Sensor::Mag => MAG_RATE_HZ,
        }
    }

    /// Nominal sample period, µs.
    pub const fn period_us(self) -> u64 {
        match self {
            Sensor::Imu => IMU_PERIOD_US,
            Sensor::Mag => MAG_PERIOD_US,
        }
    }
}

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

    /// The channels in the order of the CSV contract's columns after `t`
    /// (`t,ax,ay,az,gx,gy,gz,mx,my,mz,temp`).
    pub const CSV: [Channel; 10] = Channel::ALL;

    /// Position in [`Channel::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// Column name in the CSV contract (`ax` … `mz`, `temp`).
    pub fn name(self) -> &'static str {
        ["ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp"][self as usize]
    }

    /// The sensor that samples the channel.
    pub const fn sensor(self) -> Sensor {
        match self {
            Channel::Mx | Channel::My | Channel::Mz => Sensor::Mag,
            _ => Sensor::Imu,
        }
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

/// The contract facts as JSON, for the emulator harness (`sim/src/contract.json`): the CSV
/// columns in order with their units, and each sensor's nominal rate and period.
pub fn contract_json() -> heapless::String<1024> {
    use core::fmt::Write;
    let mut s = heapless::String::new();
    let _ = write!(
        s,
        "{{\n  \"columns\": [\n    {{ \"name\": \"t\", \"unit\": \"s\" }}"
    );
    for c in Channel::CSV {
        let _ = write!(
            s,
            ",\n    {{ \"name\": \"{}\", \"unit\": \"{}\", \"sensor\": \"{}\" }}",
            c.name(),
            c.unit(),
            match c.sensor() {
                Sensor::Imu => "imu",
                Sensor::Mag => "mag",
            }
        );
    }
    let _ = write!(s, "\n  ],\n  \"sensors\": {{");
    for (i, (name, sensor)) in [("imu", Sensor::Imu), ("mag", Sensor::Mag)]
        .iter()
        .enumerate()
    {
        let _ = write!(
            s,
            "{}\n    \"{name}\": {{ \"rate_hz\": {}, \"period_us\": {} }}",
            if i == 0 { "" } else { "," },
            sensor.rate_hz(),
            sensor.period_us()
        );
    }
    let _ = write!(s, "\n  }}\n}}\n");
    s
}
