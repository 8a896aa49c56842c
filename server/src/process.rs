//! The process's own CPU time and resident memory, read from Linux's `/proc/self` each time
//! `/metrics` is scraped (`uavnav_process_cpu_seconds_total`,
//! `uavnav_process_resident_memory_bytes`): what an operator sizes a machine by, and what
//! `uavnav loadtest --metrics URL` divides by the IMU samples the service accepted. Where there is
//! no `/proc` the two metrics stay at zero.

/// One reading of the process's resources.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProcessStats {
    /// User plus system CPU time of every thread of the process so far, s.
    pub cpu_s: f64,
    /// Resident memory, bytes.
    pub resident_bytes: u64,
}

/// Clock ticks per second of the times in `/proc/PID/stat`: Linux's `USER_HZ`, which its ABI
/// fixes at 100 on every architecture it reports to user space with.
const USER_HZ: f64 = 100.0;

/// Reads this process's figures; `None` where `/proc/self` cannot be read or parsed.
pub fn read() -> Option<ProcessStats> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    Some(ProcessStats {
        cpu_s: cpu_seconds(&stat)?,
        resident_bytes: resident_bytes(&status)?,
    })
}

/// utime + stime (fields 14 and 15) of a `/proc/PID/stat` line, s. The command name (field 2)
/// is in parentheses and may itself hold spaces and parentheses, so fields are counted from
/// the last `)`.
pub fn cpu_seconds(stat: &str) -> Option<f64> {
    let rest = &stat[stat.rfind(')')? + 1..];
    let mut fields = rest.split_whitespace().skip(11);
    let utime: u64 = fields.next()?.parse().ok()?;
    let stime: u64 = fields.next()?.parse().ok()?;
    Some((utime + stime) as f64 / USER_HZ)
}

/// `VmRSS` of a `/proc/PID/status` text, bytes (the kernel states it in kB).
pub fn resident_bytes(status: &str) -> Option<u64> {
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kib: u64 = line
        .trim_start_matches("VmRSS:")
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kib * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stat_line_gives_user_plus_system_time() {
        // A command name with a space and a parenthesis, as a thread may be named.
        let stat = "4242 (uav nav) d) S 1 4242 4242 0 -1 4194560 1534 0 0 0 250 75 0 0 20 0 9 0 \
                    12345 100000000 5000 18446744073709551615";
        assert_eq!(cpu_seconds(stat), Some(3.25));
        assert_eq!(cpu_seconds("garbage"), None);
    }

    #[test]
    fn the_resident_size_is_read_in_bytes() {
        let status = "Name:\tuavnavd\nVmPeak:\t  200000 kB\nVmRSS:\t   12345 kB\nThreads:\t9\n";
        assert_eq!(resident_bytes(status), Some(12345 * 1024));
        assert_eq!(resident_bytes("Name:\tx\n"), None);
    }

    #[test]
    fn this_process_can_be_read_on_linux() {
        if cfg!(target_os = "linux") {
            let s = read().expect("/proc/self is readable on Linux");
            assert!(s.cpu_s >= 0.0 && s.resident_bytes > 0, "{s:?}");
        }
    }
}
