//! The `imu-drivers` crate used *blocking* on rp2040-hal 0.12 (the second HAL of the design
//! card; the firmware uses the same drivers async on embassy-rp).
//!
//! Wiring as the firmware (docs/firmware.md): I2C0, SDA = GP4, SCL = GP5, 400 kHz, MPU-6050 at
//! 0x68 and QMC5883L (0x0D) or QMC5883P (0x2C) on the same bus.
//!
//! 1. Clears a stuck bus (9 SCL pulses + STOP, `imu_drivers::recovery`) with GP4/GP5 as
//!    open-drain GPIOs, then hands them to the I2C0 peripheral.
//! 2. Configures the MPU-6050 with the configuration of Jaime et al. (±250 °/s, ±4 g, DLPF 5 Hz, 1 kHz,
//!    FIFO accel + gyro) and runs the factory self-test (MPU-6050 and MPU-6500 family).
//! 3. Detects the magnetometer and configures it (±2 G, 200 Hz, OSR 512, continuous).
//! 4. Every 10 ms drains the FIFO and polls the magnetometer; every second prints over
//!    defmt-rtt the sample counts and the mean accel (m/s²), gyro (°/s), temperature (°C)
//!    and field (µT).
#![no_std]
#![no_main]

use core::cell::RefCell;

use defmt::{error, info, warn, Display2Format};
use defmt_rtt as _;
use embedded_hal::delay::DelayNs;
use embedded_hal_bus::i2c::RefCellDevice;
use imu_drivers::blocking::{Mpu6050, Qmc5883};
use imu_drivers::mpu6050::{self, Address, RawSample};
use imu_drivers::qmc5883::{self, Chip, Variant};
use imu_drivers::recovery::recover_bus;
use panic_probe as _;
use rp2040_hal::fugit::RateExtU32;
use rp2040_hal::gpio::{FunctionI2C, InOutPin, Pin, PullUp};
use rp2040_hal::{self as hal, pac, Clock};

/// Second-stage bootloader for the Pico W's W25Q16JV flash (W25Q080-compatible), placed at
/// 0x10000000 by boot2.x.
#[link_section = ".boot2"]
#[used]
pub static BOOT2: [u8; 256] = rp2040_boot2::BOOT_LOADER_W25Q080;

/// Pico W crystal, Hz.
const XTAL_FREQ_HZ: u32 = 12_000_000;
/// Poll period, ms: 10 frames of 12 bytes per poll at 1 kHz, far below the 1024-byte FIFO.
const POLL_MS: u32 = 10;
/// Report every this many polls (1 s).
const REPORT_EVERY: u32 = 100;

