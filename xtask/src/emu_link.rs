//! The end-to-end session's hold on the device: `imu_link`'s link (the one imu-lab uses) to the
//! emulator's TCP port, with everything the device sends besides replies collected for the
//! checks.
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use imu_proto::{AllanTable, DeviceMsg, Event, Orientation, Reply, Request, SampleBatch, Status};

/// How long one wait for device traffic lasts before the caller's condition is looked at again.
const POLL: Duration = Duration::from_millis(200);

/// What the device sent besides replies.
#[derive(Default)]
pub struct Collected {
    /// Latest table per channel index.
    pub tables: BTreeMap<usize, AllanTable>,
    pub statuses: Vec<Status>,
    pub events: Vec<Event>,
    pub batches: Vec<SampleBatch>,
    /// Attitude estimates, in arrival order.
    pub orientations: Vec<Orientation>,
}

impl Collected {
    fn take(&mut self, m: DeviceMsg) {
        if std::env::var_os("XTASK_EMU_DEBUG").is_some() {
            eprintln!("xtask: <- {}", describe(&m));
        }
        match m {
            // A reply nobody waits for (its request timed out): nothing to keep.
            DeviceMsg::Reply { .. } => {}
            DeviceMsg::Samples(b) => self.batches.push(b),
            DeviceMsg::Table(t) => {
                self.tables.insert(t.channel.index(), t);
            }
            DeviceMsg::Status(s) => self.statuses.push(s),
            DeviceMsg::Event(e) => self.events.push(e),
            DeviceMsg::Orientation(o) => self.orientations.extend(o),
        }
    }
}

fn describe(m: &DeviceMsg) -> String {
    match m {
        DeviceMsg::Reply { id, reply } => format!("reply {id} {reply:?}"),
        DeviceMsg::Samples(b) => format!("samples imu={} mag={}", b.imu.len(), b.mag.len()),
        DeviceMsg::Table(t) => format!("table {} pushed={}", t.channel.name(), t.pushed),
        DeviceMsg::Status(s) => format!("status uptime={} µs", s.uptime_us),
        DeviceMsg::Event(e) => format!("event {e:?}"),
        DeviceMsg::Orientation(o) => format!("orientation ×{}", o.len()),
    }
}

pub struct Link {
    link: imu_link::Link,
    pub got: Collected,
}

impl Link {
    /// Connects to the emulator's port on this machine, waiting up to `timeout` for it to listen.
    pub fn connect(port: u16, timeout: Duration) -> Result<Link> {
        let addr = format!("tcp:127.0.0.1:{port}");
        let start = Instant::now();
        loop {
            match imu_link::Link::open(&addr) {
                Ok(link) => {
                    return Ok(Link {
                        link,
                        got: Collected::default(),
                    })
                }
                Err(_) if start.elapsed() < timeout => {
                    std::thread::sleep(Duration::from_millis(100))
                }
                Err(e) => return Err(e.context("connecting to the emulated USB port")),
            }
        }
    }

    /// Sends `req` and waits (wall time) for its reply, collecting everything else meanwhile.
    pub fn request(&mut self, req: Request, timeout: Duration) -> Result<Reply> {
        let got = &mut self.got;
        self.link.request_with(req, timeout, |m| got.take(m))
    }

    /// Collects device traffic until `done` says so or the timeout.
    pub fn wait_until(
        &mut self,
        timeout: Duration,
        what: &str,
        mut done: impl FnMut(&Collected) -> bool,
    ) -> Result<()> {
        let start = Instant::now();
        let mut next_note = crate::PROGRESS_EVERY;
        while !done(&self.got) {
            if start.elapsed() > timeout {
                bail!("timed out after {timeout:?} waiting for {what}");
            }
            if start.elapsed() >= next_note {
                crate::progress_line(crate::progress(
                    &format!("waiting for {what}"),
                    start.elapsed(),
                ));
                next_note += crate::PROGRESS_EVERY;
            }
            if let Some(m) = self.link.recv(POLL)? {
                self.got.take(m);
            }
        }
        Ok(())
    }
}
