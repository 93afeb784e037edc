//! What one stage's execution cost the machine: CPU time and peak resident memory.
//!
//! Both are process-wide quantities, so they are a stage's own only while no other
//! stage runs beside it: [`crate::RunOptions::measure_usage`] runs the stages one at a
//! time for that reason (each stage still uses every core through rayon).
//!
//! - CPU time: user + system time of the whole process (all threads), from
//!   `clock_gettime(CLOCK_PROCESS_CPUTIME_ID)` through the `cpu-time` crate.
//! - Peak resident memory: Linux only. The kernel's high-water mark of the resident set
//!   (`VmHWM` in `/proc/self/status`) is reset before the stage by writing `5` to
//!   `/proc/self/clear_refs` (proc(5)) and read after it. Where either file is missing
//!   or not writable (another system, a locked-down container) the peak is `None`, never
//!   a made-up number; where only the reset fails the peak would be the process's
//!   lifetime peak, so it is `None` too.

use std::time::Duration;

use cpu_time::ProcessTime;

/// A stage's cost, as measured by [`Meter`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Usage {
    /// User + system CPU time of the process while the stage ran, in seconds.
    pub cpu_time_s: Option<f64>,
    /// Peak resident set while the stage ran, in bytes.
    pub peak_rss_bytes: Option<u64>,
}

/// A running measurement, started before a stage and read after it.
#[derive(Debug)]
pub struct Meter {
    cpu_at_start: Option<ProcessTime>,
    peak_was_reset: bool,
}

impl Meter {
    /// Starts measuring: notes the CPU time so far and resets the memory high-water mark.
    pub fn start() -> Self {
        let peak_was_reset = std::fs::write("/proc/self/clear_refs", b"5").is_ok();
        Self { cpu_at_start: ProcessTime::try_now().ok(), peak_was_reset }
    }

    /// What the process used since [`Meter::start`].
    pub fn finish(&self) -> Usage {
        let cpu = self.cpu_at_start.and_then(|start| start.try_elapsed().ok());
        Usage {
            cpu_time_s: cpu.as_ref().map(Duration::as_secs_f64),
            peak_rss_bytes: if self.peak_was_reset { peak_rss_bytes() } else { None },
        }
    }
}

/// `VmHWM` of `/proc/self/status`, in bytes.
fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    parse_vm_hwm(&status)
}

/// The `VmHWM:   1234 kB` line of a `/proc/PID/status` text, in bytes.
fn parse_vm_hwm(status: &str) -> Option<u64> {
    let line = status.lines().find_map(|l| l.strip_prefix("VmHWM:"))?;
    let kib: u64 = line.trim().strip_suffix("kB")?.trim().parse().ok()?;
    Some(kib * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_high_water_mark_is_read_in_bytes() {
        let status = "Name:\tamrepro\nVmPeak:\t  200 kB\nVmHWM:\t    1536 kB\nVmRSS:\t 1000 kB\n";
        assert_eq!(parse_vm_hwm(status), Some(1536 * 1024));
        assert_eq!(parse_vm_hwm("VmRSS:\t 1000 kB\n"), None);
        assert_eq!(parse_vm_hwm("VmHWM:\t lots\n"), None);
    }

    #[test]
    fn a_busy_stretch_costs_cpu_and_an_allocation_raises_the_peak() {
        let meter = Meter::start();
        let block = vec![1u8; 64 << 20];
        let mut sum = 0u64;
        for round in 0..20u64 {
            sum = block.iter().fold(sum, |s, &b| s.wrapping_add(u64::from(b) ^ round));
        }
        std::hint::black_box(sum);
        let usage = meter.finish();
        assert!(usage.cpu_time_s.is_some_and(|s| s > 0.0), "{usage:?}");
        if cfg!(target_os = "linux") && std::path::Path::new("/proc/self/clear_refs").exists() {
            let peak = usage.peak_rss_bytes.expect("Linux gives the peak");
            assert!(peak >= 64 << 20, "the 64 MiB block is resident: {peak}");
        }
    }
}
