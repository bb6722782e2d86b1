//! `imu-lab`: the pico-imu host lab. Each subcommand lives in `cmd/<name>.rs` and stays thin
//! over the library crates.
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

mod calibration;
mod cmd;
mod input;
mod link;
mod render;
mod serve;

#[derive(Parser)]
#[command(
    name = "imu-lab",
    version,
    about = "Characterise and calibrate low-cost IMUs"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Allan-family deviation of one column, with 68.3 % confidence bounds.
    Adev(cmd::adev::Args),
    /// Record samples from the device (or the emulator) into a CSV in the contract.
    Record(cmd::record::Args),
    /// Talk to the device: status, Allan tables, calibration, streaming mode.
    Device(cmd::device::Args),
    /// Calibration lab: fit accel/gyro/mag error models, diagnose the missing effect.
    Calibrate(cmd::calibrate::Args),
    /// Noise-model lab: fit Allan terms with uncertainties, judge the model, name the missing effect.
    Fit(cmd::fit::Args),
    /// Heading error before and after a calibration, on one raw recording (against a truth or
    /// the gyro).
    Heading(cmd::heading::Args),
    /// Simulate IMU rate data with any mix of noise effects, as CSV in the contract.
    Simulate(cmd::simulate::Args),
    /// Export noise parameters for other tools (Kalibr imu.yaml).
    Export(cmd::export::Args),
    /// The lab in the browser: a local web app on a recording (noise lab) or a live device
    /// (status, its Allan tables, the stream, recording, magnetometer calibration).
    Serve(cmd::serve::Args),
}

/// The command line, with negative numbers taken as values everywhere (`--rate -100` is then
/// refused as a rate, not as an unknown flag `-1`).
fn command_line() -> clap::Command {
    fn negatives(c: clap::Command) -> clap::Command {
        c.mut_args(|a| {
            let values = a.get_action().takes_values();
            a.allow_negative_numbers(values)
        })
        .mut_subcommands(negatives)
    }
    negatives(Cli::command())
}

fn main() {
    quiet_on_closed_pipe();
    let cli = Cli::from_arg_matches(&command_line().get_matches()).unwrap_or_else(|e| e.exit());
    let result = match cli.command {
        Command::Adev(a) => cmd::adev::run(a),
        Command::Record(a) => cmd::record::run(a),
        Command::Device(a) => cmd::device::run(a),
        Command::Fit(a) => cmd::fit::run(a),
        Command::Simulate(a) => cmd::simulate::run(a),
        Command::Export(a) => cmd::export::run(a),
        Command::Calibrate(a) => cmd::calibrate::run(a),
        Command::Heading(a) => cmd::heading::run(a),
        Command::Serve(a) => cmd::serve::run(a),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

/// `imu-lab … | head`: when the reader closes the pipe, the next print to stdout panics in std
/// ("failed printing to stdout: Broken pipe"); the output nobody reads is simply not written, so
/// the tool stops quietly with success, as command-line tools do. Every other panic is reported
/// as before.
fn quiet_on_closed_pipe() {
    let report = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let msg = payload
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| payload.downcast_ref::<&str>().copied())
            .unwrap_or("");
        if msg.contains("failed printing to stdout") && msg.contains("Broken pipe") {
            std::process::exit(0);
        }
        report(info);
    }));
}
