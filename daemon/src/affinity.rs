//! CPU affinity of the calling thread.
//!
//! On a small VM a wake-up across cores costs far more than one on the same
//! core (an iceoryx2 round trip here: 95 µs across, 14 µs on one core), so
//! the daemon can keep its latency-critical threads, and the frontends that
//! share its core, together ([`reserve_current_thread`]). Background work
//! (re-solves, freeing retired factors) then runs on the other cores
//! ([`run_in_background`]): sharing the pinned core, a re-solve's build or
//! a factor's free would time-slice with the engine thread
//! (docs/daemon.md, "Latency").

use std::sync::atomic::{AtomicU64, Ordering};

/// The cores reserved for latency-critical threads (bit `c`: core `c`).
static RESERVED: AtomicU64 = AtomicU64::new(0);

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

/// Pins the calling thread to `cpu` as [`pin_current_thread`] does, and
/// keeps background work off that core from now on.
pub fn reserve_current_thread(cpu: usize) -> bool {
    let pinned = pin_current_thread(cpu);
    if pinned && cpu < 64 {
        RESERVED.fetch_or(1 << cpu, Ordering::Relaxed);
    }
    pinned
}

/// Lowers the calling thread's priority ([`yield_to_foreground`]) and lets
/// it run on every online CPU no latency-critical thread reserved
/// ([`reserve_current_thread`]); on all of them when that leaves none.
/// With nothing reserved it keeps the CPUs it inherited (an embedding
/// application's choice).
pub fn run_in_background() {
    yield_to_foreground();
    let reserved = RESERVED.load(Ordering::Relaxed);
    if reserved == 0 {
        return;
    }
    let n = online_cpus();
    let free: Vec<usize> = (0..n).filter(|&c| c >= 64 || reserved & (1 << c) == 0).collect();
    set_affinity(if free.is_empty() { (0..n).collect() } else { free });
}

/// How much nicer than the foreground background threads run: CFS
/// weighs a nice-10 thread at 110 against 1,024, so a foreground thread
/// that wakes on a core a re-solve or the judge holds runs at once rather
/// than waiting out their time slice. On two cores the publishing thread,
/// the judge and a re-solve are three busy threads.
pub const BACKGROUND_NICE: i32 = 10;

/// Lowers the calling thread's priority by [`BACKGROUND_NICE`] (Linux,
/// where nice is per thread; elsewhere nothing).
pub fn yield_to_foreground() {
    #[cfg(target_os = "linux")]
    {
        let nice = (current_nice() + BACKGROUND_NICE).min(19);
        // SAFETY: setpriority on this thread's id changes only its own
        // nice value; raising it needs no privilege.
        unsafe {
            libc::setpriority(libc::PRIO_PROCESS, thread_id(), nice);
        }
    }
}

/// This thread's nice value (Linux; elsewhere 0).
pub fn current_nice() -> i32 {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: getpriority only reads.
        unsafe { libc::getpriority(libc::PRIO_PROCESS, thread_id()) }
    }
    #[cfg(not(target_os = "linux"))]
    0
}

/// The calling thread's kernel id, which `getpriority` and `setpriority`
/// take for one thread.
#[cfg(target_os = "linux")]
fn thread_id() -> libc::id_t {
    // SAFETY: gettid has no preconditions.
    unsafe { libc::syscall(libc::SYS_gettid) as libc::id_t }
}

/// CPUs online. Not `available_parallelism`, which counts the calling
/// thread's own mask: from a pinned thread, 1 (and the re-solve thread
/// stayed on the engine's core).
fn online_cpus() -> usize {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: sysconf reads a system constant.
        let n = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_ONLN) };
        if n > 0 {
            return n as usize;
        }
    }
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

fn set_affinity(cpus: Vec<usize>) {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: as in `pin_current_thread`.
        unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            for cpu in cpus.into_iter().filter(|&c| c < libc::CPU_SETSIZE as usize) {
                libc::CPU_SET(cpu, &mut set);
            }
            libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set);
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = cpus;
}

/// The CPUs the calling thread may run on (Linux; elsewhere none).
pub fn current_cpus() -> Vec<usize> {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: as in `pin_current_thread`; sched_getaffinity fills the set.
        unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            if libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) != 0 {
                return Vec::new();
            }
            (0..libc::CPU_SETSIZE as usize)
                .filter(|&c| libc::CPU_ISSET(c, &set))
                .collect()
        }
    }
    #[cfg(not(target_os = "linux"))]
    Vec::new()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn background_threads_run_nicer_than_the_foreground() {
        let foreground = current_nice();
        let background = std::thread::spawn(|| {
            run_in_background();
            current_nice()
        })
        .join()
        .unwrap();
        if cfg!(target_os = "linux") {
            assert_eq!(background, (foreground + BACKGROUND_NICE).min(19));
        }
        assert_eq!(
            current_nice(),
            foreground,
            "the caller's own priority is left alone"
        );
    }

    #[test]
    fn background_work_leaves_the_reserved_core() {
        std::thread::spawn(|| {
            assert!(!pin_current_thread(100_000));
            assert!(reserve_current_thread(0));
            assert_eq!(current_cpus(), vec![0]);
            // a thread spawned here inherits core 0 until it moves off
            let moved = std::thread::spawn(|| {
                run_in_background();
                current_cpus()
            })
            .join()
            .unwrap();
            let n = online_cpus();
            let expected: Vec<usize> = if n > 1 { (1..n).collect() } else { vec![0] };
            RESERVED.fetch_and(!1, Ordering::Relaxed);
            assert_eq!(moved, expected);
        })
        .join()
        .unwrap();
    }
}
