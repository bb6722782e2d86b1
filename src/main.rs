//! pico-imu firmware for the Raspberry Pi Pico W: samples an MPU-6050 (1 kHz FIFO) and a
//! QMC5883L (200 Hz) on I2C0, corrects them in fixed point, runs the streaming Allan engines for
//! ten channels, and reports over USB CDC-ACM (imu-proto frames) and defmt-RTT.
//!
//! `main` hands the executor to its run loop (`cpu::run`, which also measures the CPU load) with
//! one task, `start`: the peripherals, USB, the sensors' bus, then the tasks.
//!
//! Tasks (docs/firmware.md has the diagram):
//! * `imu_task`     — MPU-6050 FIFO bursts every 10 ms, right after every second magnetometer
//!   tick, fault handling;
//! * `mag_task`     — QMC5883L at 200 Hz, following the sensor's own phase, fault handling;
//! * `process_task` — the pipeline and host requests (`pico_imu_core::device::Device`), calibration
//!   storage (the only flash writer);
//! * `tick_task`    — the 100 ms housekeeping tick (status, tables);
//! * `usb_task`, `usb_tx_task`, `usb_rx_task` — embassy-usb device, frames out, frames in.
//!
//! Tasks talk only through the embassy-sync channels, pipe, watch and signal below; the I2C bus
//! is shared through an embassy-sync mutex.
#![no_std]
#![no_main]

mod alarm;
mod bus;
mod cpu;
mod i2c_dma;
mod statics;
mod storage;

use core::cell::Cell;
use defmt::{debug, info, warn};
use embassy_executor::Spawner;
use embassy_futures::select::{select, select4, Either4};
use embassy_rp::bind_interrupts;
use embassy_rp::i2c::{self, I2c};
use embassy_rp::peripherals::{I2C0, USB};
use embassy_rp::usb::{self, Driver};
use embassy_sync::blocking_mutex::{self, raw::NoopRawMutex};
use embassy_sync::channel::Channel;
use embassy_sync::mutex::Mutex;
use embassy_sync::pipe::{self, Pipe};
use embassy_sync::signal::Signal;
use embassy_sync::watch::Watch;
use embassy_sync::zerocopy_channel;
use embassy_time::{Duration, Instant, Ticker, Timer};
use embassy_usb::class::cdc_acm::{CdcAcmClass, Receiver, Sender, State};
use embassy_usb::UsbDevice;
use imu_drivers::asynch::{Mpu6050, Qmc5883};
use imu_drivers::mpu6050::Address;
use imu_proto::{DecodeError, FrameReader, HostFrame};
use pico_imu_core::clock::BusTiming;
use pico_imu_core::config;
use pico_imu_core::device::Device;
use pico_imu_core::imu::ImuService;
use pico_imu_core::mag::MagService;
use pico_imu_core::msg::{self, SensorMsg};
use pico_imu_core::outbox::FrameSink;
use pico_imu_core::requests::Record;
use pico_imu_core::schedule::{self, Housekeeping, MagTicks, StatusLog};
use pico_imu_core::sensor::Tick;
use static_cell::StaticCell;
use {defmt_rtt as _, panic_probe as _};

use crate::bus::{BusDevice, SharedBus};

bind_interrupts!(struct Irqs {
    I2C0_IRQ => i2c::InterruptHandler<I2C0>, i2c_dma::I2cAbortHandler;
    DMA_IRQ_0 => i2c_dma::DmaDoneHandler;
    TIMER_IRQ_1 => alarm::AlarmHandler;
    TIMER_IRQ_2 => alarm::AlarmHandler;
    TIMER_IRQ_3 => alarm::AlarmHandler;
    USBCTRL_IRQ => usb::InterruptHandler<USB>;
});

/// I2C0 clock: 400 kHz fast mode (both sensors support it).
const I2C_HZ: u32 = 400_000;

