//! Register addresses (RM section 3, "Register Map"): the part's one register table.

/// SELF_TEST_X..Z, SELF_TEST_A: factory trim codes (RM 4.1).
pub const SELF_TEST_X: u8 = 0x0D;
/// MPU-6500 family: SELF_TEST_X/Y/Z_GYRO factory codes (RM-6500 registers 0-2).
pub const SELF_TEST_X_GYRO_6500: u8 = 0x00;
/// MPU-6500 family: SELF_TEST_X/Y/Z_ACCEL factory codes (RM-6500 registers 13-15).
pub const SELF_TEST_X_ACCEL_6500: u8 = 0x0D;
/// Sample-rate divider (RM 4.2).
pub const SMPLRT_DIV: u8 = 0x19;
/// EXT_SYNC_SET and DLPF_CFG (RM 4.3).
pub const CONFIG: u8 = 0x1A;
/// Gyro self-test bits and FS_SEL (RM 4.4).
pub const GYRO_CONFIG: u8 = 0x1B;
/// Accel self-test bits and AFS_SEL (RM 4.5).
pub const ACCEL_CONFIG: u8 = 0x1C;
/// MPU-6500 family only: accelerometer DLPF (RM-6500 register 29, ACCEL_CONFIG 2). Reserved on the MPU-6050.
pub const ACCEL_CONFIG2: u8 = 0x1D;
/// Which sensor outputs are written to the FIFO (RM 4.6).
pub const FIFO_EN: u8 = 0x23;
/// INT pin / bypass configuration (RM 4.14).
pub const INT_PIN_CFG: u8 = 0x37;
/// Interrupt enables (RM 4.15).
pub const INT_ENABLE: u8 = 0x38;
/// Interrupt status, cleared on read (RM 4.16).
pub const INT_STATUS: u8 = 0x3A;
/// First of the 14 measurement bytes: accel X/Y/Z, temperature, gyro X/Y/Z, big-endian (RM 4.17-4.19).
pub const ACCEL_XOUT_H: u8 = 0x3B;
/// Signal path reset (RM 4.26).
pub const SIGNAL_PATH_RESET: u8 = 0x68;
/// FIFO enable/reset (RM 4.27).
pub const USER_CTRL: u8 = 0x6A;
/// Device reset, sleep, clock source (RM 4.28).
pub const PWR_MGMT_1: u8 = 0x6B;
/// FIFO byte count, high byte first (RM 4.30).
pub const FIFO_COUNT_H: u8 = 0x72;
/// FIFO count, low byte (RM 4.30).
pub const FIFO_COUNT_L: u8 = 0x73;
/// FIFO read port; burst reads keep popping this register (RM 4.31).
pub const FIFO_R_W: u8 = 0x74;
/// Chip identity (RM 4.32).
pub const WHO_AM_I: u8 = 0x75;
/// Temperature, high byte (RM 4.18; the driver reads it within the burst from ACCEL_XOUT_H).
pub const TEMP_OUT_H: u8 = 0x41;
/// Gyro X, high byte (RM 4.19; likewise within the burst).
pub const GYRO_XOUT_H: u8 = 0x43;
/// Power management 2: standby of single axes (RM 4.29; the driver leaves it at 0).
pub const PWR_MGMT_2: u8 = 0x6C;

/// Every register above by name: the one register table of the part. The chip models
/// (tests/src/mpu6050_model.rs, sim/src/devices/mpu6050.js) are checked against it.
pub const TABLE: &[(&str, u8)] = &[
    ("SELF_TEST_X", SELF_TEST_X),
    ("SMPLRT_DIV", SMPLRT_DIV),
    ("CONFIG", CONFIG),
    ("GYRO_CONFIG", GYRO_CONFIG),
    ("ACCEL_CONFIG", ACCEL_CONFIG),
    ("ACCEL_CONFIG2", ACCEL_CONFIG2),
    ("FIFO_EN", FIFO_EN),
    ("INT_PIN_CFG", INT_PIN_CFG),
    ("INT_ENABLE", INT_ENABLE),
    ("INT_STATUS", INT_STATUS),
    ("ACCEL_XOUT_H", ACCEL_XOUT_H),
    ("TEMP_OUT_H", TEMP_OUT_H),
    ("GYRO_XOUT_H", GYRO_XOUT_H),
    ("SIGNAL_PATH_RESET", SIGNAL_PATH_RESET),
    ("USER_CTRL", USER_CTRL),
    ("PWR_MGMT_1", PWR_MGMT_1),
    ("PWR_MGMT_2", PWR_MGMT_2),
    ("FIFO_COUNT_H", FIFO_COUNT_H),
    ("FIFO_COUNT_L", FIFO_COUNT_L),
    ("FIFO_R_W", FIFO_R_W),
    ("WHO_AM_I", WHO_AM_I),
];
