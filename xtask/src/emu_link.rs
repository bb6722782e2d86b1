//! A host link to the device over the emulator's TCP port (or any byte stream), speaking the
//! imu-proto frames: requests with ids, replies matched by id, everything else collected.
use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use imu_proto::{
    AllanTable, DeviceMsg, Event, FrameEncoder, FrameReader, HostFrame, Reply, Request,
    SampleBatch, Status, MAX_FRAME,
};

/// What the device sent besides replies.
#[derive(Default)]
pub struct Collected {
    /// Latest table per channel index.
    pub tables: BTreeMap<usize, AllanTable>,
    pub statuses: Vec<Status>,
    pub events: Vec<Event>,
    pub batches: Vec<SampleBatch>,
    pub rejected_frames: u32,
}

pub struct Link {
    sock: TcpStream,
    enc: FrameEncoder,
    reader: Box<FrameReader<MAX_FRAME>>,
    next_id: u16,
    pub got: Collected,
    pending_replies: BTreeMap<u16, Reply>,
}

impl Link {
    pub fn connect(port: u16, timeout: Duration) -> Result<Link> {
        let addr = format!("127.0.0.1:{port}");
        let start = Instant::now();
        let sock = loop {
            match TcpStream::connect(&addr) {
                Ok(s) => break s,
                Err(e) if start.elapsed() < timeout => {
                    let _ = e;
                    std::thread::sleep(Duration::from_millis(100));
                }
                Err(e) => {
                    return Err(e)
                        .with_context(|| format!("connecting to the emulated USB port {addr}"))
                }
            }
        };
        sock.set_nodelay(true)?;
        sock.set_read_timeout(Some(Duration::from_millis(200)))?;
        Ok(Link {
            sock,
            enc: FrameEncoder::new(),
            reader: Box::new(FrameReader::new()),
            next_id: 1,
            got: Collected::default(),
            pending_replies: BTreeMap::new(),
        })
    }

    /// Reads what is available (waits at most the socket's 200 ms read timeout).
    /// Returns false when the device side closed the port.
    pub fn pump(&mut self) -> Result<bool> {
        let mut buf = [0u8; 4096];
        let n = match self.sock.read(&mut buf) {
            Ok(0) => return Ok(false),
            Ok(n) => n,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                return Ok(true)
            }
            Err(e) => return Err(e).context("reading the emulated USB port"),
        };
        let mut msgs = Vec::new();
        let mut rejected = 0;
        self.reader.feed::<DeviceMsg>(&buf[..n], |r| match r {
            Ok(m) => msgs.push(m),
            Err(_) => rejected += 1,
        });
        self.got.rejected_frames += rejected;
        let debug = std::env::var_os("XTASK_EMU_DEBUG").is_some();
        for m in msgs {
            if debug {
                let kind = match &m {
                    DeviceMsg::Reply { id, reply } => format!("reply {id} {reply:?}"),
                    DeviceMsg::Samples(b) => {
                        format!("samples imu={} mag={}", b.imu.len(), b.mag.len())
                    }
                    DeviceMsg::Table(t) => {
                        format!("table {} pushed={}", t.channel.name(), t.pushed)
                    }
                    DeviceMsg::Status(s) => format!("status uptime={} µs", s.uptime_us),
                    DeviceMsg::Event(e) => format!("event {e:?}"),
                };
                eprintln!("xtask: <- {kind}");
            }
            match m {
                DeviceMsg::Reply { id, reply } => {
                    self.pending_replies.insert(id, reply);
                }
                DeviceMsg::Samples(b) => self.got.batches.push(b),
                DeviceMsg::Table(t) => {
                    self.got.tables.insert(t.channel.index(), t);
                }
                DeviceMsg::Status(s) => self.got.statuses.push(s),
                DeviceMsg::Event(e) => self.got.events.push(e),
            }
        }
        Ok(true)
    }

    pub fn send(&mut self, req: Request) -> Result<u16> {
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1);
        let frame = self
            .enc
            .encode_vec(&HostFrame { id, req })
            .map_err(|e| anyhow::anyhow!("encoding a request: {e}"))?;
        self.sock
            .write_all(&frame)
            .context("writing the emulated USB port")?;
        Ok(id)
    }

    /// Sends `req` and waits (wall time) for its reply, collecting everything else meanwhile.
    pub fn request(&mut self, req: Request, timeout: Duration) -> Result<Reply> {
        let what = format!("{req:?}");
        let id = self.send(req)?;
        let start = Instant::now();
        loop {
            if let Some(r) = self.pending_replies.remove(&id) {
                return Ok(r);
            }
            if start.elapsed() > timeout {
                bail!("no reply to {what} within {timeout:?} (wall time)");
            }
            if !self.pump()? {
                bail!("the device port closed while waiting for the reply to {what}");
            }
        }
    }

    /// Pumps until `done(self)` or the timeout.
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
            if !self.pump()? {
                bail!("the device port closed while waiting for {what}");
            }
        }
        Ok(())
    }
}
