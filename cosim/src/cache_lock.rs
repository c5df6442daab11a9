//! A lock on one entry of the model cache that holds across processes.
//!
//! Two processes that need the same model (test binaries under cargo-nextest, shards of a
//! CI matrix on a shared cache) must not both build it into the same place: the first
//! takes the entry's lock file and builds, the second waits for it and then finds the
//! model in the cache. The lock is an advisory `flock` on `<entry>.lock`, released when the
//! guard is dropped or the process ends (also when it is killed), so a crashed build leaves
//! no stale lock behind.

use crate::error::CosimError;
use std::fs::{File, OpenOptions};
use std::path::Path;

/// Holds the lock of one cache entry until dropped.
#[derive(Debug)]
pub struct CacheLock {
    _file: File,
}

impl CacheLock {
    /// Waits for and takes the lock of the cache entry `entry` (its lock file is
    /// `entry` with `.lock` appended), creating the cache directory if needed.
    pub fn acquire(entry: &Path) -> Result<CacheLock, CosimError> {
        let mut name = entry.as_os_str().to_owned();
        name.push(".lock");
        let path = Path::new(&name);
        let io = |source| CosimError::Io {
            path: path.to_path_buf(),
            source,
        };
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let file = OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(path)
            .map_err(io)?;
        file.lock().map_err(io)?;
        Ok(CacheLock { _file: file })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;
    use std::time::Duration;

    #[test]
    fn a_second_holder_waits_for_the_first() {
        let dir = std::env::temp_dir().join(format!("skinbox-cache-lock-{}", std::process::id()));
        let entry = dir.join("box1-0123");
        let first = CacheLock::acquire(&entry).unwrap();
        assert!(dir.join("box1-0123.lock").exists());
        let released = Arc::new(AtomicBool::new(false));
        let waiter = {
            let (entry, released) = (entry.clone(), released.clone());
            // a separate open file description, as in another process
            std::thread::spawn(move || {
                let _second = CacheLock::acquire(&entry).unwrap();
                released.load(Ordering::SeqCst)
            })
        };
        std::thread::sleep(Duration::from_millis(200));
        released.store(true, Ordering::SeqCst);
        drop(first);
        assert!(
            waiter.join().unwrap(),
            "the second lock was taken while the first was held"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
