//! The sensors' configuration and the contract-unit scales that go with it.
use imu_drivers::mpu6050::{self as mpu, FifoFrame};
use imu_drivers::qmc5883 as qmc;
use imu_proto::Scales;

/// MPU-6050: 1 kHz (DLPF 184 Hz, SMPLRT_DIV 0), ±4 g, ±250 deg/s (the ranges of I. Jaime et
/// al., "Caracterización y calibración de unidades de medición inercial de bajo costo", UTN
/// FRSF, which the calibration file defaults to), FIFO with temperature, no interrupt pin
/// (timer-driven).
pub fn imu_config() -> mpu::Config {
    mpu::Config {
        gyro_range: mpu::GyroRange::Dps250,
        accel_range: mpu::AccelRange::G4,
        dlpf: mpu::Dlpf::Hz184,
        sample_rate_divider: 0,
        fifo: Some(FifoFrame::AccelTempGyro),
        interrupt: mpu::InterruptConfig {
            data_ready: false,
            ..Default::default()
        },
    }
}

/// QMC5883L: continuous, 200 Hz, ±2 G, OSR 512 (the driver's defaults).
///
/// Pointer roll-over (`roll_over`, status and data in one 7-byte transfer) is left off: a read
/// whose status byte shows DRDY clear still reads the data bytes, and a sample that lands during
/// them is lost (its DRDY cleared by the discarded bytes); the status-then-data pair loses none.
pub fn mag_config() -> qmc::Config {
    qmc::Config::default()
}

/// The parts the firmware drives, whose datasheet bounds a calibration must have been checked
/// against (`imu_cal::device::plausible`): a blob fitted for others is refused.
pub const PARTS: (imu_cal::device::ImuPart, imu_cal::device::MagPart) = (
    imu_cal::device::ImuPart::Mpu6050,
    imu_cal::device::MagPart::Qmc5883l,
);

/// Contract-unit scales of the configured ranges (corrected counts keep the nominal LSB, see
/// `imu_cal::device`): m/s² = LSB·g₀/(LSB/g), deg/s = LSB/(LSB/(deg/s)), µT = LSB·100/(LSB/G).
pub fn scales() -> Scales {
    let s = imu_config().scale(mpu::ChipId::Mpu6050);
    Scales {
        accel: mpu::STANDARD_GRAVITY / s.accel_lsb_per_g,
        gyro: 1.0 / s.gyro_lsb_per_dps,
        mag: 100.0
            / mag_config()
                .range
                .lsb_per_gauss(qmc::Variant::L)
                .unwrap_or(12000.0),
        temp: 1.0 / s.temperature.lsb_per_c,
        temp_offset: s.temperature.offset_c,
    }
}