/// I2C0 on GP5 (SCL) / GP4 (SDA), async, with this file's interrupt bindings: at boot and
/// whenever the bus re-creates its controller (`bus::MakeI2c`).
///
/// # Safety
///
/// Steals I2C0, GP4 and GP5: only while nothing else drives them.
unsafe fn make_i2c(config: i2c::Config) -> I2c<'static, I2C0, i2c::Async> {
    use embassy_rp::peripherals::{PIN_4, PIN_5};
    // SAFETY: the caller guarantees no other driver of these exists.
    let (p, scl, sda) = unsafe { (I2C0::steal(), PIN_5::steal(), PIN_4::steal()) };
    I2c::new_async(p, scl, sda, Irqs, config)
}
/// The IMU FIFO is drained every 10 ms, right after every second magnetometer tick, or at
/// the fallback instant when that tick does not come; when each burst runs is
/// `pico_imu_core::schedule`'s. Bursts every 10 ms instead of 5 ms saved ≈ 750 cycles per
/// sample set (docs/firmware.md, "Budgets"). (The fallback waits on a TIMER alarm of its own,
/// `alarm::IMU_FALLBACK`, disarmed when the signal wins: no timer is left behind to wake the
/// task later.)
/// Encoded device→host frames waiting for USB; a full pipe drops whole frames (counted).
const OUT_PIPE: usize = 8192;
/// Largest host frame accepted (a SetCalibration with a 256-byte blob is ~270 bytes).
const MAX_HOST_FRAME: usize = 512;

type OutPipe = Pipe<NoopRawMutex, OUT_PIPE>;
type OutWriter = pipe::Writer<'static, NoopRawMutex, OUT_PIPE>;
type OutReader = pipe::Reader<'static, NoopRawMutex, OUT_PIPE>;
/// One sensor task's messages of one tick, filled in place by the task and read in place by
/// the processing task (no copies of the 150-byte messages through a queue).
type SensorChannel = zerocopy_channel::Channel<'static, NoopRawMutex, msg::Out>;
type SensorTx = zerocopy_channel::Sender<'static, NoopRawMutex, msg::Out>;
type SensorRx = zerocopy_channel::Receiver<'static, NoopRawMutex, msg::Out>;
/// Ticks in flight per sensor task.
const SENSOR_SLOTS: usize = 2;
type HostChannel = Channel<NoopRawMutex, HostIn, 4>;
/// `true` while measuring; the processing task clears it around a flash write.
type RunWatch = Watch<NoopRawMutex, bool, 2>;
/// The 100 ms housekeeping tick (status, tables) from `tick_task` to the processing task. A
/// task of its own: a `Ticker` polled inside the processing task's select was re-registered
/// with the timer queue (a walk of every timer) on each of its ≈ 400 wake-ups a second.
type TickSignal = Signal<NoopRawMutex, ()>;
/// Every second magnetometer tick, just finished (mag_task → imu_task): the bus is free for
/// ≈ 4.5 ms.
type MagReadSignal = Signal<NoopRawMutex, ()>;
/// What the USB receiver passes on.
#[allow(clippy::large_enum_variant)] // no heap: requests travel inline
enum HostIn {
    Frame(HostFrame),
    Rejected(DecodeError),
}

/// Bytes in the output pipe. The pipe is split so that the USB task can send from it in place
/// (`Reader::fill_buf`; a copy out of the pipe cost ≈ 170 cycles per sample set), and a
/// `Writer` cannot tell its free space, so the two tasks keep the count here: the processing
/// task adds what it writes, the USB task subtracts what it consumes.
type OutQueued = blocking_mutex::Mutex<NoopRawMutex, Cell<usize>>;

/// The processing task's end of the output pipe.
struct PipeSink {
    pipe: OutWriter,
    queued: &'static OutQueued,
}

