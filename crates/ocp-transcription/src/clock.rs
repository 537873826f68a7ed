//! CPU time of the calling thread and of the whole process: the measure of solve and
//! iteration times on a shared machine, where wall time counts the time other processes hold
//! the core.

/// CPU time (s) the calling thread has run so far: POSIX `clock_gettime` with
/// `CLOCK_THREAD_CPUTIME_ID` (nanoseconds, brought up to date at the call; through `rustix`);
/// `None` off Unix. (Linux's `/proc/thread-self/schedstat` is not used: it is brought up to
/// date only at scheduler ticks, so a span shorter than a tick can read 0.)
/// Differences of two readings on the same thread time the work between them; work done on
/// other threads (e.g. [`crate::SqpSettings::parallel_intervals`]) is not counted.
///
/// ```
/// let t0 = ocp_transcription::thread_cpu_time();
/// let x: f64 = (0..100_000).map(|i| (i as f64).sqrt()).sum();
/// if let (Some(a), Some(b)) = (t0, ocp_transcription::thread_cpu_time()) {
///     assert!(b >= a && x > 0.0);
/// }
/// ```
pub fn thread_cpu_time() -> Option<f64> {
    cpu_seconds(CpuClock::Thread)
}

/// Runs `f` and returns the CPU seconds of the calling thread it took ([`thread_cpu_time`]),
/// or its wall seconds where the thread clock is unavailable, with `f`'s result.
///
/// ```
/// let (seconds, x) = ocp_transcription::thread_cpu_timed(|| (0..1000).sum::<u64>());
/// assert!(seconds >= 0.0 && x == 499_500);
/// ```
pub fn thread_cpu_timed<R>(f: impl FnOnce() -> R) -> (f64, R) {
    let (c0, w0) = (thread_cpu_time(), std::time::Instant::now());
    let r = f();
    let t = match (c0, thread_cpu_time()) {
        (Some(a), Some(b)) => b - a,
        _ => w0.elapsed().as_secs_f64(),
    };
    (t, r)
}

/// CPU time (s, user + system, all threads) the whole process has run so far: POSIX
/// `clock_gettime` with `CLOCK_PROCESS_CPUTIME_ID` (nanoseconds; through `rustix`); `None` off
/// Unix. The measure for work spread over threads (faer's or rayon's), which
/// [`thread_cpu_time`] does not see.
///
/// ```
/// let t0 = ocp_transcription::process_cpu_time();
/// let x: f64 = (0..100_000).map(|i| (i as f64).sqrt()).sum();
/// if let (Some(a), Some(b)) = (t0, ocp_transcription::process_cpu_time()) {
///     assert!(b >= a && x > 0.0);
/// }
/// ```
pub fn process_cpu_time() -> Option<f64> {
    cpu_seconds(CpuClock::Process)
}

/// Whose CPU time a reading counts.
#[derive(Clone, Copy)]
enum CpuClock {
    Thread,
    Process,
}

/// Seconds of `clock_gettime` on the CPU clock `which`; `None` off Unix.
fn cpu_seconds(which: CpuClock) -> Option<f64> {
    #[cfg(unix)]
    {
        use rustix::time::{clock_gettime, ClockId};
        let ts = clock_gettime(match which {
            CpuClock::Thread => ClockId::ThreadCPUTime,
            CpuClock::Process => ClockId::ProcessCPUTime,
        });
        Some(ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9)
    }
    #[cfg(not(unix))]
    {
        let _ = which;
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[cfg(unix)]
    fn clocks_read_and_advance_on_unix() {
        let (t0, p0) =
            (thread_cpu_time().expect("thread clock"), process_cpu_time().expect("process clock"));
        let mut x = 0.0f64;
        for i in 0..3_000_000 {
            x += (i as f64).sqrt();
        }
        let (t1, p1) = (thread_cpu_time().unwrap(), process_cpu_time().unwrap());
        assert!(x > 0.0 && t1 > t0 && p1 > p0 && p0 >= 0.0);
    }
}
