//! `imu-lab serve`: the lab as a local web app (the server is `crate::serve`; docs/serve.md).
use std::net::SocketAddr;
use std::path::PathBuf;

use anyhow::{bail, Result};

use crate::serve::{self, Source};

/// Arguments of `imu-lab serve`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// A recording to open in the noise lab: any CSV `imu-lab fit` reads (with the same
    /// options below to select, rename and scale its columns).
    #[arg(required_unless_present = "port", conflicts_with = "port")]
    pub file: Option<PathBuf>,
    /// Sample rate in Hz (default: from the `t` column; must agree with it within 1 %).
    #[arg(long, conflicts_with = "port")]
    pub rate: Option<f64>,
    /// Ignore the `t` column: the rows are consecutive samples at --rate.
    #[arg(long, conflicts_with = "port")]
    pub ignore_time: bool,
    /// Metadata lines to skip before the header row.
    #[arg(long, default_value_t = 0, conflicts_with = "port")]
    pub skip_lines: usize,
    /// Multiply the sensor columns by this factor (e.g. 0.0076336 for ±250 °/s counts); without
    /// --unit the result is in the contract's unit for the name.
    #[arg(long, conflicts_with = "port")]
    pub scale: Option<f64>,
    /// Unit of the sensor columns (after --scale), e.g. deg/s, LSB.
    #[arg(long, conflicts_with = "port")]
    pub unit: Option<String>,
    /// Rename columns onto the contract, OLD=NEW (comma-separated or repeated), e.g. gyro_z=gz.
    #[arg(long, value_delimiter = ',', conflicts_with = "port")]
    pub rename: Vec<String>,
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
        (Some(file), None) => Source::File(crate::input::InputArgs {
            file,
            rate: args.rate,
            ignore_time: args.ignore_time,
            skip_lines: args.skip_lines,
            scale: args.scale,
            unit: args.unit,
            rename: args.rename,
        }),
        (None, Some(port)) => Source::Port {
            port,
            record_dir: args.record_dir,
        },
        _ => bail!("give a recording or --port, one of the two"),
    };
    serve::serve(args.listen, source)
}