impl FrameSink for PipeSink {
    fn room(&self) -> usize {
        OUT_PIPE.saturating_sub(self.queued.lock(Cell::get))
    }
    fn put(&mut self, mut frame: &[u8]) {
        // `room()` was checked by the caller and only this task writes, so it fits whole; a
        // ring buffer takes it in at most two contiguous pieces.
        while !frame.is_empty() {
            match self.pipe.try_write(frame) {
                Ok(n) => {
                    self.queued.lock(|q| q.set(q.get() + n));
                    frame = &frame[n..];
                }
                Err(_) => break, // unreachable given room(); never spin
            }
        }
    }
}

static OUT: StaticCell<OutPipe> = StaticCell::new();
static IMU_SLOTS: StaticCell<[msg::Out; SENSOR_SLOTS]> = StaticCell::new();
static MAG_SLOTS: StaticCell<[msg::Out; SENSOR_SLOTS]> = StaticCell::new();
static IMU_CH: StaticCell<SensorChannel> = StaticCell::new();
static MAG_CH: StaticCell<SensorChannel> = StaticCell::new();
static HOST: StaticCell<HostChannel> = StaticCell::new();
static RUN: StaticCell<RunWatch> = StaticCell::new();
static TICK: StaticCell<TickSignal> = StaticCell::new();
static MAG_READ: StaticCell<MagReadSignal> = StaticCell::new();
static OUT_QUEUED: StaticCell<OutQueued> = StaticCell::new();
static BUS: StaticCell<SharedBus> = StaticCell::new();
static DEVICE: StaticCell<Device> = StaticCell::new();

/// The thread-mode executor, run by `crate::cpu::run` (which counts its idle time).
static EXECUTOR: StaticCell<embassy_executor::raw::Executor> = StaticCell::new();

#[cortex_m_rt::entry]
fn main() -> ! {
    // The context embassy's pender takes for the thread-mode executor: it then ends a `WFE`
    // with `SEV` (embassy-executor's `platform-cortex-m`).
    let executor = EXECUTOR.init(embassy_executor::raw::Executor::new(usize::MAX as *mut ()));
    let spawner = executor.spawner();
    spawner.spawn(start(spawner).expect("spawn start"));
    cpu::run(executor)
}

