//! The host end of the device link (used by `imu-lab`, by `pico_imu.Device` and by the emulator
//! harness, `cargo xtask`): imu-proto frames over a serial port (a real Pico's USB CDC, e.g.
//! `/dev/ttyACM0`) or over TCP (`tcp:HOST:PORT`, the emulator harness's CDC bridge). On top of
//! [`Link`]: [`device`], the requests as the host's tools make them (replies checked, tables
//! read from their sums, argument checks shared), and [`record`], a recording's rows and the
//! accounts of what was lost.
//!
//! Corrupt or unknown frames from the device are counted ([`Link::rx_stats`]) and skipped, never
//! fatal: the stream resynchronises at the next frame delimiter. They are reported in one
//! warning per second at most, counted by reason. A frame whose CRC holds but whose protocol
//! version is not this build's ends the link with both versions named: every later frame would
//! be refused the same way.
//!
//! ```
//! use std::io::{Cursor, Read, Write};
//! use std::sync::{Arc, Mutex};
//! use std::time::Duration;
//! use imu_link::Link;
//! use imu_proto::{decode, DeviceMsg, FrameEncoder, HostFrame, Reply, Request, MAX_FRAME};
//!
//! /// A device that has already answered: its bytes to read, what the host wrote.
//! struct Scripted(Cursor<Vec<u8>>, Arc<Mutex<Vec<u8>>>);
//! impl Read for Scripted {
//!     fn read(&mut self, b: &mut [u8]) -> std::io::Result<usize> { self.0.read(b) }
//! }
//! impl Write for Scripted {
//!     fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
//!         self.1.lock().unwrap().extend_from_slice(b);
//!         Ok(b.len())
//!     }
//!     fn flush(&mut self) -> std::io::Result<()> { Ok(()) }
//! }
//!
//! let frame = |m: &DeviceMsg| {
//!     let mut out = [0u8; MAX_FRAME];
//!     let n = FrameEncoder::new().encode(m, &mut out).unwrap();
//!     out[..n].to_vec()
//! };
//! // Noise on the line, a reply to someone else's request, then the reply to ours (id 1).
//! let mut rx = vec![0x13, 0x37, 0x00];
//! rx.extend(frame(&DeviceMsg::Reply { id: 99, reply: Reply::Ok }));
//! rx.extend(frame(&DeviceMsg::Reply { id: 1, reply: Reply::Ok }));
//! let wire = Arc::new(Mutex::new(Vec::new()));
//! let port = Scripted(Cursor::new(rx), wire.clone());
//! let mut link = Link::over("scripted", Box::new(port), |_| {});
//! let mut others = Vec::new();
//! let reply = link
//!     .request_with(Request::ResetAllan, Duration::from_secs(1), |m| others.push(m))
//!     .unwrap();
//! assert_eq!(reply, Reply::Ok);
//! assert_eq!(others, [DeviceMsg::Reply { id: 99, reply: Reply::Ok }]);
//! assert_eq!(link.rx_stats().rejected(), 1, "the noise, skipped and counted");
//! // What went to the device: one frame, request id 1.
//! let mut sent = wire.lock().unwrap().clone();
//! assert_eq!(sent.pop(), Some(0));
//! let req: HostFrame = decode(&mut sent).unwrap();
//! assert_eq!(req, HostFrame { id: 1, req: Request::ResetAllan });
//! ```
use std::collections::VecDeque;
use std::io::{ErrorKind, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context, Result};
use imu_proto::{
    DecodeError, DeviceMsg, FrameEncoder, FrameReader, HostFrame, Reply, Request, RxStats,
    MAX_FRAME, PROTOCOL_VERSION,
};

pub mod device;
pub mod record;

/// Default wait for a reply.
pub const REPLY_TIMEOUT: Duration = Duration::from_secs(3);

/// How long one read blocks before the caller gets control back.
const POLL: Duration = Duration::from_millis(50);

/// Rejected frames are reported at most this often.
const REJECT_REPORT_EVERY: Duration = Duration::from_secs(1);

/// No reply came in time: the device is silent, busy or not there. Carried inside the
/// `anyhow::Error` of [`Link::request_with`], so that a front end can tell a timeout from other
/// link failures (`downcast_ref`).
#[derive(Debug, Clone, PartialEq)]
pub struct NoReply {
    /// The port's name.
    pub port: String,
    /// The request, by name.
    pub request: String,
    /// How long the host waited, s.
    pub waited_s: f64,
}

