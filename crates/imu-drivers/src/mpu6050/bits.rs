//! Register bit fields.

/// PWR_MGMT_1.DEVICE_RESET (RM 4.28): resets all registers, self-clearing.
pub const DEVICE_RESET: u8 = 1 << 7;
/// PWR_MGMT_1.SLEEP (RM 4.28).
pub const SLEEP: u8 = 1 << 6;
/// PWR_MGMT_1.CLKSEL = 1: PLL with X-axis gyroscope reference (RM 4.28, table).
pub const CLKSEL_PLL_GYRO_X: u8 = 0x01;
/// USER_CTRL.FIFO_EN (RM 4.27).
pub const USER_FIFO_EN: u8 = 1 << 6;
/// USER_CTRL.FIFO_RESET (RM 4.27): only acts while FIFO_EN = 0; self-clearing.
pub const USER_FIFO_RESET: u8 = 1 << 2;
/// FIFO_EN.TEMP_FIFO_EN (RM 4.6).
pub const FIFO_TEMP: u8 = 1 << 7;
/// FIFO_EN.XG/YG/ZG_FIFO_EN (RM 4.6).
pub const FIFO_GYRO_XYZ: u8 = (1 << 6) | (1 << 5) | (1 << 4);
/// FIFO_EN.ACCEL_FIFO_EN (RM 4.6).
pub const FIFO_ACCEL: u8 = 1 << 3;
/// INT_ENABLE.FIFO_OFLOW_EN and INT_STATUS.FIFO_OFLOW_INT (RM 4.15, 4.16).
pub const INT_FIFO_OFLOW: u8 = 1 << 4;
/// INT_ENABLE.DATA_RDY_EN and INT_STATUS.DATA_RDY_INT (RM 4.15, 4.16).
pub const INT_DATA_RDY: u8 = 1 << 0;
/// INT_PIN_CFG.INT_LEVEL: 1 = active low (RM 4.14).
pub const INT_LEVEL_LOW: u8 = 1 << 7;
/// INT_PIN_CFG.INT_OPEN: 1 = open drain (RM 4.14).
pub const INT_OPEN_DRAIN: u8 = 1 << 6;
/// INT_PIN_CFG.LATCH_INT_EN: 1 = held until cleared (RM 4.14).
pub const LATCH_INT_EN: u8 = 1 << 5;
/// INT_PIN_CFG.INT_RD_CLEAR: 1 = any read clears the status (RM 4.14).
pub const INT_RD_CLEAR: u8 = 1 << 4;
/// GYRO_CONFIG XG_ST|YG_ST|ZG_ST and ACCEL_CONFIG XA_ST|YA_ST|ZA_ST (RM 4.4, 4.5).
pub const SELF_TEST_XYZ: u8 = 0xE0;
