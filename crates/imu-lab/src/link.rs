//! The device link ([`imu_link`]) and the `--port` argument of the device commands.
use anyhow::{bail, Result};
pub use imu_link::Link;

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