impl std::fmt::Display for NoReply {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "no reply from {} to {} within {:.1} s (is the firmware running and the port right?)",
            self.port, self.request, self.waited_s
        )
    }
}

impl std::error::Error for NoReply {}

/// A byte stream a link runs over.
pub trait Port: Read + Write + Send {}
impl<T: Read + Write + Send> Port for T {}

/// An open link to a device.
pub struct Link {
    name: String,
    io: Box<dyn Port>,
    reader: Box<FrameReader<MAX_FRAME>>,
    enc: Box<FrameEncoder>,
    next_id: u16,
    /// Requests written to the port so far.
    sent: u64,
    /// How long [`Link::request`] waits for a reply.
    reply_timeout: Duration,
    queue: VecDeque<DeviceMsg>,
    buf: Vec<u8>,
    rejects: Rejections,
    /// Rejected frames are summarised at most this often.
    reject_every: Duration,
    /// Where the rejected-frame summaries go (stderr, or a test's collector).
    warn: Box<dyn FnMut(String) + Send>,
}

/// Frames rejected since the last report, by reason.
#[derive(Default)]
struct Rejections {
    since: Option<Instant>,
    /// Count per reason, in the order the reasons were first seen.
    counts: Vec<(&'static str, u32)>,
    /// A protocol version other than ours, seen in a frame whose CRC holds.
    version: Option<u8>,
}

impl Rejections {
    fn note(&mut self, e: &DecodeError, now: Instant) {
        self.since.get_or_insert(now);
        let reason = reason(e);
        match self.counts.iter_mut().find(|(r, _)| *r == reason) {
            Some((_, n)) => *n += 1,
            None => self.counts.push((reason, 1)),
        }
        if let DecodeError::Version(v) = e {
            self.version = Some(*v);
        }
    }

    /// "785 frames rejected in 3.0 s: invalid COBS (612), CRC (173)" when there is something to
    /// report and `every` has passed since the first of them (or `now` is the end); resets.
    fn report(&mut self, now: Instant, every: Duration, end: bool) -> Option<String> {
        let since = self.since?;
        let span = now.saturating_duration_since(since);
        if span < every && !end {
            return None;
        }
        let total: u32 = self.counts.iter().map(|(_, n)| n).sum();
        let reasons: Vec<String> = self
            .counts
            .iter()
            .map(|(r, n)| format!("{r} ({n})"))
            .collect();
        self.since = None;
        self.counts.clear();
        Some(format!(
            "{total} frame{} rejected in {:.1} s: {}",
            if total == 1 { "" } else { "s" },
            span.as_secs_f64(),
            reasons.join(", ")
        ))
    }
}

/// A short name for why a frame was rejected.
fn reason(e: &DecodeError) -> &'static str {
    match e {
        DecodeError::Cobs => "invalid COBS",
        DecodeError::TooShort => "too short",
        DecodeError::Oversize => "oversize",
        DecodeError::Crc { .. } => "CRC",
        DecodeError::Version(_) => "protocol version",
        DecodeError::Unknown => "unknown message",
        DecodeError::Trailing => "trailing bytes",
    }
}

/// The error for a device that speaks protocol `device`, with what to update.
fn version_mismatch(device: u8) -> anyhow::Error {
    let fix = if device < PROTOCOL_VERSION {
        "update the firmware (cargo xtask firmware, then flash out/pico-imu.uf2 or cargo run --release)"
    } else {
        "update imu-lab (or flash a firmware of the same version)"
    };
    anyhow!("device speaks protocol {device}, this imu-lab speaks {PROTOCOL_VERSION}: {fix}")
}

impl Link {
    /// Open `port`: `tcp:HOST:PORT`, or a serial device path; rejected-frame summaries go to
    /// stderr.
    pub fn open(port: &str) -> Result<Link> {
        Link::open_with(port, |w| eprintln!("warning: {w}"))
    }

    /// [`Link::open`] with the rejected-frame summaries handed to `warn`.
    pub fn open_with(port: &str, warn: impl FnMut(String) + Send + 'static) -> Result<Link> {
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
        Ok(Link::over(port, io, warn))
    }

