//! `tracing` setup: human-readable or JSON lines, filter from `RUST_LOG` or the config.
//!
//! Secrets stay out of the log: Zenoh's own crates print their whole configuration (credentials
//! and key paths included) at debug level, so unless the filter names Zenoh explicitly they are
//! capped at info (`zenoh` matches every `zenoh*` target). Values that come from the network
//! (vehicle ids, key chunks, reasons) are logged with `?` (quoted, control characters escaped), so
//! a key with a newline cannot forge a log line.

use tracing_subscriber::EnvFilter;

use crate::config::LogConfig;

/// The filter directives actually used: `filter`, plus `zenoh=info` unless it names Zenoh.
pub fn directives(filter: &str) -> String {
    if filter.contains("zenoh") {
        filter.to_string()
    } else if filter.trim().is_empty() {
        "zenoh=info".to_string()
    } else {
        format!("{filter},zenoh=info")
    }
}

/// Installs the global subscriber (a second call is a no-op).
pub fn init(cfg: &LogConfig) {
    let from_env = std::env::var("RUST_LOG")
        .ok()
        .filter(|v| !v.trim().is_empty());
    let filter = EnvFilter::try_new(directives(from_env.as_deref().unwrap_or(&cfg.filter)))
        .unwrap_or_else(|_| EnvFilter::new(directives(&cfg.filter)));
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr);
    let _ = if cfg.json {
        builder.json().try_init()
    } else {
        builder.try_init()
    };
}

#[cfg(test)]
mod tests {
    use super::directives;

    #[test]
    fn zenoh_is_capped_unless_named() {
        assert_eq!(directives("debug"), "debug,zenoh=info");
        assert_eq!(directives("debug,zenoh=trace"), "debug,zenoh=trace");
        assert_eq!(directives(""), "zenoh=info");
    }
}
