//! CPU time of the calling thread: the measure of solve and iteration times on a shared
//! machine, where wall time counts the time other processes hold the core.

/// CPU time (s) the calling thread has run so far, from Linux's
/// `/proc/thread-self/schedstat` (nanoseconds on CPU); `None` where that file does not exist.
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
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: f64 = s.split_whitespace().next()?.parse().ok()?;
    Some(ns * 1e-9)
}
