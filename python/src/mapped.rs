//! A capture file's bytes mapped into memory instead of read: reading copies the file into
//! fresh memory, whose first touch (the kernel zeroing every page) costs about as much
//! again; a private read-only mapping of the page cache costs neither.

use skinbox_host::pcap::PcapError;
use std::ops::Deref;
use std::path::Path;

/// The bytes of a file: mapped (Unix, a file that is not empty) or read.
pub enum FileBytes {
    #[cfg(unix)]
    Mapped {
        start: *const u8,
        len: usize,
    },
    Read(Vec<u8>),
}

// SAFETY: the mapping is read-only and private, owned by this value alone.
unsafe impl Send for FileBytes {}
// SAFETY: as for Send: nothing writes it.
unsafe impl Sync for FileBytes {}

impl Deref for FileBytes {
    type Target = [u8];

    fn deref(&self) -> &[u8] {
        match self {
            #[cfg(unix)]
            // SAFETY: `start` maps `len` readable bytes until `drop`.
            FileBytes::Mapped { start, len } => unsafe { std::slice::from_raw_parts(*start, *len) },
            FileBytes::Read(v) => v,
        }
    }
}

impl Drop for FileBytes {
    fn drop(&mut self) {
        #[cfg(unix)]
        if let FileBytes::Mapped { start, len } = *self {
            // SAFETY: the mapping made in `map_file`, unmapped once.
            unsafe { libc::munmap(start as *mut libc::c_void, len) };
        }
    }
}

/// The bytes of the file at `path`, with its name in the error. Mapped where it can be
/// (the file must then not be truncated while it is read: the kernel would stop the
/// process with SIGBUS), read otherwise.
pub fn map_file(path: &Path) -> Result<FileBytes, PcapError> {
    let io = |error| PcapError::Io {
        path: path.display().to_string(),
        error,
    };
    let file = std::fs::File::open(path).map_err(io)?;
    #[cfg(unix)]
    {
        use std::os::fd::AsRawFd;
        let len = file.metadata().map_err(io)?.len();
        if let Ok(len) = usize::try_from(len) {
            if len > 0 && file.metadata().map_err(io)?.is_file() {
                #[cfg(target_os = "linux")]
                let flags = libc::MAP_PRIVATE | libc::MAP_POPULATE;
                #[cfg(not(target_os = "linux"))]
                let flags = libc::MAP_PRIVATE;
                // SAFETY: a new read-only private mapping of an open file; the file may be
                // closed after it.
                let start = unsafe {
                    libc::mmap(
                        std::ptr::null_mut(),
                        len,
                        libc::PROT_READ,
                        flags,
                        file.as_raw_fd(),
                        0,
                    )
                };
                if start != libc::MAP_FAILED {
                    // SAFETY: the mapping just made; the advice only steers read-ahead.
                    unsafe { libc::madvise(start, len, libc::MADV_SEQUENTIAL) };
                    return Ok(FileBytes::Mapped {
                        start: start as *const u8,
                        len,
                    });
                }
            }
        }
    }
    let mut bytes = Vec::new();
    std::io::Read::read_to_end(&mut { file }, &mut bytes).map_err(io)?;
    Ok(FileBytes::Read(bytes))
}
