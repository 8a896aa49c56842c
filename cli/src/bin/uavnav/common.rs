//! What every subcommand shares: the error type that carries an exit code, and a progress bar.

use std::process::ExitCode;

/// A command failure with the exit code it maps to.
#[derive(Debug)]
pub enum CliError {
    /// Bad usage or bad input: exit 2.
    Input(anyhow::Error),
    /// Run-time failure: exit 1.
    Runtime(anyhow::Error),
    /// A checked target was missed: exit 3.
    Target(String),
}

impl CliError {
    /// Bad input, with a one-line reason.
    pub fn input(e: impl Into<anyhow::Error>) -> Self {
        CliError::Input(e.into())
    }

    /// A run-time failure.
    pub fn runtime(e: impl Into<anyhow::Error>) -> Self {
        CliError::Runtime(e.into())
    }
}

impl From<anyhow::Error> for CliError {
    fn from(e: anyhow::Error) -> Self {
        CliError::Runtime(e)
    }
}

/// The result of one subcommand.
pub type CliResult = Result<(), CliError>;

/// Prints the one-line reason (with its causes) and maps to the exit code.
pub fn finish(result: CliResult) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(CliError::Input(e)) => {
            eprintln!("uavnav: error: {}", chain(&e));
            ExitCode::from(2)
        }
        Err(CliError::Runtime(e)) => {
            eprintln!("uavnav: error: {}", chain(&e));
            ExitCode::from(1)
        }
        Err(CliError::Target(msg)) => {
            eprintln!("uavnav: target missed: {msg}");
            ExitCode::from(3)
        }
    }
}

fn chain(e: &anyhow::Error) -> String {
    e.chain()
        .map(|c| c.to_string())
        .collect::<Vec<_>>()
        .join(": ")
}

/// A progress bar on stderr (hidden when stderr is not a terminal).
pub fn progress(len: u64, what: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len);
    let style = indicatif::ProgressStyle::with_template("{msg:>10} [{bar:40}] {pos}/{len} ({eta})")
        .map(|s| s.progress_chars("=> "))
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar());
    bar.set_style(style);
    bar.set_message(what.to_string());
    bar
}

/// How to read a dataset that may be a flight log (shared by `convert`, `estimate`, `replay` and
/// `loadtest`, so a log is usable wherever a dataset is).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ReadArgs {
    /// GNSS delay, s (a fix stamped t was valid at t − delay), replacing the dataset's: for a
    /// flight log the autopilot's own parameter (ArduPilot EK3_GPS_DELAY / EK2_GPS_DELAY /
    /// EKF_POS_DELAY, PX4 EKF2_GPS_DELAY); for ASL gnss0/sensor.yaml `delay_s`. Fixes keep their
    /// logged stamps; the `eskf` profile fuses each fix at its stamp less the delay and then
    /// learns the GNSS velocity's own delay from the data (`estimate` prints it when it
    /// differs); `paper`, like the paper's filters, fuses a fix when it arrives.
    #[arg(long, value_name = "SECONDS")]
    pub gnss_delay_s: Option<f64>,
    /// Flight logs: import what comes before the first corrupt byte instead of failing with the
    /// byte offset. A log that merely ends inside a message (cut by a power loss) is always read
    /// up to its last whole message, with a note on stderr.
    #[arg(long)]
    pub stop_at_damage: bool,
}

impl ReadArgs {
    /// The dataset read options.
    pub fn options(&self) -> uavnav_dataset::ReadOptions {
        uavnav_dataset::ReadOptions {
            gnss_delay_s: self.gnss_delay_s,
            stop_at_damage: self.stop_at_damage,
            ..uavnav_dataset::ReadOptions::default()
        }
    }
}

/// Prints a dataset's reader notes (a flight log's: rows dropped, assumptions, where a damaged log
/// was cut) on stderr.
pub fn print_notes(ds: &uavnav_dataset::Dataset) {
    for note in ds.notes() {
        eprintln!("uavnav: {}: {note}", ds.path().display());
    }
}

/// A dataset that could not be opened: bad input (exit 2). A damaged flight log's one-line reason
/// (with its byte offset) gets the option that imports the part before the damage.
pub fn open_error(e: uavnav_dataset::DatasetError) -> CliError {
    let damaged = matches!(
        &e,
        uavnav_dataset::DatasetError::Log { error, .. } if error.offset().is_some()
    );
    if damaged {
        CliError::input(anyhow::anyhow!(
            "{e} (--stop-at-damage imports the log up to there)"
        ))
    } else {
        CliError::input(e)
    }
}
