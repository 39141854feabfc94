//! The clock benchmarks time work with.

/// A clock of the CPU time the calling thread has used: what a single-threaded benchmark costs,
/// unmoved by other processes on a shared machine (which only delay it). On Unix it is
/// `CLOCK_THREAD_CPUTIME_ID`; elsewhere the wall clock.
#[derive(Debug, Clone, Copy)]
pub struct CpuClock {
    #[cfg(unix)]
    start: rustix::time::Timespec,
    #[cfg(not(unix))]
    start: std::time::Instant,
}

impl CpuClock {
    pub fn start() -> CpuClock {
        #[cfg(unix)]
        let start = rustix::time::clock_gettime(rustix::time::ClockId::ThreadCPUTime);
        #[cfg(not(unix))]
        let start = std::time::Instant::now();
        CpuClock { start }
    }

    /// Seconds since [`CpuClock::start`].
    pub fn seconds(&self) -> f64 {
        #[cfg(unix)]
        {
            let now = rustix::time::clock_gettime(rustix::time::ClockId::ThreadCPUTime);
            (now.tv_sec - self.start.tv_sec) as f64 + (now.tv_nsec - self.start.tv_nsec) as f64 * 1e-9
        }
        #[cfg(not(unix))]
        {
            self.start.elapsed().as_secs_f64()
        }
    }

    /// What the clock measures, for the benchmarks' headers.
    pub fn name() -> &'static str {
        if cfg!(unix) { "thread CPU time" } else { "wall-clock time" }
    }
}
