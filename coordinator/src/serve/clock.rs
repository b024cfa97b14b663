//! The coordinator's clock: wall time read once, advanced by a monotonic clock.

/// Milliseconds since the Unix epoch, read once, then advanced by a monotonic clock: the clock
/// the pure model is fed with. Lease deadlines and time budgets must not jump when the wall
/// clock is stepped (NTP, an operator), and times stored for jobs stay close to wall time.
pub fn now_ms() -> u64 {
    use std::sync::OnceLock;
    use std::time::{Instant, SystemTime, UNIX_EPOCH};
    static ANCHOR: OnceLock<(Instant, u64)> = OnceLock::new();
    let (start, wall) = ANCHOR.get_or_init(|| {
        (Instant::now(), SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_millis() as u64))
    });
    wall + start.elapsed().as_millis() as u64
}
