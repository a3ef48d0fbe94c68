//! Free space in `/dev/shm`, checked before creating pools: iceoryx2 maps
//! its segments lazily, so a too-small `/dev/shm` would otherwise surface as
//! a SIGBUS at the first write.

use super::TransportError;

/// Free bytes in the file system holding `path`.
pub fn free_bytes(path: &str) -> Option<u64> {
    let c = std::ffi::CString::new(path).ok()?;
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: `c` is a valid NUL-terminated path and `st` a valid out-pointer.
    let rc = unsafe { libc::statvfs(c.as_ptr(), &mut st) };
    (rc == 0).then(|| st.f_bavail as u64 * st.f_frsize as u64)
}

/// Fails when `/dev/shm` has less than `need` bytes free. Where there is no
/// `/dev/shm` (another OS), nothing is checked.
pub fn check_room(need: u64) -> Result<(), TransportError> {
    match free_bytes("/dev/shm") {
        Some(free) if free < need => Err(TransportError::SharedMemoryTooSmall { need, free }),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_impossible_need_is_refused_with_the_numbers() {
        let e = check_room(u64::MAX / 2).unwrap_err();
        assert!(matches!(e, TransportError::SharedMemoryTooSmall { .. }));
        assert!(e.to_string().contains("/dev/shm has"), "{e}");
        assert!(check_room(1).is_ok());
    }
}
