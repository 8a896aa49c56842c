//! `uavnav loadtest --metrics URL`: the service's own CPU time and resident memory, read from its
//! Prometheus `/metrics` (`uavnav_process_cpu_seconds_total`,
//! `uavnav_process_resident_memory_bytes`) before and after a run, so that the cost per input
//! the service accepted comes out of the run itself rather than from `/proc` by hand. Plain HTTP
//! (the side port's default); a scrape that fails is reported and leaves the run's verdict alone.

use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// Longest a scrape may take.
const SCRAPE_TIMEOUT: Duration = Duration::from_secs(5);
/// Most bytes read of a `/metrics` answer.
const MAX_ANSWER_BYTES: u64 = 16 << 20;

/// The service process's figures at one scrape.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServiceProcess {
    /// CPU time so far, s.
    pub cpu_s: f64,
    /// Resident memory, bytes.
    pub resident_bytes: f64,
}

/// `http://HOST:PORT/PATH` → (`HOST:PORT`, `/PATH`).
fn split_url(url: &str) -> Result<(&str, &str), String> {
    let rest = url
        .strip_prefix("http://")
        .ok_or_else(|| format!("--metrics {url:?}: expected http://HOST:PORT/PATH (plain HTTP)"))?;
    Ok(match rest.find('/') {
        Some(i) => (&rest[..i], &rest[i..]),
        None => (rest, "/metrics"),
    })
}

/// The value of the sample `name` (no labels) in a Prometheus text exposition.
pub fn sample(text: &str, name: &str) -> Option<f64> {
    text.lines()
        .filter_map(|l| l.strip_prefix(name))
        .find_map(|v| v.strip_prefix(' ')?.trim().parse().ok())
}

/// Scrapes `url` once.
pub async fn scrape(url: &str) -> Result<ServiceProcess, String> {
    let (authority, path) = split_url(url)?;
    let get = async {
        let mut s = tokio::net::TcpStream::connect(authority)
            .await
            .map_err(|e| format!("{url}: {e}"))?;
        let request =
            format!("GET {path} HTTP/1.1\r\nHost: {authority}\r\nConnection: close\r\n\r\n");
        s.write_all(request.as_bytes())
            .await
            .map_err(|e| format!("{url}: {e}"))?;
        let mut answer = Vec::new();
        s.take(MAX_ANSWER_BYTES)
            .read_to_end(&mut answer)
            .await
            .map_err(|e| format!("{url}: {e}"))?;
        Ok::<_, String>(String::from_utf8_lossy(&answer).into_owned())
    };
    let answer = tokio::time::timeout(SCRAPE_TIMEOUT, get)
        .await
        .map_err(|_| format!("{url}: no answer within {SCRAPE_TIMEOUT:?}"))??;
    let status = answer.lines().next().unwrap_or_default();
    if !status.contains(" 200") {
        return Err(format!("{url}: {status}"));
    }
    let cpu_s = sample(&answer, "uavnav_process_cpu_seconds_total");
    let resident_bytes = sample(&answer, "uavnav_process_resident_memory_bytes");
    match (cpu_s, resident_bytes) {
        (Some(cpu_s), Some(resident_bytes)) => Ok(ServiceProcess {
            cpu_s,
            resident_bytes,
        }),
        _ => Err(format!(
            "{url}: no uavnav_process_cpu_seconds_total / uavnav_process_resident_memory_bytes \
             (a service older than these metrics, or not Linux)"
        )),
    }
}

/// The report line: CPU over the run, per accepted input, and memory at the end.
pub fn line(before: &ServiceProcess, after: &ServiceProcess, wall_s: f64, accepted: u64) -> String {
    let cpu_s = after.cpu_s - before.cpu_s;
    let per_input = if accepted > 0 {
        format!("{:.2} µs", cpu_s / accepted as f64 * 1e6)
    } else {
        "-".to_string()
    };
    format!(
        "  Service process: {cpu_s:.1} s of CPU over {wall_s:.1} s ({:.2} cores), {per_input} per \
         accepted input; {:.1} MiB resident at the end",
        cpu_s / wall_s.max(1e-9),
        after.resident_bytes / (1024.0 * 1024.0)
    )
}

/// The generator's line: its own CPU over the run (from `/proc/self` before and after, s).
pub fn generator_line(before_cpu_s: f64, after_cpu_s: f64, wall_s: f64) -> String {
    let cpu_s = after_cpu_s - before_cpu_s;
    format!(
        "  Generator process: {cpu_s:.1} s of CPU over {wall_s:.1} s ({:.2} cores)",
        cpu_s / wall_s.max(1e-9)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_are_found_by_their_exact_name() {
        let text = "# HELP x\nuavnav_process_cpu_seconds_total_created 1.7e9\n\
                    uavnav_process_cpu_seconds_total 12.5\nuavnav_process_resident_memory_bytes 1048576\n";
        assert_eq!(sample(text, "uavnav_process_cpu_seconds_total"), Some(12.5));
        assert_eq!(
            sample(text, "uavnav_process_resident_memory_bytes"),
            Some(1048576.0)
        );
        assert_eq!(sample(text, "uavnav_process"), None);
    }

    #[test]
    fn urls_are_plain_http() {
        assert_eq!(
            split_url("http://127.0.0.1:9464/metrics"),
            Ok(("127.0.0.1:9464", "/metrics"))
        );
        assert_eq!(split_url("http://host:1"), Ok(("host:1", "/metrics")));
        assert!(split_url("https://host:1/metrics").is_err());
    }

    #[test]
    fn the_line_divides_by_the_accepted_inputs() {
        let before = ServiceProcess {
            cpu_s: 10.0,
            resident_bytes: 0.0,
        };
        let after = ServiceProcess {
            cpu_s: 22.0,
            resident_bytes: 100.0 * 1024.0 * 1024.0,
        };
        let l = line(&before, &after, 6.0, 3_000_000);
        assert!(
            l.contains("12.0 s of CPU") && l.contains("2.00 cores"),
            "{l}"
        );
        assert!(
            l.contains("4.00 µs per accepted input") && l.contains("100.0 MiB"),
            "{l}"
        );
        let g = generator_line(1.0, 4.0, 6.0);
        assert!(g.contains("3.0 s of CPU over 6.0 s (0.50 cores)"), "{g}");
    }
}
