//! The host end of the device link: imu-proto frames over a serial port (a real Pico's USB CDC,
//! e.g. `/dev/ttyACM0`) or over TCP (`tcp:HOST:PORT`, the emulator harness's CDC bridge).
//!
//! Corrupt or unknown frames from the device are counted ([`Link::rx_stats`]) and skipped, never
//! fatal: the stream resynchronises at the next frame delimiter.
use std::collections::VecDeque;
use std::io::{ErrorKind, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use imu_proto::{
    DeviceMsg, FrameEncoder, FrameReader, HostFrame, Reply, Request, RxStats, MAX_FRAME,
};

/// Default wait for a reply.
pub const REPLY_TIMEOUT: Duration = Duration::from_secs(3);

/// How long one read blocks before the caller gets control back.
const POLL: Duration = Duration::from_millis(50);

/// `--port` argument shared by the device commands.
#[derive(clap::Args, Debug, Clone)]
pub struct PortArgs {
    /// Serial device of the Pico (e.g. /dev/ttyACM0, COM5) or `tcp:HOST:PORT` for the emulator
    /// (accepted before or after a `device` subcommand).
    #[arg(long, global = true)]
    pub port: Option<String>,
}

impl PortArgs {
    /// Open the port given with `--port`.
    pub fn open(&self) -> Result<Link> {
        match &self.port {
            Some(p) => Link::open(p),
            None => bail!("--port is required: a serial device (e.g. /dev/ttyACM0) or tcp:HOST:PORT for the emulator"),
        }
    }
}

trait Port: Read + Write + Send {}
impl<T: Read + Write + Send> Port for T {}

/// An open link to a device.
pub struct Link {
    name: String,
    io: Box<dyn Port>,
    reader: Box<FrameReader<MAX_FRAME>>,
    enc: Box<FrameEncoder>,
    next_id: u16,
    queue: VecDeque<DeviceMsg>,
    buf: Vec<u8>,
}

impl Link {
    /// Open `port`: `tcp:HOST:PORT`, or a serial device path.
    pub fn open(port: &str) -> Result<Link> {
        let io: Box<dyn Port> = if let Some(addr) = port.strip_prefix("tcp:") {
            let s = TcpStream::connect(addr)
                .with_context(|| format!("connecting to the emulator at {addr}"))?;
            s.set_read_timeout(Some(POLL))?;
            s.set_nodelay(true)?;
            Box::new(s)
        } else {
            // The baud rate is ignored by USB CDC; 115200 is a conventional placeholder.
            let p = serialport::new(port, 115_200)
                .timeout(POLL)
                .open()
                .with_context(|| format!("opening serial port {port}"))?;
            Box::new(p)
        };
        Ok(Link {
            name: port.to_string(),
            io,
            reader: Box::new(FrameReader::new()),
            enc: Box::new(FrameEncoder::new()),
            next_id: 1,
            queue: VecDeque::new(),
            buf: vec![0u8; 4096],
        })
    }

    /// The port name given to [`Link::open`].
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Frames received so far, by outcome (rejected ones were skipped).
    pub fn rx_stats(&self) -> RxStats {
        self.reader.stats()
    }

    /// Send a request; returns its id.
    pub fn send(&mut self, req: Request) -> Result<u16> {
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1).max(1);
        let mut out = vec![0u8; MAX_FRAME];
        let n = self
            .enc
            .encode(&HostFrame { id, req }, &mut out)
            .map_err(|e| anyhow!("encoding request: {e}"))?;
        self.io
            .write_all(&out[..n])
            .with_context(|| format!("writing to {}", self.name))?;
        self.io.flush().ok();
        Ok(id)
    }

    /// Read what is available (blocking at most one poll interval) into the queue.
    fn fill(&mut self) -> Result<()> {
        let n = match self.io.read(&mut self.buf) {
            Ok(0) => bail!("{} closed the connection", self.name),
            Ok(n) => n,
            Err(e)
                if matches!(
                    e.kind(),
                    ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
                ) =>
            {
                0
            }
            Err(e) => return Err(e).with_context(|| format!("reading from {}", self.name)),
        };
        let queue = &mut self.queue;
        self.reader.feed::<DeviceMsg>(&self.buf[..n], |r| match r {
            Ok(m) => queue.push_back(m),
            Err(e) => eprintln!("warning: rejected a frame from the device: {e}"),
        });
        Ok(())
    }

    /// The next device message, or `None` after `timeout`.
    pub fn recv(&mut self, timeout: Duration) -> Result<Option<DeviceMsg>> {
        let until = Instant::now() + timeout;
        loop {
            if let Some(m) = self.queue.pop_front() {
                return Ok(Some(m));
            }
            if Instant::now() >= until {
                return Ok(None);
            }
            self.fill()?;
        }
    }

    /// Send `req` and wait for its reply; other messages that arrive meanwhile are passed to
    /// `other` (streamed samples, tables, status, events).
    pub fn request_with(
        &mut self,
        req: Request,
        timeout: Duration,
        mut other: impl FnMut(DeviceMsg),
    ) -> Result<Reply> {
        let what = format!("{req:?}");
        let id = self.send(req)?;
        let until = Instant::now() + timeout;
        loop {
            let left = until.saturating_duration_since(Instant::now());
            match self.recv(left)? {
                Some(DeviceMsg::Reply { id: rid, reply }) if rid == id => return Ok(reply),
                Some(m) => other(m),
                None => bail!(
                    "no reply from {} to {} within {:.1} s (is the firmware running and the port right?)",
                    self.name,
                    short(&what),
                    timeout.as_secs_f64()
                ),
            }
        }
    }

    /// Send `req` and wait for its reply, ignoring other traffic.
    pub fn request(&mut self, req: Request) -> Result<Reply> {
        self.request_with(req, REPLY_TIMEOUT, |_| {})
    }

    /// Send `req` and require `Reply::Ok`.
    pub fn request_ok(&mut self, req: Request) -> Result<()> {
        match self.request(req)? {
            Reply::Ok => Ok(()),
            Reply::Error(e) => bail!("the device refused: {e:?}"),
            other => bail!("unexpected reply {other:?}"),
        }
    }
}

fn short(s: &str) -> &str {
    s.split(['{', '(']).next().unwrap_or(s).trim()
}
