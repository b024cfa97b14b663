//! The system calls the connection limits make: raising the descriptor limit at start-up, and
//! asking a socket whether bytes wait in it unread.

use std::io;

/// The soft descriptor limit before and after [`raise_fd_limit`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FdLimit {
    /// The soft limit the process started with.
    pub was: u64,
    /// The soft limit now.
    pub now: u64,
}

/// Raises the soft `RLIMIT_NOFILE` to the hard limit (2²⁰ when the hard limit is infinite,
/// which Linux does not accept as a soft one).
pub fn raise_fd_limit() -> io::Result<FdLimit> {
    let mut limit = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
    // SAFETY: getrlimit writes the struct it is given and nothing else
    if unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &mut limit) } != 0 {
        return Err(io::Error::last_os_error());
    }
    let was = limit.rlim_cur;
    let target = if limit.rlim_max == libc::RLIM_INFINITY { 1 << 20 } else { limit.rlim_max };
    if target <= limit.rlim_cur {
        return Ok(FdLimit { was, now: was });
    }
    let raised = libc::rlimit { rlim_cur: target, rlim_max: limit.rlim_max };
    // SAFETY: setrlimit reads the struct it is given
    if unsafe { libc::setrlimit(libc::RLIMIT_NOFILE, &raised) } != 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(FdLimit { was, now: target })
}

/// Whether bytes wait to be read on socket `fd` (`FIONREAD`); false for -1 or on error.
pub(super) fn bytes_waiting(fd: i32) -> bool {
    let mut n: libc::c_int = 0;
    // SAFETY: FIONREAD writes one int; a listed connection's socket stays open while the
    // caller holds the table's lock
    fd >= 0 && unsafe { libc::ioctl(fd, libc::FIONREAD, &mut n) } == 0 && n > 0
}