    /// A link over any byte stream; `warn` receives the rejected-frame summaries.
    pub fn over(name: &str, io: Box<dyn Port>, warn: impl FnMut(String) + Send + 'static) -> Link {
        Link {
            name: name.to_string(),
            io,
            reader: Box::new(FrameReader::new()),
            enc: Box::new(FrameEncoder::new()),
            next_id: 1,
            sent: 0,
            reply_timeout: REPLY_TIMEOUT,
            queue: VecDeque::new(),
            buf: vec![0u8; 4096],
            rejects: Rejections::default(),
            reject_every: REJECT_REPORT_EVERY,
            warn: Box::new(warn),
        }
    }

    /// Hands the rejected-frame summary to `warn` when one is due (or `end`).
    fn report_rejects(&mut self, end: bool) {
        if let Some(r) = self.rejects.report(Instant::now(), self.reject_every, end) {
            (self.warn)(format!("{}: {r}", self.name));
        }
    }

    /// The port name given to [`Link::open`] (or [`Link::over`]).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Frames received so far, by outcome (rejected ones were skipped).
    pub fn rx_stats(&self) -> RxStats {
        self.reader.stats()
    }

    /// How long [`Link::request`] waits for a reply ([`REPLY_TIMEOUT`] unless set).
    pub fn reply_timeout(&self) -> Duration {
        self.reply_timeout
    }

    /// Sets how long [`Link::request`] waits for a reply.
    pub fn set_reply_timeout(&mut self, timeout: Duration) {
        self.reply_timeout = timeout;
    }

    /// Requests written to the device so far (a front end's proof that a refused request was
    /// never sent).
    pub fn requests_sent(&self) -> u64 {
        self.sent
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
        self.sent += 1;
        self.io.flush().ok();
        Ok(id)
    }

    /// Read what is available (blocking at most one poll interval) into the queue.
    fn fill(&mut self) -> Result<()> {
        let n = match self.io.read(&mut self.buf) {
            Ok(0) => return Err(anyhow!("{} closed the connection", self.name)),
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
        let rejects = &mut self.rejects;
        let now = Instant::now();
        self.reader.feed::<DeviceMsg>(&self.buf[..n], |r| match r {
            Ok(m) => queue.push_back(m),
            Err(e) => rejects.note(&e, now),
        });
        if let Some(v) = self.rejects.version {
            self.report_rejects(true);
            return Err(version_mismatch(v));
        }
        self.report_rejects(false);
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
                None => {
                    return Err(NoReply {
                        port: self.name.clone(),
                        request: short(&what).to_string(),
                        waited_s: timeout.as_secs_f64(),
                    }
                    .into())
                }
            }
        }
    }

    /// Send `req` and wait for its reply ([`Link::reply_timeout`]), ignoring other traffic.
    pub fn request(&mut self, req: Request) -> Result<Reply> {
        self.request_with(req, self.reply_timeout, |_| {})
    }

    /// Send `req` and require `Reply::Ok`.
    pub fn request_ok(&mut self, req: Request) -> Result<()> {
        match self.request(req)? {
            Reply::Ok => Ok(()),
            Reply::Error(e) => Err(anyhow!("the device refused: {e:?}")),
            other => Err(anyhow!("unexpected reply {other:?}")),
        }
    }
}

impl Drop for Link {
    /// Rejections not yet reported are reported when the link closes.
    fn drop(&mut self) {
        self.report_rejects(true);
    }
}