/// Start-up: the peripherals, USB, the sensors' bus and every task.
#[embassy_executor::task]
async fn start(spawner: Spawner) {
    let p = embassy_rp::init(Default::default());
    info!("pico-imu {} booting", env!("CARGO_PKG_VERSION"));

    // --- USB CDC-ACM ---------------------------------------------------------------------
    let driver = Driver::new(p.USB, Irqs);
    let mut config = embassy_usb::Config::new(0x2e8a, 0x000a);
    config.manufacturer = Some("pico-imu");
    config.product = Some("pico-imu IMU lab");
    config.serial_number = Some("0001");
    config.max_power = 100;
    config.max_packet_size_0 = 64;
    static CONFIG_DESC: StaticCell<[u8; 256]> = StaticCell::new();
    static BOS_DESC: StaticCell<[u8; 256]> = StaticCell::new();
    static CONTROL_BUF: StaticCell<[u8; 64]> = StaticCell::new();
    static CDC_STATE: StaticCell<State> = StaticCell::new();
    let mut builder = embassy_usb::Builder::new(
        driver,
        config,
        CONFIG_DESC.init([0; 256]),
        BOS_DESC.init([0; 256]),
        &mut [],
        CONTROL_BUF.init([0; 64]),
    );
    let class = CdcAcmClass::new(&mut builder, CDC_STATE.init(State::new()), 64);
    let usb = builder.build();
    let (tx, rx) = class.split();

    // --- I2C0 on GP4 (SDA) / GP5 (SCL), 400 kHz --------------------------------------------
    let mut i2c_config = i2c::Config::default();
    i2c_config.frequency = I2C_HZ;
    // The bus re-creates the controller from the stolen peripherals (`make_i2c`): these are
    // not used again.
    let _ = (p.I2C0, p.PIN_4, p.PIN_5);
    alarm::init(Irqs);
    let dma = i2c_dma::I2cDma::new(p.DMA_CH0, p.DMA_CH1, Irqs);
    let bus: &'static SharedBus = BUS.init(Mutex::new(bus::Bus::new(make_i2c, dma, i2c_config)));

    // --- channels ---------------------------------------------------------------------------
    let (out_rx, out_tx) = OUT.init(Pipe::new()).split();
    let out_queued: &'static OutQueued = OUT_QUEUED.init(blocking_mutex::Mutex::new(Cell::new(0)));
    let imu_ch = IMU_CH.init(SensorChannel::new(
        IMU_SLOTS.init([const { msg::Out::new() }; SENSOR_SLOTS]),
    ));
    let mag_ch = MAG_CH.init(SensorChannel::new(
        MAG_SLOTS.init([const { msg::Out::new() }; SENSOR_SLOTS]),
    ));
    let (imu_tx, imu_rx) = imu_ch.split();
    let (mag_tx, mag_rx) = mag_ch.split();
    let host: &'static HostChannel = HOST.init(Channel::new());
    let run: &'static RunWatch = RUN.init(Watch::new());
    let tick: &'static TickSignal = TICK.init(Signal::new());
    let mag_read: &'static MagReadSignal = MAG_READ.init(Signal::new());
    run.sender().send(true);

    // --- calibration from flash -------------------------------------------------------------
    let mut store = storage::Store::new(p.FLASH);
    let device = DEVICE.init(Device::new(
        config::scales(),
        concat!("pico-imu ", env!("CARGO_PKG_VERSION")),
    ));
    let mut blob = [0u8; imu_proto::MAX_CAL_BLOB];
    match store.load(Record::Calibration, &mut blob).await {
        Ok(Some(n)) => device.load_stored(Some(&blob[..n])),
        Ok(None) => device.load_stored(None),
        Err(()) => device.flash_unreadable(),
    }
    info!("calibration: {}", device.cal_status());
    // The attitude filter's declination and expected field as the host last set them; an
    // unreadable or unusable record leaves the defaults (no declination, a learnt reference).
    let stored = match store.load(Record::Orientation, &mut blob).await {
        Ok(n) => device.load_orientation(n.map(|n| &blob[..n])),
        Err(()) => Ok(()),
    };
    match stored {
        Ok(()) => info!("orientation: {}", device.orientation_config()),
        Err(e) => warn!("orientation record not used: {}", e),
    }

    spawner.spawn(usb_task(usb).expect("spawn usb_task"));
    spawner.spawn(tick_task(tick).expect("spawn tick_task"));
    spawner.spawn(usb_tx_task(tx, out_rx, out_queued).expect("spawn usb_tx_task"));
    spawner.spawn(usb_rx_task(rx, host).expect("spawn usb_rx_task"));
    spawner.spawn(imu_task(bus, imu_tx, run, mag_read).expect("spawn imu_task"));
    spawner.spawn(mag_task(bus, mag_tx, run, mag_read).expect("spawn mag_task"));
    spawner.spawn(
        process_task(
            device,
            store,
            Inputs {
                imu: imu_rx,
                mag: mag_rx,
                host,
                tick,
            },
            PipeSink {
                pipe: out_tx,
                queued: out_queued,
            },
            run,
        )
        .expect("spawn process_task"),
    );
}

/// The housekeeping tick (`TickSignal`).
#[embassy_executor::task]
async fn tick_task(tick: &'static TickSignal) -> ! {
    let mut t = Ticker::every(Duration::from_millis(schedule::TICK_MS));
    loop {
        t.next().await;
        tick.signal(());
    }
}

#[embassy_executor::task]
async fn usb_task(mut usb: UsbDevice<'static, Driver<'static, USB>>) -> ! {
    usb.run().await
}