#[hal::entry]
fn main() -> ! {
    let Some(mut pac) = pac::Peripherals::take() else {
        panic!("peripherals taken twice");
    };
    let mut watchdog = hal::Watchdog::new(pac.WATCHDOG);
    let Ok(clocks) = hal::clocks::init_clocks_and_plls(
        XTAL_FREQ_HZ,
        pac.XOSC,
        pac.CLOCKS,
        pac.PLL_SYS,
        pac.PLL_USB,
        &mut pac.RESETS,
        &mut watchdog,
    ) else {
        panic!("clock initialisation failed");
    };
    let mut timer = hal::Timer::new(pac.TIMER, &mut pac.RESETS, &clocks);
    let sio = hal::Sio::new(pac.SIO);
    let pins = hal::gpio::Pins::new(
        pac.IO_BANK0,
        pac.PADS_BANK0,
        sio.gpio_bank0,
        &mut pac.RESETS,
    );

    // 1. Bus recovery on GP5 (SCL) / GP4 (SDA) as open-drain GPIOs with pull-ups.
    let mut scl = InOutPin::new(pins.gpio5.into_pull_up_input());
    let mut sda = InOutPin::new(pins.gpio4.into_pull_up_input());
    match recover_bus(&mut scl, &mut sda, &mut timer, 5) {
        Ok(r) if r.sda_released => info!("I2C bus free after {=u8} recovery pulses", r.pulses),
        Ok(_) => error!("SDA still held low after 9 pulses: power-cycle the sensors"),
        Err(_) => error!("bus recovery: pin error"),
    }
    let scl: Pin<_, FunctionI2C, PullUp> = scl.release().reconfigure();
    let sda: Pin<_, FunctionI2C, PullUp> = sda.release().reconfigure();
    let i2c = hal::I2C::i2c0(
        pac.I2C0,
        sda,
        scl,
        400.kHz(),
        &mut pac.RESETS,
        clocks.system_clock.freq(),
    );
    let bus = RefCell::new(i2c);

    // 2. MPU-6050.
    let mut imu = Mpu6050::new(RefCellDevice::new(&bus), Address::Ad0Low);
    let imu_cfg = mpu6050::Config::default();
    let imu_ok = match imu.init(&mut timer, &imu_cfg) {
        Ok(chip) => {
            info!(
                "IMU: {} (WHO_AM_I 0x{=u8:02X}), {=f32} Hz",
                chip,
                chip.who_am_i(),
                imu_cfg.sample_rate_hz()
            );
            match imu.self_test(&mut timer) {
                Ok(r) => info!(
                    "self-test {}: gyro {} % (window {} %), accel {} % (window {} %) from factory trim",
                    if r.passed() { "passed" } else { "FAILED" },
                    r.gyro_change_pct,
                    r.gyro_limits_pct,
                    r.accel_change_pct,
                    r.accel_limits_pct
                ),
                Err(mpu6050::Error::SelfTestUnsupported) => {
                    info!("self-test: not available on this chip")
                }
                Err(e) => warn!("self-test: {}", Display2Format(&e)),
            }
            // The self-test left samples in the FIFO taken with self-test excitation.
            if let Err(e) = imu.reset_fifo() {
                warn!("FIFO reset: {}", Display2Format(&e));
            }
            true
        }
        Err(e) => {
            error!("IMU init: {}", Display2Format(&e));
            false
        }
    };

    // 3. Magnetometer.
    let chip = {
        let mut dev = RefCellDevice::new(&bus);
        Qmc5883::detect(&mut dev)
    };
    let variant = match chip {
        Chip::Qmc5883L => Some(Variant::L),
        Chip::Qmc5883P => Some(Variant::P),
        Chip::Hmc5883L => {
            warn!("HMC5883L found: not driven by imu-drivers");
            None
        }
        Chip::None => {
            warn!("no magnetometer answered at 0x0D, 0x2C or 0x1E");
            None
        }
    };
    let mut mag = variant.map(|v| Qmc5883::new_variant(RefCellDevice::new(&bus), v));
    if let Some(m) = mag.as_mut() {
        match m.init(&mut timer, &qmc5883::Config::default()) {
            Ok(()) => info!("magnetometer: {}", chip),
            Err(e) => {
                error!("magnetometer init: {}", Display2Format(&e));
                mag = None;
            }
        }
    }

    // 4. Stream.
    let scale = imu.scale();
    let mut frames = [RawSample::default(); 16];
    let mut polls = 0u32;
    let (mut n_imu, mut n_mag, mut overflows) = (0u32, 0u32, 0u32);
    let (mut sum_a, mut sum_g, mut sum_m) = ([0i64; 3], [0i64; 3], [0i64; 3]);
    let mut last_temp = None;
    loop {
        timer.delay_ms(POLL_MS);
        if imu_ok {
            loop {
                match imu.read_fifo(&mut frames) {
                    Ok(n) => {
                        for f in &frames[..n] {
                            for i in 0..3 {
                                sum_a[i] += i64::from(f.accel[i]);
                                sum_g[i] += i64::from(f.gyro[i]);
                            }
                        }
                        n_imu += n as u32;
                        if n < frames.len() {
                            break;
                        }
                    }
                    Err(mpu6050::Error::FifoOverflow) => {
                        overflows += 1;
                        if let Err(e) = imu.reset_fifo() {
                            warn!("FIFO reset: {}", Display2Format(&e));
                        }
                        break;
                    }
                    Err(e) => {
                        warn!("IMU read: {}", Display2Format(&e));
                        break;
                    }
                }
            }
        }
        if let Some(m) = mag.as_mut() {
            match m.read() {
                Ok(s) => {
                    for (acc, v) in sum_m.iter_mut().zip(s.xyz) {
                        *acc += i64::from(v);
                    }
                    n_mag += 1;
                    if s.overflow {
                        warn!("magnetometer overflow (field beyond ±2 G)");
                    }
                }
                Err(qmc5883::Error::NotReady) => {}
                Err(e) => warn!("magnetometer read: {}", Display2Format(&e)),
            }
        }
        polls += 1;
        if polls.is_multiple_of(REPORT_EVERY) {
            if imu_ok {
                if let Ok(s) = imu.read_all() {
                    last_temp = s.temp.map(|t| scale.temperature_c(t));
                }
            }
            let mean =
                |s: [i64; 3], n: u32| s.map(|v| if n == 0 { 0 } else { (v / n as i64) as i16 });
            let a = scale.accel_ms2(mean(sum_a, n_imu));
            let g = scale.gyro_dps(mean(sum_g, n_imu));
            let b = mag
                .as_ref()
                .map(|m| qmc5883::to_microtesla(mean(sum_m, n_mag), m.lsb_per_gauss()));
            info!(
                "1 s: {=u32} IMU frames, {=u32} mag samples, {=u32} FIFO overflows | accel {} m/s², gyro {} °/s, temp {} °C, field {} µT",
                n_imu, n_mag, overflows, a, g, last_temp, b
            );
            (n_imu, n_mag, overflows) = (0, 0, 0);
            (sum_a, sum_g, sum_m) = ([0; 3], [0; 3], [0; 3]);
        }
    }
}
