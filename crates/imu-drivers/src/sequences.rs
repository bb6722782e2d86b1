//! Every bus sequence of both drivers (identify, configure, start, read, FIFO, self-test),
//! written once and expanded twice: blocking (`embedded_hal::i2c::I2c`,
//! `embedded_hal::delay::DelayNs`) and async (`embedded_hal_async::i2c::I2c`,
//! `embedded_hal_async::delay::DelayNs`). The only difference between the two expansions is
//! the `async` keyword on each method and `.await` after each bus or delay call; every
//! register value, sequence and decoding step comes from [`crate::mpu6050`] and
//! [`crate::qmc5883`].

macro_rules! drivers {
    ($($async:ident)?; $($await:ident)?; $I2c:path; $Delay:path) => {
        use embedded_hal::i2c::{ErrorType, Operation};

        use crate::mpu6050::{
            self as m, registers as mb, reg as mr, Address, ChipId, Config, Family, IntStatus,
            RawSample, Scale, SelfTestReport,
        };
        use crate::qmc5883::{self as q, registers as qr, Chip, MagSample, Status, Variant};
        use crate::register::Register;

        /// Error type of [`Mpu6050`] on bus `I2C`.
        pub type MpuError<I2C> = m::Error<<I2C as ErrorType>::Error>;
        /// Error type of [`Qmc5883`] on bus `I2C`.
        pub type MagError<I2C> = q::Error<<I2C as ErrorType>::Error>;

        /// Frames moved per FIFO burst read: 16 × 14 bytes = 224 bytes of scratch in the driver.
        const FIFO_CHUNK_FRAMES: usize = 16;

        /// MPU-6050 (and register-compatible clones) driver.
        ///
        /// `new` does no I/O; `init` checks WHO_AM_I, resets and configures the chip.
        #[derive(Debug)]
        pub struct Mpu6050<I2C> {
            i2c: I2C,
            address: u8,
            chip: Option<ChipId>,
            config: Config,
            /// FIFO burst scratch, kept here so that a read does not zero it every time.
            fifo_buf: [u8; FIFO_CHUNK_FRAMES * 14],
        }

        impl<I2C: $I2c> Mpu6050<I2C> {
            /// Wrap a bus; no I/O.
            pub fn new(i2c: I2C, address: Address) -> Self {
                Mpu6050 {
                    i2c,
                    address: address.addr(),
                    chip: None,
                    config: Config::default(),
                    fifo_buf: [0; FIFO_CHUNK_FRAMES * 14],
                }
            }

            /// Give the bus back.
            pub fn release(self) -> I2C {
                self.i2c
            }

            /// The bus, e.g. to ask it when its last transfer started.
            pub fn bus(&self) -> &I2C {
                &self.i2c
            }

            /// Chip identified by the last `init`/`probe`.
            pub fn chip(&self) -> Option<ChipId> {
                self.chip
            }

            /// Configuration applied by the last `init`.
            pub fn config(&self) -> &Config {
                &self.config
            }

            /// Conversion factors for the applied configuration and the chip found (MPU-6050
            /// temperature formula before `init`).
            pub fn scale(&self) -> Scale {
                self.config.scale(self.chip.unwrap_or(ChipId::Mpu6050))
            }

            $($async)? fn read_regs(&mut self, reg: u8, buf: &mut [u8]) -> Result<(), MpuError<I2C>> {
                self.i2c.write_read(self.address, &[reg], buf) $(.$await)? ?;
                Ok(())
            }

            /// Write one register: `bytes` from [`Register::write_bytes`], taken before the call so
            /// that an async write holds two bytes, not the register's fields.
            $($async)? fn write_register(&mut self, bytes: [u8; 2]) -> Result<(), MpuError<I2C>> {
                self.i2c.write(self.address, &bytes) $(.$await)? ?;
                Ok(())
            }

            $($async)? fn read_register<R: Register>(&mut self) -> Result<R, MpuError<I2C>> {
                let mut b = [0u8; 1];
                self.read_regs(R::ADDR, &mut b) $(.$await)? ?;
                Ok(R::from_bits(b[0]))
            }

            /// Read WHO_AM_I (0x75).
            pub $($async)? fn who_am_i(&mut self) -> Result<u8, MpuError<I2C>> {
                let mut b = [0u8; 1];
                self.read_regs(mr::WHO_AM_I, &mut b) $(.$await)? ?;
                Ok(b[0])
            }

            /// Check WHO_AM_I against the MPU-6050 and its known clones.
            pub $($async)? fn probe(&mut self) -> Result<ChipId, MpuError<I2C>> {
                let found = self.who_am_i() $(.$await)? ?;
                let chip = ChipId::from_who_am_i(found).ok_or(m::Error::WrongChip { found })?;
                self.chip = Some(chip);
                Ok(chip)
            }

            /// Identify, reset and configure the chip, then start sampling ([`Self::prepare`],
            /// then [`Self::start`]).
            pub $($async)? fn init<D: $Delay>(
                &mut self,
                delay: &mut D,
                config: &Config,
            ) -> Result<ChipId, MpuError<I2C>> {
                let chip = self.prepare(delay, config) $(.$await)? ?;
                self.start() $(.$await)? ?;
                Ok(chip)
            }

            /// Identify, reset and configure the chip, leaving it asleep (sequence and values:
            /// docs/drivers.md): 1. WHO_AM_I check; 2. PWR_MGMT_1 = DEVICE_RESET, wait 100 ms
            /// (the part is then asleep, RM 4.28); 3. one burst SMPLRT_DIV, CONFIG, GYRO_CONFIG,
            /// ACCEL_CONFIG (+ ACCEL_CONFIG2 on 6500-family clones); 4. INT_PIN_CFG,
            /// INT_ENABLE; 5. FIFO: USER_CTRL = FIFO_RESET, FIFO_EN = frame mask,
            /// USER_CTRL = FIFO_EN (or FIFO_EN = 0 and USER_CTRL = 0 when the FIFO is off).
            /// Nothing is sampled until [`Self::start`], so a caller can choose when the part's
            /// sample clock starts, and every sample from the first goes into the FIFO.
            pub $($async)? fn prepare<D: $Delay>(
                &mut self,
                delay: &mut D,
                config: &Config,
            ) -> Result<ChipId, MpuError<I2C>> {
                let chip = self.probe() $(.$await)? ?;
                self.write_register(mb::PwrMgmt1::RESET.write_bytes()) $(.$await)? ?;
                delay.delay_ms(m::RESET_DELAY_MS) $(.$await)?;
                let (burst, len) = config.config_burst(chip);
                self.i2c.write(self.address, &burst[..len]) $(.$await)? ?;
                self.write_register(config.interrupt.pin_cfg().write_bytes()) $(.$await)? ?;
                self.write_register(config.int_enable().write_bytes()) $(.$await)? ?;
                self.config = *config;
                match config.fifo {
                    Some(frame) => {
                        self.write_register(mb::UserCtrl::FIFO_EMPTIED.write_bytes()) $(.$await)? ?;
                        self.write_register(frame.fifo_en().write_bytes()) $(.$await)? ?;
                        self.write_register(mb::UserCtrl::FIFO_ON.write_bytes()) $(.$await)? ?;
                    }
                    None => {
                        self.write_register(mb::FifoEn::default().write_bytes()) $(.$await)? ?;
                        self.write_register(mb::UserCtrl::default().write_bytes()) $(.$await)? ?;
                    }
                }
                Ok(chip)
            }

            /// Wake the chip: PWR_MGMT_1 = 0x01 (awake, PLL with gyro X reference). Its sample
            /// clock starts with this write; the first sample follows one sample period later.
            pub $($async)? fn start(&mut self) -> Result<(), MpuError<I2C>> {
                self.write_register(mb::PwrMgmt1::RUNNING.write_bytes()) $(.$await)?
            }

            /// Whether the chip still holds what [`Self::init`] configured (read back:
            /// SMPLRT_DIV..ACCEL_CONFIG, FIFO_EN, USER_CTRL and PWR_MGMT_1). A part that lost
            /// power, or was reset, reads back its defaults (asleep) and needs a new `init`;
            /// one that only stopped answering for a while does not.
            pub $($async)? fn config_intact(&mut self) -> Result<bool, MpuError<I2C>> {
                let chip = self.chip.ok_or(m::Error::NotConfigured)?;
                let (burst, _) = self.config.config_burst(chip);
                let mut b = [0u8; 4];
                self.read_regs(mr::SMPLRT_DIV, &mut b) $(.$await)? ?;
                let fifo_en: mb::FifoEn = self.read_register() $(.$await)? ?;
                // USER_CTRL and PWR_MGMT_1 are adjacent: one read.
                let mut ctrl = [0u8; 2];
                self.read_regs(mb::UserCtrl::ADDR, &mut ctrl) $(.$await)? ?;
                let (user, power) = (mb::UserCtrl::from_bits(ctrl[0]), mb::PwrMgmt1::from_bits(ctrl[1]));
                let want_fifo = self.config.fifo.map(|f| f.fifo_en()).unwrap_or_default();
                Ok(b == [burst[1], burst[2], burst[3], burst[4]]
                    && fifo_en == want_fifo
                    && user.fifo_en == self.config.fifo.is_some()
                    && power == mb::PwrMgmt1::RUNNING)
            }

            /// One 14-byte burst from ACCEL_XOUT_H: accel, temperature and gyro of the same
            /// sampling instant (RM 4.17-4.19; the chip latches the set for a burst read).
            pub $($async)? fn read_all(&mut self) -> Result<RawSample, MpuError<I2C>> {
                let mut b = [0u8; 14];
                self.read_regs(mr::ACCEL_XOUT_H, &mut b) $(.$await)? ?;
                Ok(m::decode_measurements(&b))
            }

            /// Read (and thereby clear, RM 4.16) INT_STATUS.
            pub $($async)? fn int_status(&mut self) -> Result<IntStatus, MpuError<I2C>> {
                self.read_register() $(.$await)?
            }

            /// `read_all` if DATA_RDY_INT is set, else [`m::Error::NotReady`].
            pub $($async)? fn read_if_ready(&mut self) -> Result<RawSample, MpuError<I2C>> {
                if !self.int_status() $(.$await)? ?.data_ready {
                    return Err(m::Error::NotReady);
                }
                self.read_all() $(.$await)?
            }

            /// Bytes waiting in the FIFO (FIFO_COUNT_H/L read in one burst, RM 4.30).
            pub $($async)? fn fifo_count(&mut self) -> Result<u16, MpuError<I2C>> {
                let mut b = [0u8; 2];
                self.read_regs(mr::FIFO_COUNT_H, &mut b) $(.$await)? ?;
                Ok(m::decode_fifo_count(b))
            }

            /// Read whole FIFO frames into `out`; returns how many were written. Never reads
            /// a partial frame: the remainder stays in the FIFO for the next call.
            ///
            /// Returns [`m::Error::FifoOverflow`] if the count reached the FIFO capacity (the
            /// chip then overwrites the oldest bytes and frame alignment is lost); call
            /// [`Self::reset_fifo`] to recover. Two transfers per call: the count, then the
            /// frames (in chunks of at most `FIFO_CHUNK_FRAMES`): [`Self::fifo_count`] and
            /// [`Self::read_fifo_counted`].
            /// [`m::Error::NotConfigured`] if `init` did not enable the FIFO.
            pub $($async)? fn read_fifo(&mut self, out: &mut [RawSample]) -> Result<usize, MpuError<I2C>> {
                if self.config.fifo.is_none() || self.chip.is_none() {
                    return Err(m::Error::NotConfigured);
                }
                let count = self.fifo_count() $(.$await)? ?;
                self.read_fifo_counted(count, out) $(.$await)?
            }

            /// FIFO capacity of the chip found by `init`, bytes (`None` before it).
            pub fn fifo_capacity(&self) -> Option<u16> {
                self.chip.map(ChipId::fifo_capacity)
            }

            /// [`Self::read_fifo`] given a count just read with [`Self::fifo_count`]: a caller
            /// that knows how long ago that was can tell whether the FIFO may have overflowed
            /// since (the count cannot show an overflow after it), and reset it instead.
            pub $($async)? fn read_fifo_counted(&mut self, count: u16, out: &mut [RawSample]) -> Result<usize, MpuError<I2C>> {
                let mut slots = out.iter_mut();
                let max = slots.len();
                self.read_fifo_counted_with(count, max, |s| {
                    if let Some(slot) = slots.next() {
                        *slot = s;
                    }
                }) $(.$await)?
            }

            /// [`Self::read_fifo_counted`] handing each decoded frame to `put`, in FIFO order, at
            /// most `max` of them (a caller filling a buffer in place need not initialise it
            /// first). Returns how many were handed over.
            pub $($async)? fn read_fifo_counted_with(&mut self, count: u16, max: usize, mut put: impl FnMut(RawSample)) -> Result<usize, MpuError<I2C>> {
                let frame = self.config.fifo.ok_or(m::Error::NotConfigured)?;
                let chip = self.chip.ok_or(m::Error::NotConfigured)?;
                // Overflow is read from the count, not from INT_STATUS (one transfer fewer per
                // call): only reads lower the count, and a full FIFO keeps its count at the
                // FIFO size while new data overwrites the oldest (RM 4.16, 4.30), so a count
                // below the size means no byte was lost since the previous read. A full count
                // is treated as an overflow even if the last frame fitted exactly.
                if count >= chip.fifo_capacity() {
                    return Err(m::Error::FifoOverflow);
                }
                // min(count / frame size, max) by subtraction: the Cortex-M0+ has no divide
                // instruction, and `max` is a few frames.
                let fb = frame.bytes();
                let (mut wanted, mut left) = (0, count as usize);
                while wanted < max && left >= fb {
                    left -= fb;
                    wanted += 1;
                }
                let mut done = 0;
                while done < wanted {
                    let n = (wanted - done).min(FIFO_CHUNK_FRAMES);
                    // The driver's own scratch: not zeroed on every call.
                    let bytes = &mut self.fifo_buf[..n * fb];
                    self.i2c.write_read(self.address, &[mr::FIFO_R_W], bytes) $(.$await)? ?;
                    for chunk in bytes.chunks_exact(fb) {
                        if let Some(s) = m::decode_fifo_frame(chunk, frame) {
                            put(s);
                        }
                    }
                    done += n;
                }
                Ok(done)
            }

            /// [`Self::read_fifo_counted`] without decoding: as many whole frames as `count`
            /// holds and `out` has room for, read straight into `out` (FIFO order, big-endian
            /// as the part sends them, in the configured layout: [`Self::fifo_frame`]), so a
            /// caller can decode each frame where its values are used. Returns how many frames.
            pub $($async)? fn read_fifo_counted_raw(&mut self, count: u16, out: &mut [u8]) -> Result<usize, MpuError<I2C>> {
                let frame = self.config.fifo.ok_or(m::Error::NotConfigured)?;
                let chip = self.chip.ok_or(m::Error::NotConfigured)?;
                // Overflow from the count, as in `read_fifo_counted_with`.
                if count >= chip.fifo_capacity() {
                    return Err(m::Error::FifoOverflow);
                }
                // min(count / frame size, room) by subtraction (no divide on the Cortex-M0+).
                let fb = frame.bytes();
                let (mut wanted, mut left, mut room) = (0, count as usize, out.len());
                while left >= fb && room >= fb {
                    left -= fb;
                    room -= fb;
                    wanted += 1;
                }
                let mut done = 0;
                while done < wanted {
                    let n = (wanted - done).min(FIFO_CHUNK_FRAMES);
                    let bytes = &mut out[done * fb..(done + n) * fb];
                    self.i2c.write_read(self.address, &[mr::FIFO_R_W], bytes) $(.$await)? ?;
                    done += n;
                }
                Ok(done)
            }

            /// The FIFO count and `frames` whole frames in one transfer where
            /// [`Self::fifo_count`] and [`Self::read_fifo_counted_raw`] take two: FIFO_COUNT_H/L,
            /// then after a repeated START the frames from FIFO_R_W, raw into `out` (as
            /// [`Self::read_fifo_counted_raw`]). `frames` is cut to what `out` holds and to a
            /// chunk of 16. `head` receives the count's bytes; a bus that moves both reads with
            /// one DMA run wants `head` directly before `out` in memory.
            ///
            /// The frames are read whatever the count says: ask only for frames known to have
            /// landed before the transfer starts (a sample clock's prediction). Beyond the count
            /// they come from an empty FIFO, or in part from a sample landing meanwhile, which
            /// leaves the FIFO misaligned: when [`m::CountedFrames::whole`] is false, restart
            /// the FIFO. [`m::Error::FifoOverflow`] for a full count (the frames are then not
            /// aligned either).
            pub $($async)? fn read_counted_fifo_raw(&mut self, frames: usize, head: &mut [u8; 2], out: &mut [u8]) -> Result<m::CountedFrames, MpuError<I2C>> {
                let frame = self.config.fifo.ok_or(m::Error::NotConfigured)?;
                let chip = self.chip.ok_or(m::Error::NotConfigured)?;
                let fb = frame.bytes();
                let mut read = frames.min(FIFO_CHUNK_FRAMES);
                if read * fb > out.len() {
                    // What `out` holds, by subtraction (no divide on the Cortex-M0+).
                    let (mut fit, mut room) = (0, out.len());
                    while room >= fb {
                        room -= fb;
                        fit += 1;
                    }
                    read = fit;
                }
                if read == 0 {
                    let count = self.fifo_count() $(.$await)? ?;
                    return Ok(m::CountedFrames { count, read: 0, covered: 0 });
                }
                let mut ops = [
                    Operation::Write(&[mr::FIFO_COUNT_H]),
                    Operation::Read(&mut head[..]),
                    Operation::Write(&[mr::FIFO_R_W]),
                    Operation::Read(&mut out[..read * fb]),
                ];
                self.i2c.transaction(self.address, &mut ops) $(.$await)? ?;
                let count = m::decode_fifo_count(*head);
                if count >= chip.fifo_capacity() {
                    return Err(m::Error::FifoOverflow);
                }
                // min(count / frame size, read): all of them as a rule; else by subtraction.
                let mut covered = read;
                if (count as usize) < read * fb {
                    let mut left = count as usize;
                    covered = 0;
                    while left >= fb {
                        left -= fb;
                        covered += 1;
                    }
                }
                Ok(m::CountedFrames { count, read, covered })
            }

            /// The FIFO frame layout configured (`None` before `init`).
            pub fn fifo_frame(&self) -> Option<m::FifoFrame> {
                self.config.fifo
            }

            /// Empty the FIFO and clear a pending overflow: [`Self::stop_fifo`],
            /// [`Self::start_fifo`], then read INT_STATUS.
            pub $($async)? fn reset_fifo(&mut self) -> Result<(), MpuError<I2C>> {
                self.stop_fifo() $(.$await)? ?;
                self.start_fifo() $(.$await)? ?;
                self.int_status() $(.$await)? ?;
                Ok(())
            }

            /// Empty the FIFO and stop filling it: USER_CTRL = FIFO_RESET with FIFO_EN = 0 (RM
            /// 4.27 resets only then). Samples taken until [`Self::start_fifo`] are not kept.
            pub $($async)? fn stop_fifo(&mut self) -> Result<(), MpuError<I2C>> {
                if self.config.fifo.is_none() {
                    return Err(m::Error::NotConfigured);
                }
                self.write_register(mb::UserCtrl::FIFO_EMPTIED.write_bytes()) $(.$await)?
            }

            /// Fill the FIFO again (USER_CTRL = FIFO_EN): the first frame in it is the first
            /// sample taken after this write.
            pub $($async)? fn start_fifo(&mut self) -> Result<(), MpuError<I2C>> {
                if self.config.fifo.is_none() {
                    return Err(m::Error::NotConfigured);
                }
                self.write_register(mb::UserCtrl::FIFO_ON.write_bytes()) $(.$await)?
            }

            $($async)? fn average<D: $Delay>(&mut self, delay: &mut D) -> Result<([f32; 3], [f32; 3]), MpuError<I2C>> {
                let mut a = [0i32; 3];
                let mut g = [0i32; 3];
                for _ in 0..m::SELF_TEST_SAMPLES {
                    let s = self.read_all() $(.$await)? ?;
                    for i in 0..3 {
                        a[i] += s.accel[i] as i32;
                        g[i] += s.gyro[i] as i32;
                    }
                    delay.delay_ms(2) $(.$await)?;
                }
                let n = m::SELF_TEST_SAMPLES as f32;
                Ok((a.map(|v| v as f32 / n), g.map(|v| v as f32 / n)))
            }

            /// Factory self-test. MPU-6050 (RM 4.1, PS 6.1/6.2): outputs averaged with
            /// self-test on and off at ±250 °/s and ±8 g, compared with the factory trim from
            /// SELF_TEST_X..A. MPU-6500 family (AN-MPU-6500A-02): at ±250 °/s and ±2 g, compared
            /// with the OTP codes in registers 0x00-0x02 and 0x0D-0x0F. The ICM parts return
            /// [`m::Error::SelfTestUnsupported`]. The configured ranges are restored
            /// afterwards; the FIFO then holds self-test frames (call `reset_fifo`). About 0.6 s.
            pub $($async)? fn self_test<D: $Delay>(&mut self, delay: &mut D) -> Result<SelfTestReport, MpuError<I2C>> {
                let chip = self.chip.ok_or(m::Error::NotConfigured)?;
                let a_range = match chip.family() {
                    Family::Mpu6050 => m::AccelRange::G8,
                    Family::Mpu6500 => m::AccelRange::G2,
                    Family::Icm => return Err(m::Error::SelfTestUnsupported),
                };
                let g = m::GyroRange::Dps250;
                self.write_register(mb::GyroConfig::self_test(g).write_bytes()) $(.$await)? ?;
                self.write_register(mb::AccelConfig::self_test(a_range).write_bytes()) $(.$await)? ?;
                delay.delay_ms(m::SELF_TEST_SETTLE_MS) $(.$await)?;
                let (on_a, on_g) = self.average(delay) $(.$await)? ?;
                self.write_register(mb::GyroConfig::range(g).write_bytes()) $(.$await)? ?;
                self.write_register(mb::AccelConfig::range(a_range).write_bytes()) $(.$await)? ?;
                delay.delay_ms(m::SELF_TEST_SETTLE_MS) $(.$await)?;
                let (off_a, off_g) = self.average(delay) $(.$await)? ?;
                let report = if chip.family() == Family::Mpu6050 {
                    let mut trim = [0u8; 4];
                    self.read_regs(mr::SELF_TEST_X, &mut trim) $(.$await)? ?;
                    m::self_test_report(on_a, on_g, off_a, off_g, trim)
                } else {
                    let mut gc = [0u8; 3];
                    let mut ac = [0u8; 3];
                    self.read_regs(mr::SELF_TEST_X_GYRO_6500, &mut gc) $(.$await)? ?;
                    self.read_regs(mr::SELF_TEST_X_ACCEL_6500, &mut ac) $(.$await)? ?;
                    m::self_test_report_6500(on_a, on_g, off_a, off_g, gc, ac)
                };
                self.write_register(mb::GyroConfig::range(self.config.gyro_range).write_bytes()) $(.$await)? ?;
                self.write_register(mb::AccelConfig::range(self.config.accel_range).write_bytes()) $(.$await)? ?;
                Ok(report)
            }
        }

        /// QMC5883L / QMC5883P magnetometer driver.
        #[derive(Debug)]
        pub struct Qmc5883<I2C> {
            i2c: I2C,
            variant: Variant,
            config: q::Config,
        }

        impl<I2C: $I2c> Qmc5883<I2C> {
            /// A QMC5883L at 0x0D; no I/O.
            pub fn new(i2c: I2C) -> Self {
                Self::new_variant(i2c, Variant::L)
            }

            /// A given variant (QMC5883P at 0x2C with [`Variant::P`]); no I/O.
            pub fn new_variant(i2c: I2C, variant: Variant) -> Self {
                Qmc5883 { i2c, variant, config: q::Config::default() }
            }

            /// Give the bus back.
            pub fn release(self) -> I2C {
                self.i2c
            }

            /// The bus, e.g. to ask it when its last transfer started.
            pub fn bus(&self) -> &I2C {
                &self.i2c
            }

            /// Variant driven.
            pub fn variant(&self) -> Variant {
                self.variant
            }

            /// Configuration applied by the last `init`.
            pub fn config(&self) -> &q::Config {
                &self.config
            }

            /// Probe the three addresses and report which magnetometer answers with the right
            /// identity: QMC5883L (0x0D: reg 0x0D = 0xFF), QMC5883P (0x2C: reg 0x00 = 0x80),
            /// HMC5883L (0x1E: regs 10..12 = "H43"). A NACK or another id counts as absent.
            pub $($async)? fn detect(i2c: &mut I2C) -> Chip {
                let mut b = [0u8; 1];
                if i2c.write_read(q::QMC5883L_ADDR, &[q::reg_l::CHIP_ID], &mut b) $(.$await)?.is_ok()
                    && b[0] == q::reg_l::CHIP_ID_VALUE
                {
                    return Chip::Qmc5883L;
                }
                if i2c.write_read(q::QMC5883P_ADDR, &[q::reg_p::CHIP_ID], &mut b) $(.$await)?.is_ok()
                    && b[0] == q::reg_p::CHIP_ID_VALUE
                {
                    return Chip::Qmc5883P;
                }
                let mut id = [0u8; 3];
                if i2c.write_read(q::HMC5883L_ADDR, &[q::reg_hmc::ID_A], &mut id) $(.$await)?.is_ok()
                    && id == q::reg_hmc::ID_VALUE
                {
                    return Chip::Hmc5883L;
                }
                Chip::None
            }

            /// Write one register: `bytes` from [`Register::write_bytes`] (see `Mpu6050`).
            $($async)? fn write_register(&mut self, bytes: [u8; 2]) -> Result<(), MagError<I2C>> {
                self.i2c.write(self.variant.addr(), &bytes) $(.$await)? ?;
                Ok(())
            }

            $($async)? fn read_regs(&mut self, reg: u8, buf: &mut [u8]) -> Result<(), MagError<I2C>> {
                self.i2c.write_read(self.variant.addr(), &[reg], buf) $(.$await)? ?;
                Ok(())
            }

            /// Read the chip-id register of the variant.
            pub $($async)? fn chip_id(&mut self) -> Result<u8, MagError<I2C>> {
                let mut b = [0u8; 1];
                self.read_regs(self.variant.chip_id().0, &mut b) $(.$await)? ?;
                Ok(b[0])
            }

            /// Check the chip id, soft-reset and configure ([`Self::prepare`], then
            /// [`Self::start`]; values: docs/drivers.md).
            pub $($async)? fn init<D: $Delay>(&mut self, delay: &mut D, config: &q::Config) -> Result<(), MagError<I2C>> {
                self.prepare(delay, config) $(.$await)? ?;
                self.start() $(.$await)?
            }

            /// Check the chip id, soft-reset and configure everything but CONTROL1 (the part
            /// then does not measure). QMC5883L: CONTROL2 = SOFT_RST, wait, SET/RESET period
            /// (0x0B), CONTROL2. QMC5883P: CONTROL2 = SOFT_RST, wait, axis sign (0x29 = 0x06),
            /// CONTROL2.
            pub $($async)? fn prepare<D: $Delay>(&mut self, delay: &mut D, config: &q::Config) -> Result<(), MagError<I2C>> {
                if config.range.lsb_per_gauss(self.variant).is_none() {
                    return Err(q::Error::InvalidConfig);
                }
                if self.variant == Variant::L && config.control1_l().is_none() {
                    return Err(q::Error::InvalidConfig);
                }
                let found = self.chip_id() $(.$await)? ?;
                if found != self.variant.chip_id().1 {
                    return Err(q::Error::WrongChip { found });
                }
                match self.variant {
                    Variant::L => {
                        self.write_register(qr::Control2L::RESET.write_bytes()) $(.$await)? ?;
                        delay.delay_ms(q::SOFT_RESET_DELAY_MS) $(.$await)?;
                        self.write_register(config.set_reset_period_l().write_bytes()) $(.$await)? ?;
                        self.write_register(config.control2_l().write_bytes()) $(.$await)? ?;
                    }
                    Variant::P => {
                        self.write_register(qr::Control2P::RESET.write_bytes()) $(.$await)? ?;
                        delay.delay_ms(q::SOFT_RESET_DELAY_MS) $(.$await)?;
                        self.write_register(qr::AxisSign::DATASHEET.write_bytes()) $(.$await)? ?;
                        self.write_register(config.control2_p().write_bytes()) $(.$await)? ?;
                    }
                }
                self.config = *config;
                Ok(())
            }

            /// Write CONTROL1 (mode, rate, range, over-sampling): in continuous mode the part's
            /// measurement clock starts with this write, its first sample one period later.
            pub $($async)? fn start(&mut self) -> Result<(), MagError<I2C>> {
                match self.variant {
                    Variant::L => {
                        let c1 = self.config.control1_l().ok_or(q::Error::InvalidConfig)?;
                        self.write_register(c1.write_bytes()) $(.$await)?
                    }
                    Variant::P => self.write_register(self.config.control1_p().write_bytes()) $(.$await)?,
                }
            }

            /// Whether the part still holds the configuration (CONTROL1 and CONTROL2 read back):
            /// a power cycle or a soft reset clears them.
            pub $($async)? fn config_intact(&mut self) -> Result<bool, MagError<I2C>> {
                let (c1_reg, c1, c2) = match self.variant {
                    Variant::L => (
                        qr::Control1L::ADDR,
                        self.config.control1_l().ok_or(q::Error::InvalidConfig)?.bits(),
                        self.config.control2_l().bits(),
                    ),
                    Variant::P => (
                        qr::Control1P::ADDR,
                        self.config.control1_p().bits(),
                        self.config.control2_p().bits(),
                    ),
                };
                let mut b = [0u8; 2];
                self.read_regs(c1_reg, &mut b) $(.$await)? ?;
                Ok(b == [c1, c2])
            }

            /// Read the status register.
            pub $($async)? fn status(&mut self) -> Result<Status, MagError<I2C>> {
                let mut b = [0u8; 1];
                self.read_regs(self.variant.status_reg(), &mut b) $(.$await)? ?;
                Ok(Status::from_bits(b[0], self.variant))
            }

            /// Read one measurement: status (with the L's temperature in the same burst),
            /// then the 6 data bytes. [`q::Error::NotReady`] if DRDY is clear — the data
            /// registers are then not read, so DOR keeps counting skipped samples.
            ///
            /// With [`q::Config::roll_over`] on the L: one 7-byte read from 06H, status then
            /// data (no temperature). If DRDY was clear the data bytes are discarded and
            /// [`q::Error::NotReady`] returned. Reading them clears DRDY and DOR, which were
            /// clear — unless a measurement completed during the transfer itself: that one is
            /// then lost without DOR, and the next reading comes a period late (a caller that
            /// checks the spacing of its readings sees the gap; the firmware does).
            pub $($async)? fn read(&mut self) -> Result<MagSample, MagError<I2C>> {
                if self.variant == Variant::L && self.config.roll_over {
                    let mut b = [0u8; 7];
                    self.read_regs(q::reg_l::STATUS, &mut b) $(.$await)? ?;
                    let status = Status::from_bits(b[0], Variant::L);
                    if !status.ready {
                        return Err(q::Error::NotReady);
                    }
                    return Ok(MagSample {
                        xyz: q::decode_xyz([b[1], b[2], b[3], b[4], b[5], b[6]]),
                        temp: None,
                        overflow: status.overflow,
                        skipped: status.skipped,
                    });
                }
                let (status, temp) = match self.variant {
                    Variant::L => {
                        let mut b = [0u8; 3];
                        self.read_regs(q::reg_l::STATUS, &mut b) $(.$await)? ?;
                        (Status::from_bits(b[0], Variant::L), Some(i16::from_le_bytes([b[1], b[2]])))
                    }
                    Variant::P => (self.status() $(.$await)? ?, None),
                };
                if !status.ready {
                    return Err(q::Error::NotReady);
                }
                let mut d = [0u8; 6];
                self.read_regs(self.variant.data_reg(), &mut d) $(.$await)? ?;
                Ok(MagSample {
                    xyz: q::decode_xyz(d),
                    temp,
                    overflow: status.overflow,
                    skipped: status.skipped,
                })
            }

            /// The status and then the 6 data bytes in one transaction, a repeated START between
            /// them (no pointer roll-over needed, for either variant). Reading the data clears
            /// DRDY: they are the newest measurement when the status shows DRDY, and a
            /// measurement that completes after the status byte, during the transfer, is cleared
            /// unseen. Use it where the measurement is known to have landed already (after the
            /// late end of a sample clock's interval), [`Self::status`] elsewhere.
            pub $($async)? fn status_and_data(&mut self) -> Result<(Status, [i16; 3]), MagError<I2C>> {
                let mut b = [0u8; 7];
                let (status, data) = b.split_at_mut(1);
                let mut ops = [
                    Operation::Write(&[self.variant.status_reg()]),
                    Operation::Read(status),
                    Operation::Write(&[self.variant.data_reg()]),
                    Operation::Read(data),
                ];
                self.i2c.transaction(self.variant.addr(), &mut ops) $(.$await)? ?;
                let d = [b[1], b[2], b[3], b[4], b[5], b[6]];
                Ok((Status::from_bits(b[0], self.variant), q::decode_xyz(d)))
            }

            /// The six data bytes alone (no status): the latest measurement, whether or not it
            /// is new (a caller that polled the status first knows). Reading them clears DRDY
            /// and DOR.
            pub $($async)? fn read_data(&mut self) -> Result<[i16; 3], MagError<I2C>> {
                let mut d = [0u8; 6];
                self.read_regs(self.variant.data_reg(), &mut d) $(.$await)? ?;
                Ok(q::decode_xyz(d))
            }

            /// Sensitivity of the applied configuration, LSB/G.
            pub fn lsb_per_gauss(&self) -> f32 {
                // `init` rejects ranges the variant lacks; the fallback is the L's ±2 G.
                self.config.range.lsb_per_gauss(self.variant).unwrap_or(12000.0)
            }

            /// Field of `sample` in µT (1 G = 100 µT).
            pub fn microtesla(&self, sample: &MagSample) -> [f32; 3] {
                q::to_microtesla(sample.xyz, self.lsb_per_gauss())
            }
        }
    };
}

pub(crate) use drivers;
