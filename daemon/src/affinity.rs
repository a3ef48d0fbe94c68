//! CPU affinity of the calling thread.
//!
//! On a small VM a wake-up across cores costs far more than one on the same
//! core (an iceoryx2 round trip here: 95 µs across, 14 µs on one core), so
//! the daemon can keep its latency-critical threads, and the frontends that
//! share its core, together. Background work unpins itself.

/// Pins the calling thread to `cpu`. Returns false where that is not
/// possible (no such CPU, or not Linux).
pub fn pin_current_thread(cpu: usize) -> bool {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: a zeroed cpu_set_t is a valid empty set; CPU_SET writes
        // inside it; sched_setaffinity(0, ..) affects only this thread.
        unsafe {
            if cpu >= libc::CPU_SETSIZE as usize {
                return false;
            }
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            libc::CPU_SET(cpu, &mut set);
            libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) == 0
        }
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = cpu;
        false
    }
}

/// Lets the calling thread run on every online CPU again.
pub fn unpin_current_thread() {
    #[cfg(target_os = "linux")]
    {
        let n = std::thread::available_parallelism().map_or(1, |n| n.get());
        // SAFETY: as in `pin_current_thread`.
        unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            for cpu in 0..n.min(libc::CPU_SETSIZE as usize) {
                libc::CPU_SET(cpu, &mut set);
            }
            libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pins_and_unpins_this_thread() {
        std::thread::spawn(|| {
            assert!(pin_current_thread(0));
            assert!(!pin_current_thread(100_000));
            unpin_current_thread();
        })
        .join()
        .unwrap();
    }
}