/// Moves encoded frames from the pipe to the IN endpoint, up to 64 bytes a packet, sent
/// straight from the pipe's buffer.
#[embassy_executor::task]
async fn usb_tx_task(
    mut tx: Sender<'static, Driver<'static, USB>>,
    mut out: OutReader,
    queued: &'static OutQueued,
) -> ! {
    loop {
        tx.wait_connection().await;
        info!("usb: host connected");
        loop {
            let bytes = out.fill_buf().await;
            let n = bytes.len().min(64);
            if tx.write_packet(&bytes[..n]).await.is_err() {
                // Not consumed: the bytes go out when a host connects again.
                warn!("usb: host gone");
                break;
            }
            out.consume(n);
            queued.lock(|q| q.set(q.get().saturating_sub(n)));
        }
    }
}

/// Reads host frames; every decoded or rejected frame goes to the processing task.
#[embassy_executor::task]
async fn usb_rx_task(
    mut rx: Receiver<'static, Driver<'static, USB>>,
    host: &'static HostChannel,
) -> ! {
    let mut reader = FrameReader::<MAX_HOST_FRAME>::new();
    let mut pkt = [0u8; 64];
    loop {
        rx.wait_connection().await;
        loop {
            let n = match rx.read_packet(&mut pkt).await {
                Ok(n) => n,
                Err(_) => break,
            };
            for &b in &pkt[..n] {
                match reader.push::<HostFrame>(b) {
                    Some(Ok(f)) => host.send(HostIn::Frame(f)).await,
                    Some(Err(e)) => host.send(HostIn::Rejected(e)).await,
                    None => {}
                }
            }
        }
    }
}

fn now_us() -> u64 {
    Instant::now().as_micros()
}

/// Waits while measurement is paused (flash write); returns whether it was paused.
async fn wait_running(
    run: &mut embassy_sync::watch::Receiver<'static, NoopRawMutex, bool, 2>,
) -> bool {
    if run.try_get() != Some(false) {
        return false;
    }
    while !run.changed().await {}
    true
}

/// Run a bus recovery for a sensor service that asks for one, and report it.
async fn recover_bus(bus: &'static SharedBus, msgs: &mut msg::Out) {
    let (pulses, sda_released) = bus.lock().await.recover();
    let _ = msgs.push(SensorMsg::BusRecovered {
        t_us: now_us(),
        pulses,
        sda_released,
    });
}

/// MPU-6050: FIFO bursts every 10 ms (`pico_imu_core::imu::ImuService`), after every second
/// magnetometer tick; faults are retried with bus recovery.
#[embassy_executor::task]
async fn imu_task(
    bus: &'static SharedBus,
    mut out: SensorTx,
    run: &'static RunWatch,
    mag_read: &'static MagReadSignal,
) -> ! {
    let mut run = run.receiver().expect("watch receiver for imu_task");
    // The driver and the service live in statics (the task is spawned once), so that its future
    // holds pointers to them: the fields its polls reach lie nearer its start.
    static IMU: StaticCell<Mpu6050<BusDevice>> = StaticCell::new();
    static SVC: StaticCell<ImuService> = StaticCell::new();
    let imu = IMU.init(Mpu6050::new(BusDevice::new(bus), Address::Ad0Low));
    let svc = SVC.init(ImuService::new(BusTiming::from_hz(I2C_HZ)));
    let mut last_us = now_us();
    let mut was = svc.state();
    loop {
        let fallback = Instant::from_micros(schedule::imu_fallback_at(last_us, svc.retrying()));
        // Either result starts a burst.
        let _ = select(mag_read.wait(), alarm::IMU_FALLBACK.wait_until(fallback)).await;
        last_us = now_us();
        let msgs = out.send().await;
        msgs.clear();
        // The fallback alarm is idle until the next burst: it times the tick's own waits.
        let mut delay = alarm::Delay(alarm::IMU_FALLBACK);
        let cx = &mut Tick::new(imu, &mut delay, &now_us, msgs);
        if wait_running(&mut run).await {
            svc.resume(cx).await;
        } else {
            if svc.wants_recovery(now_us()) {
                recover_bus(bus, cx.out).await;
                svc.recovered();
            }
            svc.tick(cx).await;
        }
        if svc.state() != was {
            warn!("imu: {} -> {}", was, svc.state());
            was = svc.state();
        }
        if !msgs.is_empty() {
            out.send_done();
        }
    }
}

