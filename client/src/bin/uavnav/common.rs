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
