//! `imu-lab serve`: the lab as a local web app (the server is `crate::serve`; docs/serve.md).
use std::net::SocketAddr;
use std::path::PathBuf;

use anyhow::{bail, Result};

use crate::serve::{self, Source};

/// Arguments of `imu-lab serve`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// A recording (CSV in the contract) to open in the noise lab.
    #[arg(required_unless_present = "port", conflicts_with = "port")]
    pub file: Option<PathBuf>,
    /// A live device instead: serial port of the Pico (e.g. /dev/ttyACM0) or tcp:HOST:PORT for
    /// the emulator.
    #[arg(long)]
    pub port: Option<String>,
    /// Where the live page's recordings are written (live mode).
    #[arg(long, default_value = ".", requires = "port")]
    pub record_dir: PathBuf,
    /// Address and port to listen on (port 0: any free port; the URL is printed). Another
    /// address than a loopback one exposes the page to the network.
    #[arg(long, default_value = "127.0.0.1:8750")]
    pub listen: SocketAddr,
}

pub fn run(args: Args) -> Result<()> {
    let source = match (args.file, args.port) {
        (Some(file), None) => Source::File(file),
        (None, Some(port)) => Source::Port {
            port,
            record_dir: args.record_dir,
        },
        _ => bail!("give a recording or --port, one of the two"),
    };
    serve::serve(args.listen, source)
}