/// QMC5883L at 200 Hz (`pico_imu_core::mag::MagService`), at the instants its sample clock
/// predicts; every second tick is signalled to `imu_task`, which places its bursts between them.
#[embassy_executor::task]
async fn mag_task(
    bus: &'static SharedBus,
    mut out: SensorTx,
    run: &'static RunWatch,
    mag_read: &'static MagReadSignal,
) -> ! {
    let mut run = run.receiver().expect("watch receiver for mag_task");
    // The driver, the service and the tick plan live in statics (the task is spawned once), so
    // that its future holds pointers to them: the fields its polls reach lie nearer its start.
    static MAG: StaticCell<Qmc5883<BusDevice>> = StaticCell::new();
    static SVC: StaticCell<MagService> = StaticCell::new();
    static TURNS: StaticCell<MagTicks> = StaticCell::new();
    let mag = MAG.init(Qmc5883::new(BusDevice::new(bus)));
    let svc = SVC.init(MagService::new(BusTiming::from_hz(I2C_HZ)));
    let turns = TURNS.init(MagTicks::new());
    let mut was = svc.state();
    loop {
        let at = Instant::from_micros(turns.next_at(svc.next_poll_us(), now_us()));
        alarm::MAG_TICK.wait_until(at).await;
        // A few ticks' messages share a slot: the slot stays ours until `send_done`.
        let msgs = out.send().await;
        if turns.fresh() {
            msgs.clear();
        }
        if wait_running(&mut run).await {
            svc.resume();
        } else {
            if svc.wants_recovery(now_us()) {
                recover_bus(bus, msgs).await;
                svc.recovered();
            }
            // The tick alarm is idle until the next tick: it times the tick's own waits.
            svc.tick(&mut Tick::new(
                mag,
                &mut alarm::Delay(alarm::MAG_TICK),
                &now_us,
                msgs,
            ))
            .await;
        }
        if svc.state() != was {
            warn!("mag: {} -> {}", was, svc.state());
            was = svc.state();
        }
        let next = turns.done(msgs.len(), msgs.capacity());
        if next.burst {
            // The bus is free until the next tick.
            mag_read.signal(());
        }
        if next.hand_over {
            out.send_done();
        }
    }
}

/// What the processing task waits on.
struct Inputs {
    imu: SensorRx,
    mag: SensorRx,
    host: &'static HostChannel,
    tick: &'static TickSignal,
}

