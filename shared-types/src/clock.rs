//! CLOCK_MONOTONIC in nanoseconds: one clock for every process on the host, so a
//! capture time stamped by acquisition can be subtracted from "now" in any other stage.

/// Nanoseconds on CLOCK_MONOTONIC.
pub fn monotonic_ns() -> u64 {
    clock_ns(libc::CLOCK_MONOTONIC)
}

/// CPU time of this whole process (every thread), nanoseconds: what a stage costs the
/// machine, whatever its parallelism (CLOCK_PROCESS_CPUTIME_ID).
pub fn process_cpu_ns() -> u64 {
    clock_ns(libc::CLOCK_PROCESS_CPUTIME_ID)
}

fn clock_ns(clock: libc::clockid_t) -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; both clocks always exist on Linux.
    let rc = unsafe { libc::clock_gettime(clock, &mut ts) };
    if rc != 0 {
        return 0;
    }
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Microseconds from `earlier_ns` to `later_ns`, 0 if the clock order is reversed.
pub fn elapsed_us(earlier_ns: u64, later_ns: u64) -> u64 {
    later_ns.saturating_sub(earlier_ns) / 1000
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotonic_and_positive() {
        let a = monotonic_ns();
        std::thread::sleep(std::time::Duration::from_millis(2));
        let b = monotonic_ns();
        assert!(a > 0 && b > a && b - a >= 2_000_000);
        assert_eq!(elapsed_us(b, a), 0);
        assert_eq!(elapsed_us(1_000, 5_000), 4);
    }

    /// Process CPU time counts the whole test binary, whose other tests run on other
    /// threads meanwhile: with a 20 ms sleep against ~15 ms of work, another test busy
    /// during the sleep made the sleep "cost" more (seen once in CI). So the sleep is
    /// short and the work long: the sleep window can hold at most 2 ms per core of
    /// other threads' CPU, the work 100 ms of this thread's.
    #[test]
    fn process_cpu_time_counts_work_not_sleep() {
        let a = process_cpu_ns();
        std::thread::sleep(std::time::Duration::from_millis(2));
        let b = process_cpu_ns();
        let start = monotonic_ns();
        let mut x = 0u64;
        while monotonic_ns() - start < 100_000_000 {
            for i in 0..10_000u64 {
                x = std::hint::black_box(x.wrapping_add(i * i));
            }
        }
        let c = process_cpu_ns();
        assert!(a > 0 && b >= a && c > b, "{a} {b} {c} {x}");
        assert!(c - b > b - a, "work should cost more CPU than sleeping");
    }
}