fn short(s: &str) -> &str {
    s.split(['{', '(']).next().unwrap_or(s).trim()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::{Arc, Mutex};

    /// A device that sends the given chunks, one per read; an empty chunk is a read that times
    /// out after 60 ms with nothing.
    struct Mock {
        chunks: VecDeque<Vec<u8>>,
    }

    impl Read for Mock {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            match self.chunks.pop_front() {
                Some(c) if !c.is_empty() => {
                    buf[..c.len()].copy_from_slice(&c);
                    Ok(c.len())
                }
                Some(_) => {
                    std::thread::sleep(Duration::from_millis(60));
                    Err(ErrorKind::TimedOut.into())
                }
                None => {
                    std::thread::sleep(Duration::from_millis(5));
                    Err(ErrorKind::TimedOut.into())
                }
            }
        }
    }

    impl Write for Mock {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    fn link(chunks: Vec<Vec<u8>>) -> (Link, Arc<Mutex<Vec<String>>>) {
        let said = Arc::new(Mutex::new(Vec::new()));
        let s = said.clone();
        let mock = Mock {
            chunks: chunks.into(),
        };
        let l = Link::over("mock", Box::new(mock), move |w| s.lock().unwrap().push(w));
        (l, said)
    }

    /// `COBS(content | crc) 0x00`, with the CRC of `content` plus `crc_error`.
    fn frame(content: &[u8], crc_error: u32) -> Vec<u8> {
        let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(content) ^ crc_error;
        let mut raw = content.to_vec();
        raw.extend_from_slice(&crc.to_le_bytes());
        let mut out = vec![0u8; raw.len() + raw.len() / 254 + 2];
        let n = imu_proto::cobs_encode(&raw, &mut out).unwrap();
        out.truncate(n);
        out.push(0);
        out
    }

    fn reply_ok(id: u16) -> Vec<u8> {
        FrameEncoder::new()
            .encode_vec(&DeviceMsg::Reply {
                id,
                reply: Reply::Ok,
            })
            .unwrap()
    }

    /// 70 bad frames give one line with the count per reason, not 70 warnings, and do not
    /// stop the reply behind them.
    #[test]
    fn rejected_frames_are_summarised_by_reason() {
        let mut chunk = Vec::new();
        for _ in 0..50 {
            chunk.extend_from_slice(&[0x05, 0x01, 0x00]); // COBS: 4 bytes promised, 1 given
        }
        for _ in 0..20 {
            chunk.extend(frame(&[PROTOCOL_VERSION, 0, 1, 0], 1));
        }
        chunk.extend(reply_ok(1));
        let (mut l, said) = link(vec![chunk]);
        assert_eq!(l.request(Request::Identify).unwrap(), Reply::Ok);
        assert!(
            said.lock().unwrap().is_empty(),
            "reported before a second passed"
        );
        assert_eq!(l.rx_stats().rejected(), 70);
        drop(l);
        assert_eq!(
            *said.lock().unwrap(),
            ["mock: 70 frames rejected in 0.0 s: invalid COBS (50), CRC (20)"]
        );
    }

    /// Rejections further apart than the report interval are reported separately.
    #[test]
    fn rejections_are_reported_once_per_interval() {
        let cobs = [0x05u8, 0x01, 0x00];
        let crc = frame(&[PROTOCOL_VERSION, 0, 1, 0], 0x100).repeat(2);
        // Two reads within the interval, a quiet read past it, then two more bad frames.
        let chunks = vec![cobs.repeat(2), cobs.to_vec(), vec![], crc, reply_ok(1)];
        let (mut l, said) = link(chunks);
        l.reject_every = Duration::from_millis(50);
        assert_eq!(l.request(Request::Identify).unwrap(), Reply::Ok);
        drop(l);
        let said = said.lock().unwrap();
        assert_eq!(said.len(), 2, "{said:?}");
        assert!(said[0].starts_with("mock: 3 frames rejected in 0."));
        assert!(said[0].ends_with(" s: invalid COBS (3)"), "{}", said[0]);
        assert_eq!(said[1], "mock: 2 frames rejected in 0.0 s: CRC (2)");
    }

    /// A device of another protocol version is named with both versions and what to update,
    /// at its first frame rather than after the reply timeout.
    #[test]
    fn a_protocol_mismatch_names_both_versions() {
        let older = PROTOCOL_VERSION - 1;
        let (mut l, _) = link(vec![frame(&[older, 0, 1, 0], 0)]);
        let start = Instant::now();
        let e = l.request(Request::Identify).unwrap_err().to_string();
        assert!(start.elapsed() < REPLY_TIMEOUT);
        assert_eq!(
            e,
            format!(
                "device speaks protocol {older}, this imu-lab speaks {PROTOCOL_VERSION}: update the firmware (cargo xtask firmware, then flash out/pico-imu.uf2 or cargo run --release)"
            )
        );
        let newer = PROTOCOL_VERSION + 1;
        let (mut l, _) = link(vec![frame(&[newer, 0, 1, 0], 0)]);
        let e = l.recv(Duration::from_secs(1)).unwrap_err().to_string();
        assert!(
            e.starts_with(&format!(
                "device speaks protocol {newer}, this imu-lab speaks {PROTOCOL_VERSION}: update imu-lab"
            )),
            "{e}"
        );
    }
}