/// The pipeline, host requests, periodic status/tables, and flash writes on request.
#[embassy_executor::task]
async fn process_task(
    device: &'static mut Device,
    mut store: storage::Store,
    inputs: Inputs,
    mut sink: PipeSink,
    run: &'static RunWatch,
) -> ! {
    let Inputs {
        mut imu,
        mut mag,
        host,
        tick,
    } = inputs;
    let mut housekeeping = Housekeeping::new(now_us());
    let mut cpu = cpu::Meter::new();
    let mut status_log = StatusLog::default();
    loop {
        // A table frame (its encoding) runs right after a magnetometer reading, so it cannot
        // hold up the next one. Without a working magnetometer it runs on the 100 ms tick.
        let mut table_turn = false;
        // The host arm only waits for readiness: selecting on `receive()` would return the
        // ≈ 300-byte `HostIn` through the select's output, copied on every wake-up (≈ 190
        // cycles per sample set in the emulator).
        match select4(
            imu.receive(),
            mag.receive(),
            host.ready_to_receive(),
            tick.wait(),
        )
        .await
        {
            Either4::First(msgs) => {
                for m in msgs.iter() {
                    device.on_sensor(m, &mut sink);
                }
                imu.receive_done();
                // The queued attitude updates (one per magnetometer sample, ≈ 20 µs each in
                // integers) run here, in line with the IMU burst's processing, at most three
                // (two queue per 10 ms; the third drains a backlog): the sensor tasks are then
                // between their transfers and see the same delay every time. (Measured with the
                // 0.25 ms soft-float updates: run right after the magnetometer's hand-over, four
                // back to back misdated magnetometer reads under bus faults; run one at a time
                // with the tasks polled in between, they delayed the IMU's count reads at
                // random, stamps 25 µs rms off instead of 2.)
                for _ in 0..3 {
                    if !device.attitude_step(&mut sink) {
                        break;
                    }
                }
            }
            Either4::Second(msgs) => {
                for m in msgs.iter() {
                    table_turn |= matches!(m, SensorMsg::Mag { .. });
                    device.on_sensor(m, &mut sink);
                }
                mag.receive_done();
            }
            Either4::Third(()) => match host.try_receive() {
                Err(_) => {}
                Ok(HostIn::Rejected(e)) => {
                    warn!("host frame rejected: {}", e);
                    device.rejected_frame();
                }
                Ok(HostIn::Frame(f)) => {
                    let load = cpu.last_permille();
                    if let Some(req) = device.handle(f, now_us(), load, &mut sink) {
                        // Flash write: pause sampling, let the tasks see it, write, resume.
                        // With the magnetometer task paused, imu_task wakes on its fallback
                        // timer at the latest, schedule::IMU_FALLBACK_US after its last burst.
                        run.sender().send(false);
                        Timer::after_micros(schedule::IMU_FALLBACK_US + 10_000).await;
                        let ok = store.save(req.record, &req.blob).await.is_ok();
                        run.sender().send(true);
                        info!("{} persisted: {}", req.record, ok);
                        device.persisted(&req, ok, &mut sink);
                    }
                }
            },
            Either4::Fourth(()) => {
                // Without IMU bursts (the IMU missing or stalled), the queued attitude updates
                // run on the 100 ms tick.
                if device.attitude_backlog() {
                    while device.attitude_step(&mut sink) {}
                }
                let now = now_us();
                let plan = housekeeping.on_tick(
                    now,
                    device.status_interval_ms(),
                    device.tables_interval_ms(),
                    device.tables_pending(),
                    device.mag_ok(),
                );
                table_turn = plan.table_turn;
                if plan.status {
                    let load = cpu.sample();
                    let st = device.send_status(now, load, &mut sink);
                    if status_log.due(&st, device.tables_pending()) {
                        info!(
                            "status: {} samples, {} lost, {} overflows, {} I2C errors, cpu {}‰, imu {} ({} ns), mag {} ({} ns, {} lost)",
                            st.samples_taken, st.samples_dropped, st.fifo_overflows, st.i2c_errors, load, st.imu, st.imu_period_ns, st.mag, st.mag_period_ns, st.mag_dropped
                        );
                    }
                }
                if plan.tables {
                    let round = device.start_tables(now);
                    // Debug level: the host sees every table, and a line would cost as much as
                    // the snapshot.
                    debug!("tables: round {} (snapshot at {} µs)", round, now);
                }
            }
        }
        if !table_turn {
            continue;
        }
        // One table frame per turn at most, spaced out (`pico_imu_core::tables`); each frame
        // is logged at debug level only (ten lines a round would cost more than the frames).
        if let Some(ch) = device.tables_step(now_us(), &mut sink) {
            debug!("table {} sent", ch.name());
        }
    }
}
